"""The time base of measured records (data.timebase): the Python API and `sdnn identify` read a time column
the same way, and jittered, gapped, semicolon and decimal-comma files load with a note and give the clean
file's parameters.

The records are the exact zero-order-hold response of a mass-spring-damper (scipy.signal.lsim, an oracle
independent of the network), m = 2 kg, k = 800 N/m, b = 4 N*s/m, 1 ms, with 1 % noise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import signal

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.data.timebase import conform
from flowchart2sdnn.errors import SdnnError

# the integrators start at fitted values: a part after a gap starts in motion
CHART_TEXT = (Path(__file__).parent.parent / "diagrams" / "mass_spring_damper.yaml").read_text().replace(
    "{type: integrator, in: a, unit: m/s}", "{type: integrator, in: a, unit: m/s, init: estimate}").replace(
    "{type: integrator, in: v, unit: m}", "{type: integrator, in: v, unit: m, init: estimate}").replace(
    "sample_time: 0.001", "sample_time: 0.001\nsubsteps: 16")  # the network's step error well below the noise
TRUE = {"m": 2.0, "k": 800.0, "b": 4.0}
N = 3000


def _record(step: float = 1e-3, n: int = N, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    hold = max(1, int(round(0.15 / step)))
    force = np.repeat(rng.uniform(-10, 10, n // hold + 1), hold)[:n]
    plant = signal.lti(np.array([[0.0, 1.0], [-400.0, -2.0]]), np.array([[0.0], [0.5]]), np.array([[1.0, 0.0]]),
                       np.array([[0.0]]))
    t = np.arange(n) * step
    _, x, _ = signal.lsim(plant, force, t, interp=False)
    return t, force, x + 1e-4 * rng.standard_normal(n)


def _write(path, t, force, x, delimiter=",", decimal=".", time_header="time"):
    lines = [delimiter.join([time_header, "F", "x"])]
    for row in zip(t, force, x, strict=True):
        cells = [f"{v:.10g}" for v in row]
        lines.append(delimiter.join(c.replace(".", decimal) for c in cells))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    global CHART
    root = tmp_path_factory.mktemp("timebase")
    CHART = str(root / "msd.yaml")
    (root / "msd.yaml").write_text(CHART_TEXT)
    t, force, x = _record()
    rng = np.random.default_rng(7)
    keep = np.r_[0:1500, 1541:N]  # a logger dropout of 41 samples
    return {
        "clean": _write(root / "clean.csv", t, force, x),
        "jitter": _write(root / "jitter.csv", t + rng.uniform(-2e-4, 2e-4, N), force, x),
        "gap": _write(root / "gap.csv", t[keep], force[keep], x[keep]),
        "semicolon": _write(root / "semicolon.csv", t, force, x, ";", ","),
        "tab": _write(root / "tab.csv", t, force, x, "\t"),
        "10ms": _write(root / "ten_ms.csv", *_record(1e-2, 300)),
        "ms": _write(root / "ms.csv", t * 1e3, force, x),
        "off_grid": _write(root / "off_grid.csv", np.where(np.arange(N) == 700, t + 4.5e-4, t), force, x),
    }


def _api(path):
    return sd.identify(CHART, sd.read_csv(path), floor_bias=False)


def _cli(path, *extra):
    return CliRunner().invoke(main, ["identify", CHART, str(path), "--no-floor-bias", *extra])


@pytest.fixture(scope="module")
def clean(files):
    return _api(files["clean"])


@pytest.mark.parametrize("case", ["10ms", "ms", "off_grid"])
def test_api_and_cli_refuse_the_same_time_column_with_the_same_line(files, case):
    with pytest.raises(SdnnError) as info:
        _api(files[case])
    res = _cli(files[case])
    assert res.exit_code == 1
    assert res.stderr.strip() == info.value.diagnostics[0].one_line()
    code = {"10ms": "CSV021", "ms": "CSV021", "off_grid": "CSV020"}[case]
    assert f"error[{code}]" in res.stderr and str(files[case]) in res.stderr


def test_ms_hint_names_the_unit_and_resample(files):
    res = _cli(files["ms"])
    assert "--unit" in res.stderr and "--resample" in res.stderr


@pytest.mark.parametrize("case", ["jitter", "gap", "semicolon", "tab"])
def test_prepared_files_load_with_a_note_and_give_the_clean_parameters(files, clean, case):
    ident = _api(files[case])
    notes = [w for w in ident.notices if w.message.startswith(str(files[case]))]
    assert notes, ident.warnings
    word = {"jitter": "snapped", "gap": "split into 2 records", "semicolon": "decimal comma", "tab": "tab"}[case]
    code = {"jitter": "TIME001", "gap": "TIME002", "semicolon": "READ002", "tab": "READ001"}[case]
    assert any(word in n.message and n.code == code for n in notes), notes
    for name in TRUE:
        estimate = ident.parameters[name]
        ref = clean.parameters[name]
        if case == "gap":  # other rows, so other noise: the two estimates agree within their joint interval
            assert abs(estimate.value - ref.value) <= 1.96 * np.hypot(estimate.stderr, ref.stderr), (name, estimate)
        else:  # the same numbers on the same grid
            assert estimate.value == pytest.approx(ref.value, rel=1e-6), (name, estimate.value, ref.value)
        assert abs(estimate.value - TRUE[name]) < 0.01 * TRUE[name]
    res = _cli(files[case])
    assert res.exit_code == 0, res.output
    for note in notes:
        assert f"warning[{note.code}] {note.message}" in res.output


def test_the_gap_is_two_records_of_the_rows_around_it(files):
    parts = conform(sd.read_csv(files["gap"]), 1e-3)
    assert [p.n_rows for p in parts] == [1500, N - 1541]
    note = parts[0].notes[-1]
    assert "41 after line 1501" in note.message and note.code == "TIME002"
    # the rows of the file as written (41 samples left out after row 1499): the parts' rows, by number
    assert note.numbers["gaps"] == 1 and note.numbers["records"] == [[0, 1499], [1500, N - 42]]


def test_resample_puts_a_10ms_record_on_the_1ms_grid(files, tmp_path):
    # a smooth record: resample_poly's interpolation against the signal itself at 1 ms
    t = np.arange(400) * 1e-2
    smooth = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.cos(2 * np.pi * 1.9 * t)
    path = _write(tmp_path / "smooth.csv", t, smooth, smooth)
    (part,) = conform(sd.read_csv(path), 1e-3, resample=True)
    fine = part.time
    truth = np.sin(2 * np.pi * 0.7 * fine) + 0.3 * np.cos(2 * np.pi * 1.9 * fine)
    inner = slice(200, -200)  # the ends carry the filter's edge
    assert np.max(np.abs(part.columns["F"][inner] - truth[inner])) < 2e-3
    assert np.allclose(np.diff(fine), 1e-3)
    assert "resampled from 0.01 s" in part.notes[-1].message and part.notes[-1].code == "TIME003"


def test_resample_on_the_command_line_notes_and_fits(files):
    res = _cli(files["10ms"], "--resample", "--max-iter", "2")
    assert res.exit_code == 0, res.output
    assert "resampled from 0.01 s to the chart's 0.001 s" in res.output


def test_explicit_comma_delimiter_still_refuses_a_semicolon_file(files):
    res = _cli(files["semicolon"], "--delimiter", ",")
    assert res.exit_code == 1 and "error[CSV014]" in res.stderr


def test_a_held_input_fitted_right_raises_no_lag_zero_warning(clean):
    # the record's force is truly held (lsim with zero-order hold): the residual is noise, no false alarm
    assert not any("lag 0" in w for w in clean.warnings), clean.warnings


@pytest.mark.parametrize("case", ["10ms", "off_grid"])
def test_diagnose_refuses_like_identify(files, case):
    with pytest.raises(SdnnError) as info:
        sd.diagnose(CHART, sd.read_csv(files[case]))
    res = CliRunner().invoke(main, ["diagnose", CHART, str(files[case])])
    assert res.exit_code == 1
    assert res.stderr.strip() == info.value.diagnostics[0].one_line()

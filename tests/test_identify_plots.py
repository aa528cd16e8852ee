"""`sdnn identify --plots DIR`: the paper's figures as PNG files (skipped without matplotlib), and a one-line
error naming the install command when matplotlib is missing."""

from __future__ import annotations

import builtins
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import read_csv, write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.problem import required_columns
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parents[1]
DIAGRAMS = ROOT / "diagrams"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _record(path: Path, plant: str, seconds: float, seed: int) -> Path:
    columns = excite(load_diagram(DIAGRAMS / plant), ExcitationSettings(seconds=seconds, seed=seed, noise_std=0.01))
    write_csv(path, columns, float_format="%.17g")
    return path


@pytest.fixture(scope="module")
def engine_csv(tmp_path_factory):
    return _record(tmp_path_factory.mktemp("plots") / "engine.csv", "engine_plant.yaml", 2.0, seed=1)


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == PNG_MAGIC
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_plots_offline_are_written_as_pngs(engine_csv, tmp_path):
    pytest.importorskip("matplotlib")
    plots = tmp_path / "figs" / "run1"  # created, parents too
    res = CliRunner().invoke(main, ["identify", str(DIAGRAMS / "engine.yaml"), str(engine_csv),
                                    "-o", str(tmp_path / "r.json"), "--plots", str(plots), "--max-iter", "20",
                                    "--quiet"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in plots.iterdir())
    # no parameter trajectories offline
    assert names == ["compare.png", "curve_MR1.png", "output.png", "resid_w1.png", "residual.png"]
    for name in names:
        width, height = _png_size((plots / name).read_bytes())
        assert width >= 400 and height >= 250
    # the same run again replaces the figures with identical bytes (no timestamps in the PNGs)
    before = {n: (plots / n).read_bytes() for n in names}
    res = CliRunner().invoke(main, ["identify", str(DIAGRAMS / "engine.yaml"), str(engine_csv),
                                    "-o", str(tmp_path / "r.json"), "--plots", str(plots), "--max-iter", "20",
                                    "--quiet", "--force"], catch_exceptions=False)
    assert res.exit_code == 0
    assert {n: (plots / n).read_bytes() for n in names} == before
    assert not [p for p in plots.iterdir() if p.name.startswith(".sdnn-tmp.")]


def test_plots_online_include_parameter_trajectories(engine_csv, tmp_path):
    pytest.importorskip("matplotlib")
    from flowchart2sdnn.report.identify_plots import write_plots

    diagram = load_diagram(DIAGRAMS / "engine.yaml")
    ds = read_csv(engine_csv, required_columns(diagram), None, diagram.sample_time)
    outcome = identify(diagram, ds, None, IdentifySettings(online=True, window=400, average=200))
    written = write_plots(outcome, tmp_path)
    assert sorted(p.name for p in written) == ["curve_MR1.png", "output.png", "parameters.png",
                                                      "resid_w1.png", "residual.png"]
    assert all(p.read_bytes()[:8] == PNG_MAGIC for p in written)


def test_curve_range_is_the_range_of_the_signal_feeding_the_block(tmp_path):
    """The nonlinear block MR2 of the two-mass chart is fed by w2, MR1 by w1: their ranges over a free run."""
    from flowchart2sdnn.network.alignment import run_aligned
    from flowchart2sdnn.report.identify_plots import curve_input_range

    data = _record(tmp_path / "tm.csv", "two_mass_plant.yaml", 1.0, seed=2)
    diagram = load_diagram(ROOT / "tests" / "data" / "two_mass_euler.yaml")  # two_mass.yaml at N = 1: quick
    ds = read_csv(data, required_columns(diagram), None, diagram.sample_time)
    outcome = identify(diagram, ds, None, IdentifySettings(max_iter=3))
    # oracle: the chart's own output w2 in a free run (run_aligned), rows 1.. (zoh: row 0 is the initial state)
    u = np.column_stack([ds.columns["M1"]])
    w2 = run_aligned(outcome.problem.compiled, outcome.x, u, "zoh", {})[1:, 0]
    lo, hi = curve_input_range(outcome, "MR2")
    assert lo == pytest.approx(w2.min(), abs=1e-12) and hi == pytest.approx(w2.max(), abs=1e-12)
    lo1, hi1 = curve_input_range(outcome, "MR1")
    assert lo1 < hi1 and (lo1, hi1) != (lo, hi)


def test_without_matplotlib_plots_is_one_line_naming_the_extra(engine_csv, tmp_path, monkeypatch):
    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError(f"No module named '{name}'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    res = CliRunner().invoke(main, ["identify", str(DIAGRAMS / "engine.yaml"), str(engine_csv),
                                    "-o", str(tmp_path / "r.json"), "--plots", str(tmp_path / "p")])
    assert res.exit_code == 1
    assert res.stderr.count("\n") == 1 and "error[PLOT001]" in res.stderr
    assert "pip install flowchart2sdnn[plots]" in res.stderr
    assert list(tmp_path.iterdir()) == []  # checked before the run: no result, no chart, no directory


def test_result_json_is_unchanged_by_plots(engine_csv, tmp_path):
    pytest.importorskip("matplotlib")
    args = ["identify", str(DIAGRAMS / "engine.yaml"), str(engine_csv), "--max-iter", "5", "--quiet"]
    assert CliRunner().invoke(main, [*args, "-o", str(tmp_path / "a.json")]).exit_code == 0
    assert CliRunner().invoke(main, [*args, "-o", str(tmp_path / "b.json"), "--plots", str(tmp_path / "p")]
                              ).exit_code == 0
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    for doc in (a, b):
        doc.pop("identified_chart")
    assert a == b

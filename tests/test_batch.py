"""`sdnn batch` and `sdnn report`: one row per file, error rows, resuming after a kill, drift per drive."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from fleet_data import TRUTH, write_chart, write_log

from flowchart2sdnn.batch.drift import drift_table, load_fleet, parse_group
from flowchart2sdnn.batch.results import columns_for, parquet_available, read_results
from flowchart2sdnn.batch.run import BatchSettings, run_batch
from flowchart2sdnn.cli import main
from flowchart2sdnn.cli.batch import expand_files
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.identify.offline.run import IdentifySettings
from flowchart2sdnn.report.drift import plots_available, write_report

REPO = Path(__file__).resolve().parents[1]
FAST = BatchSettings(identify=IdentifySettings(max_iter=20))


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Two drives, three days each; drive B's Coulomb friction rises by 0.1 N*m a day; one broken file."""
    d = tmp_path_factory.mktemp("fleet")
    chart = write_chart(d)
    files = []
    for day in range(3):
        files.append(write_log(d / f"A_day{day:03d}.csv", seed=10 + day))
        files.append(write_log(d / f"B_day{day:03d}.csv", seed=20 + day, Fc=0.6 + 0.1 * day))
    bad = d / "C_day000.csv"
    bad.write_text("time,M1,w1\n0,1,2\n0.001,1,abc\n0.002,1,2\n")
    return {"dir": d, "chart": chart, "files": sorted(str(f) for f in files), "bad": str(bad),
            "diagram": load_diagram(str(chart))}


def _table(path) -> list[dict]:
    """Rows without the wall-time column, sorted by file."""
    _, rows, dropped = read_results(path)
    assert dropped == 0
    return sorted(({k: v for k, v in r.items() if k != "seconds"} for r in rows), key=lambda r: r["file"])


def test_one_row_per_file_with_values_and_an_error_row(fleet, tmp_path):
    out = str(tmp_path / "r.csv")
    seen = []
    summary = run_batch(fleet["diagram"], fleet["files"] + [fleet["bad"]], out, FAST,
                        progress=lambda done, total, row: seen.append((done, total, row is not None)))
    assert (summary.identified, summary.failed, summary.skipped) == (6, 1, 0)
    assert seen[-1] == (7, 7, True)
    header, rows, _ = read_results(out)
    assert tuple(header) == columns_for(("J1", "Fc", "b"), ("w1",)).names
    by_file = {Path(r["file"]).name: r for r in rows}
    assert set(by_file) == {Path(f).name for f in fleet["files"]} | {"C_day000.csv"}
    bad = by_file["C_day000.csv"]
    assert bad["status"] == "error" and "CSV004" in bad["error"] and bad["J1"] is None
    for day in range(3):
        for drive, fc in (("A", TRUTH["Fc"]), ("B", TRUTH["Fc"] + 0.1 * day)):
            r = by_file[f"{drive}_day{day:03d}.csv"]
            assert r["error"] is None and r["rows"] == 1000
            assert r["t_start"] == 0.0 and r["t_end"] == pytest.approx(0.999)
            # the plant's friction, inside the row's own interval (widened for the short record)
            half = r["Fc_hi"] - r["Fc"]
            assert r["Fc_lo"] < r["Fc"] < r["Fc_hi"] and abs(r["Fc"] - fc) < max(4 * half, 0.01)
            assert r["fit_w1"] > 95


def test_a_failing_fit_is_an_error_row_not_a_lost_run(fleet, tmp_path, monkeypatch):
    import importlib

    run_module = importlib.import_module("flowchart2sdnn.identify")  # the face batch takes identify from

    real = run_module.identify

    def flaky(diagram, data, *args, **kwargs):
        if data.path.endswith("A_day001.csv"):
            raise FloatingPointError("the fit blew up")
        return real(diagram, data, *args, **kwargs)

    monkeypatch.setattr(run_module, "identify", flaky)
    out = str(tmp_path / "r.csv")
    summary = run_batch(fleet["diagram"], fleet["files"][:3], out, FAST)
    assert (summary.identified, summary.failed) == (2, 1)
    rows = {Path(r["file"]).name: r for r in read_results(out)[1]}
    assert rows["A_day001.csv"]["status"] == "error"
    assert rows["A_day001.csv"]["error"] == "FloatingPointError: the fit blew up"
    # a rerun keeps the error row unless asked to retry it
    monkeypatch.setattr(run_module, "identify", real)
    again = run_batch(fleet["diagram"], fleet["files"][:3], out, FAST)
    assert (again.identified, again.skipped) == (0, 3)
    retry = run_batch(fleet["diagram"], fleet["files"][:3], out,
                      BatchSettings(identify=FAST.identify, retry_errors=True))
    assert (retry.identified, retry.skipped) == (1, 2)
    assert {r["status"] for r in read_results(out)[1]} != {"error"}
    assert len(read_results(out)[1]) == 3  # the retried file replaced its error row


def test_rerun_skips_done_files_and_matches_a_single_run(fleet, tmp_path):
    whole = str(tmp_path / "whole.csv")
    run_batch(fleet["diagram"], fleet["files"], whole, FAST)
    part = str(tmp_path / "part.csv")
    first = run_batch(fleet["diagram"], fleet["files"][:2], part, FAST)
    rest = run_batch(fleet["diagram"], fleet["files"], part, FAST)
    assert (first.identified, rest.identified, rest.skipped) == (2, 4, 2)
    assert _table(part) == _table(whole)


def test_torn_last_line_is_dropped_and_that_file_redone(fleet, tmp_path):
    out = tmp_path / "r.csv"
    run_batch(fleet["diagram"], fleet["files"][:3], str(out), FAST)
    reference = _table(out)
    lines = out.read_text().splitlines(keepends=True)
    out.write_text("".join(lines[:-1]) + lines[-1][: len(lines[-1]) // 2])  # a kill in mid-write
    again = run_batch(fleet["diagram"], fleet["files"][:3], str(out), FAST)
    assert (again.identified, again.skipped, again.dropped_lines) == (1, 2, 1)
    assert _table(out) == reference


def test_same_content_elsewhere_is_copied_and_changed_content_redone(fleet, tmp_path):
    out = str(tmp_path / "r.csv")
    run_batch(fleet["diagram"], fleet["files"][:1], out, FAST)
    copy = tmp_path / "A_day000_copy.csv"
    copy.write_bytes(Path(fleet["files"][0]).read_bytes())
    s = run_batch(fleet["diagram"], fleet["files"][:1] + [str(copy)], out, FAST)
    assert (s.copied, s.identified, s.skipped) == (1, 0, 1)
    write_log(copy, seed=99)  # new content under a known name: identified again, one row for the name
    s = run_batch(fleet["diagram"], fleet["files"][:1] + [str(copy)], out, FAST)
    assert (s.identified, s.skipped) == (1, 1)
    assert len(read_results(out)[1]) == 2


def test_other_settings_are_refused_unless_forced(fleet, tmp_path):
    out = str(tmp_path / "r.csv")
    run_batch(fleet["diagram"], fleet["files"][:1], out, FAST)
    other = BatchSettings(identify=IdentifySettings(max_iter=5))
    with pytest.raises(SdnnError, match="BATCH002"):
        run_batch(fleet["diagram"], fleet["files"][:1], out, other)
    s = run_batch(fleet["diagram"], fleet["files"][:1], out, BatchSettings(identify=other.identify, force=True))
    assert s.identified == 1


@pytest.mark.skipif(parquet_available(), reason="pyarrow is installed")
def test_parquet_without_pyarrow_is_a_clear_error(fleet, tmp_path):
    with pytest.raises(SdnnError, match="pip install pyarrow"):
        run_batch(fleet["diagram"], fleet["files"][:1], str(tmp_path / "r.parquet"), FAST)


def test_parquet_table_equals_the_csv_table_and_resumes(fleet, tmp_path):
    """Parquet holds the same rows as CSV (same types, the error row too) and a rerun skips done files."""
    pytest.importorskip("pyarrow")
    files = fleet["files"][:3] + [fleet["bad"]]
    csv_out, pq_out = str(tmp_path / "r.csv"), str(tmp_path / "r.parquet")
    run_batch(fleet["diagram"], files, csv_out, FAST)
    first = run_batch(fleet["diagram"], files[:2], pq_out, FAST)
    rest = run_batch(fleet["diagram"], files, pq_out, FAST)
    assert (first.identified, rest.identified, rest.failed, rest.skipped) == (2, 1, 1, 2)
    assert _table(pq_out) == _table(csv_out)
    header, _, _ = read_results(pq_out)
    assert header == read_results(csv_out)[0]
    import pyarrow.parquet as pq

    schema = pq.read_schema(pq_out)
    assert str(schema.field("J1").type) == "double" and str(schema.field("rows").type) == "int64"
    assert str(schema.field("error").type) == "string"


def test_a_corrupt_parquet_table_is_a_one_line_error(fleet, tmp_path):
    pytest.importorskip("pyarrow")
    bad = tmp_path / "r.parquet"
    bad.write_bytes(b"PAR1 not really")
    with pytest.raises(SdnnError, match="BATCH004.*r.parquet"):
        run_batch(fleet["diagram"], fleet["files"][:1], str(bad), FAST)
    assert bad.read_bytes() == b"PAR1 not really"  # never overwritten


def test_expand_files_globs_and_leaves_out_the_table(fleet):
    d = fleet["dir"]
    out = str(d / "results.csv")
    Path(out).write_text("")
    try:
        files = expand_files((str(d / "*.csv"), fleet["files"][0]), exclude=(out,))
    finally:
        os.remove(out)
    assert files == sorted(fleet["files"] + [fleet["bad"]])
    with pytest.raises(SdnnError, match="no file matches"):
        expand_files((str(d / "nothing*.csv"),))


def _data_rows(path: Path) -> list[str]:
    if not path.exists():
        return []
    return [line for line in path.read_text().splitlines(keepends=True)[1:] if line.endswith("\n")]


def test_sigkill_midway_then_rerun_finishes_without_redoing(fleet, tmp_path):
    out = tmp_path / "r.csv"
    cmd = [sys.executable, "-m", "flowchart2sdnn.cli", "batch", str(fleet["chart"]), *fleet["files"],
           "-o", str(out), "--starts", "4", "--max-iter", "20", "--quiet"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while len(_data_rows(out)) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = _data_rows(out)
    assert proc.returncode == -signal.SIGKILL and 2 <= len(before) < len(fleet["files"])
    rerun = subprocess.run(cmd[:-1], cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{len(before)} already done" in rerun.stdout
    after = _data_rows(out)
    # finished rows kept byte for byte (their wall time too: never redone), the rest added
    assert set(before) <= set(after) and len(after) == len(fleet["files"])
    single = tmp_path / "single.csv"
    run_batch(fleet["diagram"], fleet["files"], str(single),
              BatchSettings(identify=IdentifySettings(starts=4, max_iter=20)))
    assert _table(out) == _table(single)


def test_cli_batch_and_report(fleet, tmp_path):
    runner = CliRunner()
    out = tmp_path / "r.csv"
    res = runner.invoke(main, ["batch", str(fleet["chart"]), str(fleet["dir"] / "*.csv"), "-o", str(out),
                               "--max-iter", "20"])
    assert res.exit_code == 0, res.output
    assert "6 identified, 1 failed" in res.output
    rep = runner.invoke(main, ["report", str(out), "-o", str(tmp_path / "rep")])
    assert rep.exit_code == 0, rep.output
    drifting = [line for line in rep.output.splitlines() if line.startswith("drift:")]
    assert len(drifting) == 1 and "drive B: Fc rising" in drifting[0]
    names = {p.name for p in (tmp_path / "rep").iterdir()}
    assert {"drift.csv", "report.md"} <= names
    if plots_available():
        assert {"Fc.png", "J1.png", "b.png", "drive_A.png", "drive_B.png"} <= names
    with open(tmp_path / "rep" / "drift.csv") as handle:
        b_fc = [r for r in csv.DictReader(handle) if r["drive"] == "B" and r["parameter"] == "Fc"][0]
    # the plant's friction rose 0.1 N*m a day
    assert float(b_fc["slope_per_day"]) == pytest.approx(0.1, abs=0.01)


def test_parse_group_default_rule_and_regex():
    import datetime as dt
    import re

    assert parse_group("/x/drive07_day012.csv") == ("drive07", 12)
    assert parse_group("pump-3_2024-05-01.csv") == ("pump-3", dt.date(2024, 5, 1))
    assert parse_group("logs/drive07/2024-05-01.csv") == ("drive07", dt.date(2024, 5, 1))
    assert parse_group("logs/drive07/day3.csv") == ("drive07", 3)
    assert parse_group("notes.csv") is None
    rx = re.compile(r"site(?P<drive>\d+)-(?P<day>\d+)h")
    assert parse_group("/d/site4-17h.csv", rx) == ("4", 17)


def test_drift_table_finds_a_known_slope_despite_a_failed_day(tmp_path):
    """A synthetic table: drive P's b rises 2 % of its value a day (plus noise), drive Q only has noise; each
    has one day whose fit went wrong (a local minimum far off): it neither hides nor fakes a drift."""
    rng = np.random.default_rng(5)
    cols = columns_for(("b",), ("w1",))
    lines = [",".join(cols.names)]
    for drive, slope, bad_day in (("P", 0.02, 4), ("Q", 0.0, 6)):
        for day in range(10):
            v = 1.0 + slope * day + 0.002 * rng.standard_normal() + (0.5 if day == bad_day else 0.0)
            row = {"file": f"{drive}_day{day}.csv", "sha256": "x", "status": "small_step", "b": repr(v),
                   "b_lo": repr(v - 0.004), "b_hi": repr(v + 0.004), "config": "c"}
            lines.append(",".join(row.get(c, "") for c in cols.names))
    path = tmp_path / "t.csv"
    path.write_text("\n".join(lines) + "\n")
    fleet = load_fleet(path)
    table = {d["drive"]: d for d in drift_table(fleet)}
    assert table["P"]["drift"] == "rising" and table["Q"]["drift"] == ""
    assert table["P"]["slope_per_day"] == pytest.approx(0.02, abs=0.001)
    assert (table["P"]["outliers"], table["Q"]["outliers"]) == ("4", "6")
    written = write_report(fleet, drift_table(fleet), tmp_path / "rep", plots=plots_available())
    assert all(Path(f).stat().st_size > 0 for f in written)
    assert len(written) == (2 + 1 + 2 if plots_available() else 2)  # b.png, drive_P.png, drive_Q.png


def test_diagnose_column_and_report_section(fleet, tmp_path, monkeypatch):
    """--diagnose wiring: the accepted effects go to the 'effects' column and the report lists them per drive.

    diagnose() itself is replaced by a stand-in that 'finds' friction on drive B from day 1 (the real loop is
    exercised in the slow test below and in the diagnose package's own tests)."""
    from flowchart2sdnn.diagnose import loop

    class Found:
        def __init__(self, accepted):
            self.report = {"accepted": accepted}

    def fake(diagram, data, validation=(), settings=None, **kwargs):
        late = "B_day" in data.path and not data.path.endswith("day000.csv")
        # the shape diagnose() reports: label is the chosen option's text ("" for friction, "n=6" for a dead time)
        return Found([{"effect": "friction", "at": "w1", "label": ""},
                      {"effect": "dead_time", "at": "M1", "label": "n=6"}] if late else [])

    monkeypatch.setattr(loop, "diagnose", fake)
    out = tmp_path / "r.csv"
    settings = BatchSettings(identify=FAST.identify, diagnose=True)
    run_batch(fleet["diagram"], fleet["files"], str(out), settings)
    rows = {Path(r["file"]).name: r for r in read_results(out)[1]}
    assert rows["B_day002.csv"]["effects"] == "friction@w1; dead_time@M1 (n=6)"
    assert rows["A_day002.csv"]["effects"] == "none"
    with pytest.raises(SdnnError, match="BATCH002"):  # a table without the column is another configuration
        run_batch(fleet["diagram"], fleet["files"], str(out), FAST)
    from flowchart2sdnn.batch.drift import effects_table

    effects = effects_table(load_fleet(out))
    assert effects == [{"drive": "B", "effect": "friction@w1", "days": ["1", "2"], "of": 3, "first_day": "1"},
                       {"drive": "B", "effect": "dead_time@M1 (n=6)", "days": ["1", "2"], "of": 3, "first_day": "1"}]


@pytest.mark.slow
def test_diagnose_finds_the_friction_a_chart_lacks(fleet, tmp_path):
    text = (fleet["dir"] / "drive.yaml").read_text()
    lacking = text.replace("  Fc: {init: 0.5, unit: N*m, min: 0}\n", "").replace("[M1, -MF, -MV]", "[M1, -MV]")
    lacking = "\n".join(line for line in lacking.splitlines() if not line.lstrip().startswith(("sg:", "MF:")))
    chart = tmp_path / "nofric.yaml"
    chart.write_text(lacking + "\n")
    # a log in which the drive reverses: in the fleet's 1 s logs the speed is positive 99.7 % of the time, where
    # Coulomb friction is a constant torque and an input offset (diagnose's input_offset) explains it as well
    log = write_log(tmp_path / "A_reversing.csv", seed=10, seconds=3.0)
    w = np.loadtxt(log, delimiter=",", skiprows=1, usecols=2)
    assert (w < -0.05).mean() > 0.02 and (w > 0.05).mean() > 0.02
    out = tmp_path / "r.csv"
    run_batch(load_diagram(str(chart)), [str(log)], str(out), BatchSettings(identify=FAST.identify, diagnose=True))
    row = read_results(out)[1][0]
    assert "friction" in row["effects"]


def test_unconverged_fits_are_left_out_of_the_trends(tmp_path):
    """Drive R's b falls 4 % a day; its last five days stopped at the iteration limit far above the truth, which
    turns the trend around (a 'rising' drift when they are kept). Left out and listed, they cannot fake one."""
    cols = columns_for(("b",), ("w1",))
    lines = [",".join(cols.names)]
    for day in range(10):
        unconverged = day >= 5
        v = 1.0 - 0.04 * day + (0.8 if unconverged else 0.0)
        row = {"file": f"R_day{day}.csv", "sha256": "x", "status": "max_iter" if unconverged else "small_cost_change",
               "b": repr(v), "b_lo": repr(v - 0.004), "b_hi": repr(v + 0.004), "config": "c"}
        lines.append(",".join(row.get(c, "") for c in cols.names))
    path = tmp_path / "t.csv"
    path.write_text("\n".join(lines) + "\n")
    fleet = load_fleet(path)
    assert fleet.unconverged == tuple(f"R_day{k}.csv" for k in range(5, 10))
    (d,) = drift_table(fleet)
    assert d["drift"] == "falling" and d["slope_per_day"] == pytest.approx(-0.04, abs=1e-9)

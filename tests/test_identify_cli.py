"""`sdnn identify` end to end: the result document, the identified chart, recovery of the truth, metrics
recomputed with numpy from `sdnn simulate`, --fix-from, validation, reproducibility and output safety.

All data come from the *_plant charts (exact friction, continuous-time simulation by `excite`), never from
the model under test. Records are a few seconds long so that the whole file runs in well under a minute.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn import __version__
from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.run import IdentifySettings
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parents[1]
DIAGRAMS = ROOT / "diagrams"
J1_TRUE = 0.1912  # diagrams/engine_plant.yaml


def _strict_json(path: Path) -> dict:
    def refuse(token):
        raise ValueError(f"non-strict JSON constant {token} in {path}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def _record(plant: str, path: Path, seconds: float, seed: int, noise: float = 0.01) -> Path:
    columns = excite(load_diagram(DIAGRAMS / plant), ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise))
    write_csv(path, columns, float_format="%.17g")
    return path


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _identify(*args):
    return _run("identify", *args)


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    d = tmp_path_factory.mktemp("bench")
    _record("engine_plant.yaml", d / "engine.csv", 3.0, seed=1)
    _record("engine_plant.yaml", d / "engine_val.csv", 2.0, seed=7)
    _record("two_mass_plant.yaml", d / "two_mass.csv", 3.0, seed=2)
    # the two-mass chart with J1 free, so that --fix-from has something to fix
    text = (ROOT / "tests" / "data" / "two_mass_euler.yaml").read_text()  # two_mass.yaml at N = 1: quick
    assert ", fixed: true}" in text
    (d / "two_mass_free.yaml").write_text(text.replace(", fixed: true}", "}"))
    # Table 1's second start
    text = (DIAGRAMS / "engine.yaml").read_text()
    assert "init: 0.6," in text
    (d / "engine_001.yaml").write_text(text.replace("init: 0.6,", "init: 0.01,"))
    return d


@pytest.fixture(scope="module")
def engine_run(bench):
    """Stage 1 of the paper on the engine record, from Table 1's first start (J1 = 0.6)."""
    out = bench / "stage1"
    out.mkdir()
    res = _identify(DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", out / "r.json", "--quiet")
    assert res.exit_code == 0, res.output
    return out / "r.json"


def test_result_document_has_the_public_keys(bench, engine_run):
    r = _strict_json(engine_run)
    j1 = r["parameters"]["J1"]
    assert set(j1) >= {"value", "stderr", "ci95", "unit", "fixed"}
    assert j1["unit"] == "kg*m^2" and j1["fixed"] is False
    assert j1["ci95"][0] < j1["value"] < j1["ci95"][1] and j1["stderr"] > 0
    w = r["nonlinear"]["MR1"]
    # the default tanh basis: 7 fixed slopes, their output weights and the linear term c
    assert len(w["a"]) == len(w["v"]) == 7 and all(math.isfinite(x) for x in w["a"] + w["v"] + [w["c"]])
    train = r["fit"]["train"]
    assert set(train) >= {"cost", "rms", "fit_percent"}
    assert set(train["rms"]) == set(train["fit_percent"]) == {"w1"}
    assert "validation" in r["fit"]
    assert r["status"] in ("max_iter", "min_grad", "mu_max", "small_step", "small_cost_change", "cost_goal",
                           "negligible_gain")
    assert r["interrupted"] is False
    # every setting, the seed, versions and the hashes of the inputs (hashlib on the files: independent)
    assert set(r["settings"]) == {f.name for f in dataclasses.fields(IdentifySettings)}
    assert r["seed"] == 0 and r["settings"]["seed"] == 0
    assert r["versions"]["sdnn"] == __version__ and r["versions"]["numpy"] == np.__version__
    assert r["chart"]["sha256"] == hashlib.sha256((DIAGRAMS / "engine.yaml").read_bytes()).hexdigest()
    assert r["data"]["train"]["sha256"] == hashlib.sha256((bench / "engine.csv").read_bytes()).hexdigest()
    assert r["data"]["train"]["rows"] == 3000
    assert r["command"]["data"] == str(bench / "engine.csv") and r["command"]["map"] == {}
    assert (engine_run.parent / "r.chart.yaml").is_file()
    assert r["identified_chart"] == str(engine_run.parent / "r.chart.yaml")


def test_identified_chart_loads_back_and_simulate_accepts_the_result(bench, engine_run):
    r = _strict_json(engine_run)
    chart = engine_run.parent / "r.chart.yaml"
    d = load_diagram(chart)
    assert {p.name: p.init for p in d.parameters} == {"J1": r["parameters"]["J1"]["value"]}
    block = next(b for b in d.blocks if b.name == "MR1")
    assert list(block.weights.a) == r["nonlinear"]["MR1"]["a"]
    assert list(block.weights.v) == r["nonlinear"]["MR1"]["v"]
    a, b = engine_run.parent / "sim_chart.csv", engine_run.parent / "sim_params.csv"
    assert _run("simulate", chart, bench / "engine.csv", "-o", a).exit_code == 0
    res = _run("simulate", DIAGRAMS / "engine.yaml", bench / "engine.csv", "--params", engine_run, "-o", b)
    assert res.exit_code == 0, res.output
    assert a.read_bytes() == b.read_bytes()
    # and the start chart simulates differently: --params did something
    c = engine_run.parent / "sim_start.csv"
    assert _run("simulate", DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", c).exit_code == 0
    assert c.read_bytes() != a.read_bytes()


@pytest.mark.parametrize("start", ["engine.yaml", "engine_001.yaml"])
def test_engine_identification_recovers_J1_from_both_table1_starts(bench, engine_run, start):
    if start == "engine.yaml":
        path = engine_run
    else:
        path = bench / "r_001.json"
        res = _identify(bench / start, bench / "engine.csv", "-o", path, "--quiet", "--max-iter", "200")
        assert res.exit_code == 0, res.output
    r = _strict_json(path)
    assert r["parameters"]["J1"]["init"] == (0.6 if start == "engine.yaml" else 0.01)
    assert abs(r["parameters"]["J1"]["value"] - J1_TRUE) / J1_TRUE < 0.02


def _metrics(y: np.ndarray, yhat: np.ndarray) -> tuple[float, float, float]:
    e = y - yhat
    return (0.5 * float(np.sum(e**2)), float(np.sqrt(np.mean(e**2))),
            100.0 * (1.0 - np.linalg.norm(e) / np.linalg.norm(y - y.mean())))


def test_cost_rms_and_fit_percent_match_a_numpy_recomputation(bench, tmp_path):
    res = _identify(DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", tmp_path / "r.json",
               "--validate", bench / "engine_val.csv", "--max-iter", "30", "--quiet")
    assert res.exit_code == 0, res.output
    r = _strict_json(tmp_path / "r.json")
    for which, data in (("train", bench / "engine.csv"), ("validation", bench / "engine_val.csv")):
        sim = tmp_path / f"sim_{which}.csv"
        res = _run("simulate", tmp_path / "r.chart.yaml", data, "-o", sim)
        assert res.exit_code == 0, res.output
        measured = np.loadtxt(data, delimiter=",", skiprows=1)  # time, M1, w1
        model = np.loadtxt(sim, delimiter=",", skiprows=1)  # time, w1
        # zoh: row 0 is the initial state, not a fitted sample
        cost, rms, fit = _metrics(measured[1:, 2], model[1:, 1])
        m = r["fit"][which]
        assert m["rows"] == len(measured) - 1
        assert m["cost"] == pytest.approx(cost, rel=1e-6)
        assert m["rms"]["w1"] == pytest.approx(rms, rel=1e-6)
        assert m["fit_percent"]["w1"] == pytest.approx(fit, rel=1e-6)
    assert r["fit"]["train"]["fit_percent"]["w1"] > 95


def test_fix_from_fixes_matching_parameters_and_curves(bench, engine_run, tmp_path):
    stage1 = _strict_json(engine_run)
    res = _identify(bench / "two_mass_free.yaml", bench / "two_mass.csv", "--fix-from", engine_run,
               "-o", tmp_path / "r2.json", "--max-iter", "40", "--quiet")
    assert res.exit_code == 0, res.output
    r = _strict_json(tmp_path / "r2.json")
    assert r["settings"]["fixed_from"] == ["J1", "MR1"]
    assert r["parameters"]["J1"]["value"] == stage1["parameters"]["J1"]["value"]
    assert r["parameters"]["J1"]["fixed"] is True and r["parameters"]["J1"]["stderr"] is None
    assert r["nonlinear"]["MR1"]["a"] == stage1["nonlinear"]["MR1"]["a"]
    assert r["nonlinear"]["MR1"]["v"] == stage1["nonlinear"]["MR1"]["v"]
    assert r["nonlinear"]["MR1"]["fixed"] is True
    assert r["nonlinear"]["MR2"]["fixed"] is False
    for name in ("J2", "c", "d"):
        p = r["parameters"][name]
        assert p["fixed"] is False and p["value"] != p["init"]
    assert "uncertainty" in r and "J1" not in r["uncertainty"]["names"]
    d = load_diagram(tmp_path / "r2.chart.yaml")
    assert next(p for p in d.parameters if p.name == "J1").fixed
    assert next(b for b in d.blocks if b.name == "MR1").fixed
    assert not next(b for b in d.blocks if b.name == "MR2").fixed


def test_split_and_validate_both_give_validation_metrics_but_not_together(bench, tmp_path):
    res = _identify(DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", tmp_path / "s.json",
               "--split", "0.7", "--max-iter", "15", "--quiet")
    assert res.exit_code == 0, res.output
    r = _strict_json(tmp_path / "s.json")
    assert r["fit"]["train"]["rows"] == 2100 - 1
    assert r["fit"]["validation"]["rows"] == 3000 - 2100
    assert r["fit"]["validation"]["rms"]["w1"] > 0 and r["settings"]["split"] == 0.7
    res = _identify(DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", tmp_path / "v.json",
               "--validate", bench / "engine_val.csv", "--max-iter", "15", "--quiet")
    assert res.exit_code == 0, res.output
    r = _strict_json(tmp_path / "v.json")
    assert r["fit"]["validation"]["rows"] == 2000 - 1
    assert r["data"]["validation"]["sha256"] == hashlib.sha256((bench / "engine_val.csv").read_bytes()).hexdigest()
    res = _identify(DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", tmp_path / "both.json",
               "--validate", bench / "engine_val.csv", "--split", "0.7")
    assert res.exit_code == 2
    assert not (tmp_path / "both.json").exists() and not (tmp_path / "both.chart.yaml").exists()


@pytest.mark.parametrize("extra", [["--max-iter", "15"], ["--starts", "3", "--seed", "5", "--max-iter", "8"]])
def test_same_inputs_and_seed_give_byte_identical_files(bench, tmp_path, extra):
    args = [DIAGRAMS / "engine.yaml", bench / "engine.csv", "-o", tmp_path / "r.json", "--quiet",
            *extra]
    assert _identify(*args).exit_code == 0
    first = (tmp_path / "r.json").read_bytes(), (tmp_path / "r.chart.yaml").read_bytes()
    assert _identify(*args, "--force").exit_code == 0
    assert ((tmp_path / "r.json").read_bytes(), (tmp_path / "r.chart.yaml").read_bytes()) == first
    r = _strict_json(tmp_path / "r.json")
    if "--starts" in extra:
        assert r["settings"]["starts"] == 3 and r["seed"] == 5 and r["multistart"]["n"] == 3
        assert len({tuple(s) for s in r["multistart"]["starts"]}) == 3  # three different starts
    # a different seed changes the run (the initial curve weights are drawn from it)
    assert _identify(*args, "--force", "--seed", "11").exit_code == 0
    assert (tmp_path / "r.json").read_bytes() != first[0]


def test_no_command_writes_over_its_inputs_or_an_existing_output(bench, tmp_path):
    data = tmp_path / "d.csv"
    data.write_bytes((bench / "engine.csv").read_bytes())
    chart = tmp_path / "m.chart.yaml"
    chart.write_bytes((DIAGRAMS / "engine.yaml").read_bytes())
    before = {p: p.read_bytes() for p in (data, chart)}
    cases = [
        ["-o", data],  # the result onto the data
        ["-o", chart],  # the result onto the chart
        ["-o", tmp_path / "m.json"],  # the identified chart m.chart.yaml onto the input chart
        ["-o", tmp_path / "sub" / ".." / "d.csv"],  # the data again, spelled differently
    ]
    (tmp_path / "sub").mkdir()
    for extra in cases:
        res = _identify(chart, data, *extra, "--force")
        assert res.exit_code == 1, (extra, res.output)
        assert len(res.stderr.strip().splitlines()) == 1 and "OUT002" in res.stderr
    assert {p: p.read_bytes() for p in (data, chart)} == before
    # an existing output (the result or the chart beside it) without --force
    for existing in ("r.json", "r.chart.yaml"):
        out = tmp_path / existing
        out.write_text("keep me\n")
        res = _identify(chart, data, "-o", tmp_path / "r.json")
        assert res.exit_code == 1 and "OUT003" in res.stderr and "--force" in res.stderr
        assert out.read_text() == "keep me\n"
        out.unlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "m.chart.yaml", "sub"]


def test_real_subprocess_run_prints_the_table_and_writes_the_files(bench, tmp_path):
    out = tmp_path / "r.json"
    proc = subprocess.run([sys.executable, "-m", "flowchart2sdnn", "identify", str(DIAGRAMS / "engine.yaml"),
                           str(bench / "engine.csv"), "-o", str(out), "--max-iter", "10"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "J1" in proc.stdout and "kg*m^2" in proc.stdout and "fit %" in proc.stdout
    assert f"wrote {out}" in proc.stdout
    r = _strict_json(out)
    assert r["optimizer"]["iterations"] <= 10
    assert (tmp_path / "r.chart.yaml").is_file()

"""Training hardening of `sdnn identify`: unstable models, starts on bounds, no excitation, a singular Jacobian,
overflowing data, and a result document that is always strict JSON (json.dumps(allow_nan=False)).

Each case must end with a clear status and a usable result, or with one clear line on stderr and no file.
Data come from the *_plant charts through `excite`, never from the model under test.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import read_csv, write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.fit.lm import STATUS_MESSAGES
from flowchart2sdnn.identify.offline.problem import required_columns
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite
from flowchart2sdnn.strictjson import strict_json

ROOT = Path(__file__).resolve().parents[1]
DIAGRAMS = ROOT / "diagrams"
J1_TRUE = 0.1912
KNOWN_STATUSES = set(STATUS_MESSAGES) | {"no_excitation", "nothing_to_fit", "completed"}

ENGINE_PRODUCT = """\
sdnn: 1
name: engine_product
description: the inertia split into two factors that only ever appear as their product
sample_time: 0.001
inputs:
  M1: {unit: N*m}
outputs:
  w1: {unit: rad/s}
parameters:
  Ja: {init: 0.5, min: 0}
  Jb: {init: 0.8, min: 0}
blocks:
  MB1:  {type: sum, in: [M1, -MR1]}
  acc1: {type: gain, in: MB1, k: 1/(Ja*Jb)}
  w1:   {type: integrator, in: acc1}
  MR1:  {type: nonlinear, in: w1, neurons: 3}
"""

ENGINE_FEEDBACK = """\
sdnn: 1
name: engine_feedback
description: a speed feedback g whose start value makes the model unstable (it grows like 1.008^k)
sample_time: 0.001
inputs:
  M1: {unit: N*m}
outputs:
  w1: {unit: rad/s}
parameters:
  J1: {init: 0.6, min: 0.01}
  g: {init: 5}
blocks:
  MB1:  {type: sum, in: [M1, -MR1, G]}
  acc1: {type: gain, in: MB1, k: 1/J1}
  w1:   {type: integrator, in: acc1}
  G:    {type: gain, in: w1, k: g}
  MR1:  {type: nonlinear, in: w1, neurons: 3, basis: neurons}
"""


def _record(path: Path, seconds: float, seed: int, noise: float = 0.01, plant: str = "engine_plant.yaml",
            **excitation) -> Path:
    settings = ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise, **excitation)
    write_csv(path, excite(load_diagram(DIAGRAMS / plant), settings), float_format="%.17g")
    return path


def _engine_chart(path: Path, j1: str) -> Path:
    text = (DIAGRAMS / "engine.yaml").read_text()
    old = "J1: {init: 0.6, unit: kg*m^2, min: 0,"
    assert old in text
    path.write_text(text.replace(old, "J1: {" + j1 + ", unit: kg*m^2,"))
    return path


def _fit(chart: Path, data: Path, **settings):
    diagram = load_diagram(chart)
    ds = read_csv(data, required_columns(diagram), None, diagram.sample_time)
    outcome = identify(diagram, ds, None, IdentifySettings(**settings))
    text = json.dumps(outcome.result, allow_nan=False)  # raises on NaN or inf anywhere in the document
    assert outcome.result["status"] in KNOWN_STATUSES | {"interrupted", "diverged_at_start"}
    for p in outcome.result["parameters"].values():
        assert math.isfinite(p["value"])
    return outcome, json.loads(text)


def _identify_cli(*args):
    return CliRunner().invoke(main, ["identify", *[str(a) for a in args]], catch_exceptions=False)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("hardening")
    _record(d / "engine.csv", 3.0, seed=1)
    _record(d / "engine_long.csv", 6.0, seed=4)  # longer than one online chunk (5000 samples)
    _record(d / "two_mass.csv", 2.0, seed=2, plant="two_mass_plant.yaml")
    _record(d / "zero.csv", 2.0, seed=3, amplitude=(0.0, 0.0), relay_level=0.0)
    (d / "product.yaml").write_text(ENGINE_PRODUCT)
    (d / "feedback.yaml").write_text(ENGINE_FEEDBACK)
    return d


def test_a_start_that_makes_the_model_diverge_is_one_clear_line_and_no_file(data, tmp_path):
    text = (ROOT / "tests" / "data" / "two_mass_euler.yaml").read_text()  # two_mass.yaml at one step per sample
    chart = tmp_path / "stiff.yaml"
    chart.write_text(text.replace("c:  {init: 100,", "c:  {init: 1000000,"))  # far beyond 4*J/T^2
    out = tmp_path / "out"
    out.mkdir()
    res = _identify_cli(chart, data / "two_mass.csv", "-o", out / "r.json")
    assert res.exit_code == 1
    assert res.stderr.count("\n") == 1 and res.stderr.startswith(f"{chart}: error[FIT001]")
    assert "init" in res.stderr
    assert list(out.iterdir()) == []
    # the library says so too, with the same diagnostic
    with pytest.raises(SdnnError) as info:
        _fit(chart, data / "two_mass.csv", max_iter=5)
    assert info.value.diagnostics[0].code == "FIT001"


def test_an_unstable_but_finite_start_ends_with_a_usable_result(data):
    # single shooting's own handling of the growing start (auto would cut the record: identify.shooting.auto), from
    # the chart's random curves (the default stick-slip start, identify.offline.curvestart, damps the feedback g away)
    outcome, r = _fit(data / "feedback.yaml", data / "engine.csv", max_iter=25, shooting="off", curve_start="random")
    history = r["optimizer"]["cost_history"]
    assert history[0] > 1e15  # the start grows like (1 + T g / J1)^k over 3000 samples
    assert history[-1] < history[0] and all(math.isfinite(c) for c in history)
    assert r["status"] in STATUS_MESSAGES
    # the reported cost is the free-run cost of the final values (finite here), never NaN
    assert r["fit"]["train"]["cost"] is None or math.isfinite(r["fit"]["train"]["cost"])


def test_data_too_large_to_square_is_one_line_naming_file_and_column(data, tmp_path):
    rows = np.loadtxt(data / "engine.csv", delimiter=",", skiprows=1)
    huge = tmp_path / "huge.csv"
    write_csv(huge, {"time": rows[:, 0], "M1": rows[:, 1] * 1e200, "w1": rows[:, 2] * 1e200}, "%.17g")
    out = tmp_path / "out"
    out.mkdir()
    res = _identify_cli(DIAGRAMS / "engine.yaml", huge, "-o", out / "r.json")
    assert res.exit_code == 1 and res.stderr.count("\n") == 1
    assert res.stderr.startswith(f"{huge}: error[DATA002] column 'M1'")
    assert list(out.iterdir()) == []


def test_start_on_the_lower_bound_still_recovers_J1(data, tmp_path):
    chart = _engine_chart(tmp_path / "lo.yaml", "init: 0.05, min: 0.05, max: 1")
    outcome, r = _fit(chart, data / "engine.csv")
    assert abs(r["parameters"]["J1"]["value"] - J1_TRUE) / J1_TRUE < 0.02
    assert any("J1 starts on its lower bound" in w for w in r["warnings"])
    assert {"code": "START002", "parameter": "J1", "side": "lower", "value": 0.05} in [
        {"code": n["code"], **n["numbers"]} for n in r["notices"]]


def test_start_on_the_upper_bound_is_warned_about_and_stays_within_bounds(data, tmp_path):
    chart = _engine_chart(tmp_path / "hi.yaml", "init: 0.6, min: 0.05, max: 0.6")
    outcome, r = _fit(chart, data / "engine.csv", max_iter=30)
    assert 0.05 <= r["parameters"]["J1"]["value"] <= 0.6
    assert r["parameters"]["J1"]["value"] < 0.6  # it did leave the bound, towards the truth
    assert any("J1 starts on its upper bound" in w for w in r["warnings"])


def test_zero_excitation_gives_status_no_excitation_and_the_start_values(data, tmp_path):
    rows = np.loadtxt(data / "zero.csv", delimiter=",", skiprows=1)
    assert not np.any(rows[:, 1])  # the input really is all zeros (the output is noise only)
    outcome, r = _fit(DIAGRAMS / "engine.yaml", data / "zero.csv")
    assert r["status"] == "no_excitation"
    assert "constant input: M1" in r["message"]
    assert r["parameters"]["J1"]["value"] == 0.6 and r["parameters"]["J1"]["stderr"] is None
    assert "uncertainty" not in r
    res = _identify_cli(data / "zero.csv", "--diagram", DIAGRAMS / "engine.yaml", "-o", tmp_path / "r.json")
    assert res.exit_code == 0 and "status: no_excitation" in res.stdout
    json.loads((tmp_path / "r.json").read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON {c}"))


def test_parameters_that_only_appear_as_a_product_are_reported_not_crashed_on(data):
    outcome, r = _fit(data / "product.yaml", data / "engine.csv")
    ja, jb = r["parameters"]["Ja"], r["parameters"]["Jb"]
    assert abs(ja["value"] * jb["value"] - J1_TRUE) / J1_TRUE < 0.02  # the product is identified
    assert ja["stderr"] is None and jb["stderr"] is None and ja["ci95"] is None  # the factors are not
    assert any("Ja" in w and "Jb" in w and "told apart" in w for w in r["warnings"])
    assert any(n["code"] == "IDENT001" and set(n["numbers"]["parameters"]) == {"Ja", "Jb"} for n in r["notices"])
    assert r["uncertainty"]["condition_number"] is None or r["uncertainty"]["condition_number"] > 1e8


def test_non_finite_values_never_reach_the_document():
    bad: list[str] = []
    doc = strict_json({"a": [1.0, math.nan, {"b": math.inf}], "c": np.float64(-math.inf), "d": "x", "e": 2},
                     "", bad)
    assert doc == {"a": [1.0, None, {"b": None}], "c": None, "d": "x", "e": 2}
    assert bad == ["a[1]", "a[2].b", "c"]
    json.dumps(doc, allow_nan=False)


def test_stop_request_ends_offline_and_online_runs_as_interrupted(data):
    diagram = load_diagram(DIAGRAMS / "engine.yaml")
    ds = read_csv(data / "engine.csv", required_columns(diagram), None, diagram.sample_time)
    calls = []

    def stop():
        calls.append(1)
        return len(calls) >= 3

    offline = identify(diagram, ds, None, IdentifySettings(max_iter=500), stop=stop)
    r = offline.result
    assert r["status"] == "interrupted" and r["interrupted"] is True
    assert r["optimizer"]["iterations"] == 3 and "Ctrl-C" in r["message"]
    json.dumps(r, allow_nan=False)
    # online runs poll between chunks of 5000 samples
    ds = read_csv(data / "engine_long.csv", required_columns(diagram), None, diagram.sample_time)
    online = identify(diagram, ds, None, IdentifySettings(online=True, window=500, average=100), stop=lambda: True)
    assert online.result["status"] == "interrupted" and online.result["online"]["steps"] < ds.n_rows - 1
    json.dumps(online.result, allow_nan=False)

"""Per-record parameters (`per_record: true`): one value per training record, shared values for the rest.

Oracles: central finite differences of the Problem's own residual for the Jacobian, the offsets a continuous
plant (RK4) was simulated with for the identified values, and a hand-computed mean; never numbers taken from
this code's output.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.report.identify_text import format_result
from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import aprbs

CHART = """\
sdnn: 1
name: motor_offset
sample_time: 0.01
inputs:
  M: {unit: N*m}
outputs:
  w: {unit: rad/s}
parameters:
  J: {init: 0.02, min: 0, unit: kg*m^2}
  b: {init: 0.01, min: 0, unit: N*m*s/rad}
  off: {init: 0.0, unit: N*m, per_record: PR}
blocks:
  T0: {type: constant, k: off}
  s: {type: sum, in: [M, T0, -Mb]}
  a: {type: gain, in: s, k: 1/J}
  w: {type: integrator, in: a}
  Mb: {type: gain, in: w, k: b}
"""
TRUTH = {"J": 0.025, "b": 0.012}
OFFSETS = (0.03, -0.02, 0.01)


def _chart(tmp_path, per_record="true"):
    path = tmp_path / "motor_offset.yaml"
    path.write_text(CHART.replace("PR", per_record))
    return load_diagram(path)


def _record(chart, seed: int, off: float, q: int = 400, noise: float = 0.0):
    rng = np.random.default_rng(seed)
    u = aprbs(q, chart.sample_time, rng, (-0.1, 0.1))
    y = simulate_continuous(chart, u[:, None], parameters={**TRUTH, "off": off}, init={"w": 0.0})[:, 0]
    y = y + noise * rng.standard_normal(y.shape)
    frame = {"time": np.arange(q) * chart.sample_time, "M": u, "w": y}
    return sd.dataset_from_frame(frame, time="time", inputs=["M"], outputs=["w"])


def test_per_record_must_be_a_boolean_with_its_line(tmp_path):
    with pytest.raises(SdnnError, match=r"motor_offset.yaml:11:\d+.*'per_record' must be true or false, found 3"):
        _chart(tmp_path, "3")


def test_one_value_per_record_and_the_jacobian_equals_central_differences(tmp_path):
    chart = _chart(tmp_path)
    records = [_record(chart, s, off) for s, off in zip((1, 2, 3), OFFSETS, strict=True)]
    problem = build_problem(chart, records[0], more=records[1:])
    assert problem.names[-2:] == ("off@2", "off@3") and problem.record_params == ("off",)
    x = problem.expand(problem.compiled.theta0())
    x = x + np.linspace(0.001, 0.004, x.size)  # every record's offset different, away from the start
    e, jac = problem.fun(x)
    fd = np.empty_like(jac)
    for i in range(x.size):
        h = 1e-6 * max(1.0, abs(x[i]))
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        fd[:, i] = (problem.residual(down) - problem.residual(up)) / (2 * h)  # d yhat = -d e
    assert np.max(np.abs(jac - fd)) <= 1e-6 * max(1.0, np.max(np.abs(fd)))
    # record k's rows depend on record k's offset only
    rows = [s.targets.size for s in problem.segments]
    edges = np.cumsum([0] + rows)
    off = problem.record_index()["off"]
    for k in range(3):
        block = jac[edges[k]:edges[k + 1]]
        for j in range(3):
            assert np.any(block[:, off[j]]) == (j == k)


def test_a_single_record_keeps_one_value(tmp_path):
    chart = _chart(tmp_path)
    problem = build_problem(chart, _record(chart, 1, 0.02))
    assert problem.record_params == () and "off@2" not in problem.names


def test_identify_recovers_each_offset_reports_the_mean_and_fits_validation_on_its_window(tmp_path):
    chart = _chart(tmp_path)
    records = [_record(chart, s, off, noise=0.002) for s, off in zip((1, 2, 3), OFFSETS, strict=True)]
    val_off = -0.04
    validation = _record(chart, 9, val_off, noise=0.002)
    result = sd.identify(chart, records, validation, max_iter=200, init_window=150)
    doc = json.loads(result.to_json())
    per = doc["parameters_per_record"]["off"]
    assert [r["record"] for r in per] == [r.path for r in records]
    for r, truth in zip(per, OFFSETS, strict=True):
        assert r["value"] == pytest.approx(truth, abs=2e-3)
        assert r["ci95"][0] < r["value"] < r["ci95"][1]
    # the shared parameters are shared, the `parameters` entry of `off` is the mean of the records' values
    assert result.parameters["J"].value == pytest.approx(TRUTH["J"], rel=0.03)
    mean = sum(r["value"] for r in per) / 3
    assert result.parameters["off"].value == pytest.approx(mean, abs=1e-12)
    assert doc["parameters"]["off"]["ci95"][0] < mean < doc["parameters"]["off"]["ci95"][1]
    # the validation record's own offset, fitted on its first 150 samples with J and b fixed
    fitted = doc["initial_states"]["validation"]["parameters"]["off"]
    assert fitted == pytest.approx(val_off, abs=3e-3)
    text = format_result(result)
    assert "per-record parameters" in text and records[2].path in text and "validation record: off" in text
    # without the window the validation record runs with the mean: worse than with its own offset
    plain = sd.identify(chart, records, validation, max_iter=200)
    assert plain.fit.validation.rms["w"] > 2 * result.fit.validation.rms["w"]

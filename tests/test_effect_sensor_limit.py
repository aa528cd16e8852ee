"""The sensor-limit effect (issue 16): a measured output clipped at learned limits.

Oracles: the chart's own outputs clipped by hand (numpy), and a virtual test bench whose measured speed is
clipped by hand after the continuous simulation; the truths are the plant's parameters and the clip.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnose_bench import aprbs_input, chart, record, simulate

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS, Scales, SensorLimit
from flowchart2sdnn.diagnose.graph import Place
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagram.validate import diagram_from_text

TWO = chart("two_mass_nominal")


def _set(diagram, **values):
    return dataclasses.replace(diagram, parameters=tuple(
        dataclasses.replace(p, init=values[p.name]) if p.name in values else p for p in diagram.parameters))


def test_the_patched_output_is_the_charts_output_clipped_and_the_dynamics_are_untouched():
    patched = _set(SensorLimit().patch(TWO, Place("w2", "output"), 1.0), w2_lim=1.0, w2_off=-0.2)
    u = aprbs_input(3000, seed=7)
    plain = simulate(TWO, u)
    i2 = TWO.output_names.index("w2")
    assert plain[:, i2].min() < -1.5 and plain[:, i2].max() > 1.0  # the clip at [-1.2, 0.8] acts
    expected = plain.copy()
    expected[:, i2] = np.clip(plain[:, i2], -1.2, 0.8)
    np.testing.assert_allclose(simulate(patched, u), expected, rtol=0, atol=1e-9)
    assert patched.output_names == TWO.output_names and patched.block("w2").kind == "sum"
    assert patched.block("w2_true").kind == "integrator"


def test_limits_are_scanned_from_the_outputs_range_and_outputs_started_from_data_are_not_offered():
    opts = SensorLimit(fractions=(0.5, 0.9)).options(TWO, Place("w2", "output"), Scales({}, {"w2": -4.0}, {"w2": 8.0}))
    assert opts == (4.0, 7.2)
    text = """
sdnn: 1
name: from_data
sample_time: 0.001
inputs: {F: {}}
outputs: {v: {}, x: {}}
parameters: {m: {init: 2}}
blocks:
  acc: {type: gain, in: F, k: 1/m}
  v:   {type: integrator, in: acc, init: data}
  x:   {type: integrator, in: v}
"""
    d = diagram_from_text(text, "from_data.yaml")
    assert [p.at for p in SensorLimit().places(d)] == ["x"]


def test_a_clipped_speed_sensor_is_found_at_its_output_with_its_limits():
    plant = chart("one_mass_plant")
    excitation = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
    train, val = (record(plant, s, seed, 0.02, **excitation) for s, seed in ((6.0, 3), (3.0, 101)))
    lo, hi = -0.6, 0.85
    assert train.columns["v"].min() < lo - 0.25 and train.columns["v"].max() > hi + 0.25
    for r in (train, val):
        r.columns["v"] = np.clip(r.columns["v"], lo, hi)
    effects = [BUILTIN_EFFECTS[n] for n in ("friction", "damping", "dead_time", "saturation", "sensor_limit")]
    report = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(rounds=2), effects).report
    first = report["accepted"][0]
    assert (first["effect"], first["at"]) == ("sensor_limit", "v"), report["accepted"]
    p = report["final"]["parameters"]
    assert p["v_off"]["value"] - p["v_lim"]["value"] == pytest.approx(lo, abs=0.01)
    assert p["v_off"]["value"] + p["v_lim"]["value"] == pytest.approx(hi, abs=0.01)
    assert p["m"]["value"] == pytest.approx(2.0, rel=0.05) and p["b"]["value"] == pytest.approx(0.5, rel=0.05)
    rnd = report["rounds"][0]
    # the rule: within 1.2x of the noise (the clipped samples carry less than the noise) or 3x lower
    assert rnd["validation_rms_after"] <= 1.2 * 0.02 or rnd["validation_rms_after"] < rnd["validation_rms_before"] / 3

"""Physical friction (`Coulomb`, the "coulomb" option of `friction`): asymmetric Coulomb and viscous friction
with named parameters (issue 5, EMPS).

Oracles: a hand-written forward-Euler recursion of the one-mass chart with ``Fc tanh(v/eps) + c +
dFv max(v, 0)`` (numpy's maximum, not the patch's clip construction), and diagnose runs on records of the
continuous simulation of plant charts (a plant with asymmetric friction, a plant without), never of the model
under test; the truths are the plants' parameters.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnose_bench import aprbs_input, chart, record, simulate

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS, Coulomb, Friction, Physical, Scales
from flowchart2sdnn.diagnose.graph import speeds
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagram.validate import diagram_from_text

NOISE = 0.02
EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
EFFECTS = [BUILTIN_EFFECTS[n] for n in ("friction", "damping", "dead_time", "saturation")]

# one mass (m = 2, b = 0.5) with Coulomb friction 1.0 N, an offset of 0.3 N (levels 1.3 N forwards, 0.7 N
# backwards) and 0.4 N*s/m more viscous friction forwards; max(v, 0) = 20*sat((v - 20)/20) + 20 for v < 40
PLANT = """
sdnn: 1
name: one_mass_asymmetric_friction_plant
sample_time: 0.001
inputs: {F: {unit: N}}
outputs: {v: {unit: m/s}}
parameters:
  m:   {init: 2.0, unit: kg}
  b:   {init: 0.5, unit: N*s/m}
  Fc:  {init: 1.0, unit: N}
  c:   {init: 0.3, unit: N}
  dFv: {init: 0.4, unit: N*s/m}
blocks:
  Fsum: {type: sum, in: [F, -Fv, -Fsg, -off, -Fup], unit: N}
  acc:  {type: gain, in: Fsum, k: 1/m, unit: m/s^2}
  v:    {type: integrator, in: acc, unit: m/s}
  Fv:   {type: gain, in: v, k: b, unit: N}
  sg:   {type: function, f: sign_smooth, in: v, eps: 0.01}
  Fsg:  {type: gain, in: sg, k: Fc, unit: N}
  off:  {type: constant, k: c, unit: N}
  top:  {type: constant, k: 20, unit: m/s}
  sh:   {type: sum, in: [v, -top], unit: m/s}
  cl:   {type: function, f: sat, in: sh, k: 0.05}
  gl:   {type: gain, in: cl, k: 20, unit: m/s}
  up:   {type: sum, in: [gl, top], unit: m/s}
  Fup:  {type: gain, in: up, k: dFv, unit: N}
"""


def _set(diagram, **values):
    return dataclasses.replace(diagram, parameters=tuple(
        dataclasses.replace(p, init=values[p.name]) if p.name in values else p for p in diagram.parameters))


def test_the_neutral_patch_leaves_the_outputs_unchanged():
    one = chart("one_mass")
    patched = Coulomb().patch(one, speeds(one)[0], 0.8)
    assert {"Fc_v", "c_v", "dFv_v"} <= set(patched.parameter_names)
    assert patched.parameter("Fc_v").min == 0.0
    compile_diagram(patched)
    u = aprbs_input(3000, seed=3)
    np.testing.assert_allclose(simulate(patched, u), simulate(one, u), rtol=0, atol=1e-12)
    # without the viscous part only Fc and c are added
    assert "dFv_v" not in Coulomb(asymmetric=False).patch(one, speeds(one)[0], 0.8).parameter_names


@pytest.mark.parametrize("asymmetric", [True, False])
def test_with_values_set_the_patch_is_the_hand_written_friction(asymmetric):
    one = chart("one_mass")  # m = 2.4, b = 0.4
    scale, fc, c, dfv = 0.5, 0.9, -0.25, 0.6
    patched = Coulomb(asymmetric=asymmetric).patch(one, speeds(one)[0], scale)
    patched = _set(patched, Fc_v=fc, c_v=c, **({"dFv_v": dfv} if asymmetric else {}))
    u = 2.0 * aprbs_input(4000, seed=11)
    y = simulate(patched, u)[:, 0]
    m, b, T, eps = 2.4, 0.4, 0.001, scale / 100.0
    v = np.zeros(len(u) + 1)
    for k in range(len(u)):
        friction = fc * np.tanh(v[k] / eps) + c + (dfv * max(v[k], 0.0) if asymmetric else 0.0)
        v[k + 1] = v[k] + T * (u[k, 0] - b * v[k] - friction) / m
    assert np.max(np.abs(v)) > 0.5 and np.min(v) < -0.5  # both directions, beyond eps
    np.testing.assert_allclose(y, v[:-1], rtol=1e-10, atol=1e-12)


def test_friction_offers_the_physical_terms_as_a_second_option_of_the_same_place():
    one = chart("one_mass")
    place = speeds(one)[0]
    assert Coulomb().options(one, place, Scales({"v": 0.3})) == (0.3,)
    # the learned curve's option is the speed's span (its largest |value|, 3 RMS where unknown)
    opts = BUILTIN_EFFECTS["friction"].options(one, place, Scales({"v": 0.3}, {"v": -0.5}, {"v": 0.8}))
    assert opts == (0.8, Physical(0.3)) and str(opts[1]) == "coulomb"
    assert [Friction().label(o) for o in opts] == ["", "coulomb"]
    assert Friction(physical=None).options(one, place, Scales({"v": 0.3})) == (pytest.approx(0.9),)
    via_friction = Friction().patch(one, place, Physical(0.3))
    assert via_friction == Coulomb().patch(one, place, 0.3)
    assert "coulomb" not in BUILTIN_EFFECTS  # reached through friction: one (effect, place) key, one refit slot


def _run(plant, seed: int = 3):
    train = record(plant, 6.0, seed, NOISE, **EXCITATION)
    val = record(plant, 3.0, seed + 98, NOISE, **EXCITATION)
    return diagnose(chart("one_mass"), train, [val], DiagnoseSettings(rounds=2), EFFECTS).report


def test_asymmetric_friction_is_found_with_its_physical_values():
    r = _run(diagram_from_text(PLANT))
    assert r["accepted"][0] == {"effect": "friction", "at": "v", "option": "coulomb", "label": "coulomb"}
    first = r["rounds"][0]
    assert first["validation_rms_after"] < first["validation_rms_before"] / 3
    assert first["validation_rms_after"] < 1.2 * NOISE
    p = {k: v["value"] for k, v in r["final"]["parameters"].items()}
    assert p["m"] == pytest.approx(2.0, rel=0.03) and p["b"] == pytest.approx(0.5, rel=0.1)
    assert p["Fc_v"] == pytest.approx(1.0, rel=0.1) and p["c_v"] == pytest.approx(0.3, abs=0.05)
    assert p["dFv_v"] == pytest.approx(0.4, abs=0.1)


def test_nothing_is_added_when_the_plant_has_no_friction_beyond_the_viscous():
    r = _run(chart("one_mass_plant"), seed=5)
    assert r["accepted"] == [], r["rounds"]

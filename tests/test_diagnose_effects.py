"""The effects library: where each effect attaches, and what its patch does to a chart's outputs.

Oracles: signs derived by hand from the physics (friction opposes motion, shaft damping acts on both masses
with opposite signs), hand-shifted and hand-clipped inputs, and hand-written equivalent charts.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnose_bench import aprbs_input, chart, simulate

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagnose.effects import (
    BUILTIN_EFFECTS,
    Backlash,
    Cogging,
    Damping,
    DeadTime,
    DeadZone,
    Friction,
    Saturation,
    Scales,
    select_effects,
)
from flowchart2sdnn.diagnose.graph import Place, speed_differences, speeds, spring_angles
from flowchart2sdnn.diagram.model import NonlinearWeights
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.errors import SdnnError

TWO = chart("two_mass_nominal")


def _place(places, at):
    return next(p for p in places if p.at == at)


def _set_param(diagram, name, value):
    return dataclasses.replace(diagram, parameters=tuple(
        dataclasses.replace(p, init=value) if p.name == name else p for p in diagram.parameters))


# ------------------------------------------------------------------------------------------------ places
def test_speeds_are_integrated_torque_sums_and_friction_enters_against_the_motion():
    places = speeds(TWO)
    assert {p.at: p.sums for p in places} == {"w1": (("MB1", -1),), "w2": (("MB2", -1),)}
    assert "dphi" not in {p.at for p in places}  # an angle: no mass gain between sum and integrator


def test_a_negative_mass_gain_flips_the_sign_of_the_friction_term():
    text = """
sdnn: 1
name: flipped
sample_time: 0.001
inputs: {F: {}}
outputs: {v: {}}
parameters: {m: {init: 2}}
blocks:
  S:   {type: sum, in: [-F]}
  acc: {type: gain, in: S, k: -1/m}
  v:   {type: integrator, in: acc}
"""
    (p,) = speeds(diagram_from_text(text))
    assert p.sums == (("S", 1),)  # v' = -S/m: a term +x in S decelerates, so friction enters with +


def test_shaft_damping_acts_on_both_masses_with_opposite_signs():
    (p,) = speed_differences(TWO)
    # MD = d*(w1 - w2) enters MB1 with - and MB2 with +, exactly as the chart's own damping does
    assert p.at == "dw" and p.sums == (("MB1", -1), ("MB2", 1))


def test_the_spring_angle_is_found_with_its_spring_gain():
    (p,) = spring_angles(TWO)
    assert (p.at, p.kind, p.via) == ("dphi", "spring_angle", "MC")


# ------------------------------------------------------------------------------------------------ neutral
NEUTRAL = [(Friction(), "w2", 4.0), (Friction(), "w1", 4.0), (Damping(), "w2", None), (Damping(), "dw", None),
           (Backlash(), "dphi", 0.01), (Cogging(), "w1", 3), (Cogging(), "w2", 1)]


@pytest.mark.parametrize("effect,at,option", NEUTRAL, ids=lambda x: str(x)[:20])
def test_a_neutral_patch_leaves_the_outputs_unchanged_and_the_chart_untouched(effect, at, option):
    places = effect.places(TWO)
    before = dataclasses.replace(TWO)
    patched = effect.patch(TWO, _place(places, at), option)
    assert TWO == before and patched != TWO  # a new chart; the input is not mutated
    assert len(patched.blocks) > len(TWO.blocks)
    compile_diagram(patched)  # lint-clean
    u = aprbs_input(3000, seed=3)
    np.testing.assert_allclose(simulate(patched, u), simulate(TWO, u), rtol=0, atol=1e-12)


def test_patches_compose_into_one_chart():
    d = TWO
    for effect, at, option in NEUTRAL:
        d = effect.patch(d, _place(effect.places(d), at), option)
    u = aprbs_input(2000, seed=4)
    np.testing.assert_allclose(simulate(d, u), simulate(TWO, u), rtol=0, atol=1e-12)
    assert len({b.name for b in d.blocks}) == len(d.blocks)


# ------------------------------------------------------------------------------------------------ not neutral
@pytest.mark.parametrize("n", [1, 4])
def test_dead_time_equals_the_chart_driven_by_the_input_shifted_by_n_samples(n):
    # the dead time is the input's `delay`, a new parameter started at n samples: the chart's blocks stay
    one = chart("one_mass")
    patched = DeadTime().patch(one, Place("F", "input"), n)
    assert patched.blocks == one.blocks and patched.inputs[0].delay == "tau_F"
    assert patched.parameter("tau_F").init == pytest.approx(n * one.sample_time)
    u = aprbs_input(2500, seed=5)
    shifted = np.concatenate([np.repeat(u[:1], n, axis=0), u[:-n]])  # history: the first sample held
    np.testing.assert_allclose(simulate(patched, u), simulate(one, shifted), rtol=1e-12, atol=1e-12)


def test_saturation_equals_the_chart_driven_by_the_clipped_input():
    patched = Saturation().patch(TWO, Place("M1", "input"), 3.0)
    patched = _set_param(patched, "M1_off", 0.5)  # limits 0.5 -+ 3 = [-2.5, 3.5]
    u = aprbs_input(2500, seed=6)
    np.testing.assert_allclose(simulate(patched, u), simulate(TWO, np.clip(u, -2.5, 3.5)), rtol=1e-12,
                               atol=1e-12)


def test_saturation_options_scan_the_data_range():
    opts = Saturation(fractions=(0.5, 0.9)).options(TWO, Place("M1", "input"), Scales({}, {"M1": -8.0}, {"M1": 6.0}))
    assert opts == (4.0, 7.2)


CHART_WITH = """
sdnn: 1
name: by_hand
sample_time: 0.001
substeps: 1
delays: search
inputs: {M1: {}}
outputs: {w1: {}, w2: {}}
parameters: {J1: {init: 0.17}, J2: {init: 0.43}, c: {init: 420}, d: {init: 0.3}, b1: {init: 0.04}}
blocks:
  MB1:  {type: sum, in: [M1, -MC, -MD, -MV1]}
  acc1: {type: gain, in: MB1, k: 1/J1}
  w1:   {type: integrator, in: acc1}
  MV1:  {type: gain, in: w1, k: b1}
  dw:   {type: sum, in: [w1, -w2]}
  dphi: {type: integrator, in: dw}
  MC:   {type: gain, in: dphi, k: c}
  MD:   {type: gain, in: dw, k: d}
  MB2:  {type: sum, in: [MC, MD, EXTRA]}
  acc2: {type: gain, in: MB2, k: 1/J2}
  w2:   {type: integrator, in: acc2}
"""


def test_cogging_with_amplitudes_set_equals_a_hand_written_chart():
    patched = Cogging().patch(TWO, _place(speeds(TWO), "w2"), 3)
    patched = _set_param(_set_param(patched, "cog3_A_w2", 0.4), "cog3_B_w2", -0.2)
    hand = CHART_WITH.replace("EXTRA", "-T3").replace(
        "  w2:   {type: integrator, in: acc2}\n",
        "  w2:   {type: integrator, in: acc2}\n  ph:   {type: integrator, in: w2}\n"
        "  s3:   {type: function, f: sin, in: ph, k: 3}\n  c3:   {type: function, f: cos, in: ph, k: 3}\n"
        "  A3:   {type: gain, in: s3, k: 0.4}\n  B3:   {type: gain, in: c3, k: -0.2}\n"
        "  T3:   {type: sum, in: [A3, B3]}\n")
    u = aprbs_input(3000, seed=7)
    np.testing.assert_allclose(simulate(patched, u), simulate(diagram_from_text(hand), u), rtol=1e-10, atol=1e-10)


def test_friction_with_weights_set_equals_a_hand_written_curve():
    patched = Friction().patch(TWO, _place(speeds(TWO), "w2"), 1.0)
    curve = patched.block("fric_w2")
    assert curve.basis == "tanh" and set(curve.weights.v) == {0.0}  # neutral: the flat curve of the basis
    patched = dataclasses.replace(patched, blocks=tuple(
        dataclasses.replace(b, weights=NonlinearWeights((8.0,), (0.7,), None)) if b.name == "fric_w2" else b
        for b in patched.blocks))
    hand = CHART_WITH.replace("EXTRA", "-FR").replace(
        "  w2:   {type: integrator, in: acc2}\n",
        "  w2:   {type: integrator, in: acc2}\n  th:   {type: function, f: tanh, in: w2, k: 8}\n"
        "  FR:   {type: gain, in: th, k: 0.7}\n")
    u = aprbs_input(3000, seed=8)
    np.testing.assert_allclose(simulate(patched, u), simulate(diagram_from_text(hand), u), rtol=1e-10, atol=1e-10)


def test_dead_zone_equals_a_hand_written_dead_zone_in_the_shaft():
    patched = DeadZone().patch(TWO, _place(spring_angles(TWO), "dphi"), 0.003)
    assert patched.parameter("dphi_gap").init == 0.003 and patched.parameter("dphi_gap").min == 0.0
    hand = CHART_WITH.replace(", EXTRA", "").replace(
        "  MC:   {type: gain, in: dphi, k: c}\n",
        "  MC:   {type: gain, in: dz, k: c}\n  cl:   {type: function, f: sat, in: dphi, k: 1/0.003}\n"
        "  gw:   {type: gain, in: cl, k: 0.003}\n  dz:   {type: sum, in: [dphi, -gw]}\n")
    u = aprbs_input(3000, seed=9)
    np.testing.assert_allclose(simulate(patched, u), simulate(diagram_from_text(hand), u), rtol=1e-10, atol=1e-10)
    assert DeadZone(fractions=(0.1, 0.5)).options(TWO, Place("dphi", "spring_angle", via="MC"),
                                                  Scales({"dphi": 0.02})) == (0.002, 0.01)


def test_backlash_keeps_the_spring_signal_name_and_adds_an_odd_curve():
    patched = Backlash().patch(TWO, _place(spring_angles(TWO), "dphi"), 0.01)
    mc = patched.block("MC")
    assert mc.kind == "sum" and {t.signal for t in mc.inputs} == {"MC_lin", "bl_dphi"}
    assert patched.block("MC_lin").k == TWO.block("MC").k
    curve = patched.block("bl_dphi")
    # odd (no bias), flat at the start, and no linear term of its own: the spring's gain is that
    assert not curve.bias and set(curve.weights.v) == {0.0} and curve.weights.c is None


def test_new_names_never_clash_with_existing_ones():
    once = Damping().patch(TWO, _place(speeds(TWO), "w2"))
    twice = Damping().patch(once, _place(speeds(once), "w2"))
    assert {"b_w2", "b_w2_2", "damp_w2", "damp_w2_2"} <= set(twice.parameter_names) | set(twice.block_names)


def test_damping_starts_at_its_lower_bound_zero():
    patched = Damping().patch(TWO, _place(speeds(TWO), "w1"))
    p = patched.parameter("b_w1")
    assert (p.init, p.min) == (0.0, 0.0)


def test_the_registry_names_and_selection():
    assert set(BUILTIN_EFFECTS) == {"friction", "damping", "dead_time", "saturation", "backlash", "dead_zone",
                                    "cogging", "spring", "overflow", "sensor_limit", "sensor_offset", "input_offset",
                                    "linear_term"}
    assert [e.name for e in select_effects(["dead_time", " friction"], BUILTIN_EFFECTS)] == ["dead_time", "friction"]
    with pytest.raises(SdnnError, match="did you mean 'friction'"):
        select_effects(["fricton"], BUILTIN_EFFECTS)
    for e in BUILTIN_EFFECTS.values():
        assert e.describe().startswith(e.name)

"""Effects at positions: where a position is, the learned spring to ground, and cogging reading the chart's angle.

Oracles: signs derived by hand from the physics (a spring to ground pulls the mass back), hand-written
equivalent charts, and for the diagnosis a mass on a hardening spring simulated by scipy's solve_ivp
(tests/smooth_oracle.py: DOP853, rtol 1e-10), not by the network under test.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import smooth_oracle as so
from diagnose_bench import aprbs_input, chart, simulate

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import Dataset
from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS, Cogging, Spring
from flowchart2sdnn.diagnose.graph import Place, positions, signal_place, speeds, states
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagram.model import NonlinearWeights
from flowchart2sdnn.diagram.validate import diagram_from_text

# a mass on a linear spring to ground: 2 Hz, 5 % damping, sampled at 10 ms (50 samples a period)
F0 = 2.0
K = (2 * np.pi * F0) ** 2
D = 2 * 0.05 * 2 * np.pi * F0
K3 = 0.5 * K  # the plant's hardening: at x = 1 m the cubic is half the linear force

LINEAR = f"""
sdnn: 1
name: ground_spring
sample_time: 0.01
inputs: {{u: {{unit: N}}}}
outputs: {{x: {{unit: m}}}}
parameters:
  m: {{init: 1.0, unit: kg, fixed: true}}
  k: {{init: {K:.6g}, unit: N/m, min: 0}}
  d: {{init: {D:.6g}, unit: N*s/m, min: 0}}
blocks:
  F:  {{type: sum, in: [u, -Fk, -Fd{{extra}}], unit: N}}
  a:  {{type: gain, in: F, k: 1/m}}
  v:  {{type: integrator, in: a, unit: m/s}}
  x:  {{type: integrator, in: {{x_in}}, unit: m}}
  Fk: {{type: gain, in: x, k: k}}
  Fd: {{type: gain, in: v, k: d}}
"""


def _chart(extra: str = "", x_in: str = "v", more: str = ""):
    return diagram_from_text(LINEAR.replace("{extra}", extra).replace("{x_in}", x_in) + more)


def _set_weights(diagram, name, weights):
    return dataclasses.replace(diagram, blocks=tuple(
        dataclasses.replace(b, weights=weights) if b.name == name else b for b in diagram.blocks))


def _set_param(diagram, name, value):
    return dataclasses.replace(diagram, parameters=tuple(
        dataclasses.replace(p, init=value) if p.name == name else p for p in diagram.parameters))


# ------------------------------------------------------------------------------------------------ places
def test_a_position_is_the_integral_of_a_speed_and_a_spring_force_enters_against_it():
    lin = _chart()
    (p,) = positions(lin)
    # x' = v, v' = F/m: a force +f in F pushes x up, so a spring f(x) enters F with -
    assert (p.at, p.kind, p.sums, p.via) == ("x", "position", (("F", -1),), "v")
    assert {q.at for q in states(lin)} == {"v", "x"}
    # x = integral(-v): x falls when the force grows, so the spring enters with +
    (flipped,) = positions(_chart(x_in="-v"))
    assert flipped.sums == (("F", 1),)


def test_the_integral_of_a_speed_difference_is_a_spring_angle_not_a_position():
    two = chart("two_mass_nominal")
    assert positions(two) == ()
    assert signal_place(two, "dphi").kind == "spring_angle"


def test_a_named_signal_takes_its_most_specific_place():
    lin = _chart()
    assert signal_place(lin, "v").kind == "speed" and signal_place(lin, "x").kind == "position"
    assert signal_place(lin, "u").kind == "input" and signal_place(lin, "Fk") == Place("Fk", "signal")
    with pytest.raises(KeyError):
        signal_place(lin, "nope")


# ------------------------------------------------------------------------------------------------ spring
def test_a_flat_spring_leaves_the_outputs_unchanged():
    lin = _chart()
    patched = Spring().patch(lin, positions(lin)[0], 1.0)
    compile_diagram(patched)
    curve = patched.block("spring_x")
    # odd, flat, and no linear term of its own: the chart's k x is that
    assert curve.basis == "tanh" and not curve.bias and set(curve.weights.v) == {0.0} and curve.weights.c is None
    u = aprbs_input(1500, seed=1, amplitude=40.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(lin, u), rtol=0, atol=1e-12)


def test_a_spring_with_weights_set_equals_a_hand_written_chart():
    lin = _chart()
    patched = Spring().patch(lin, positions(lin)[0], 1.0)
    patched = _set_weights(patched, "spring_x", NonlinearWeights((3.0,), (50.0,), None))
    hand = _chart(", -FS", more="  S:  {type: function, f: tanh, in: x, k: 3}\n  FS: {type: gain, in: S, k: 50}\n")
    u = aprbs_input(1500, seed=2, amplitude=40.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(hand, u), rtol=1e-10, atol=1e-10)


def test_a_spring_where_the_chart_has_none_carries_a_linear_term():
    bare = diagram_from_text(LINEAR.replace("{extra}", "").replace("{x_in}", "v").replace("-Fk, ", ""))
    patched = Spring().patch(bare, positions(bare)[0], 1.0)
    assert patched.block("spring_x").weights.c == 0.0


# ------------------------------------------------------------------------------------------------ cogging
def test_cogging_reads_the_charts_own_position_of_the_speed():
    lin = _chart()
    patched = Cogging().patch(lin, speeds(lin)[0], 2)
    assert [b.name for b in patched.blocks if b.kind == "integrator"] == ["v", "x"]  # no second angle
    patched = _set_param(_set_param(patched, "cog2_A_v", 30.0), "cog2_B_v", -10.0)
    hand = _chart(", -T2", more="  s2: {type: function, f: sin, in: x, k: 2}\n  c2: {type: function, f: cos, in: x, k: 2}\n"
                               "  A2: {type: gain, in: s2, k: 30}\n  B2: {type: gain, in: c2, k: -10}\n"
                               "  T2: {type: sum, in: [A2, B2]}\n")
    u = aprbs_input(1500, seed=3, amplitude=40.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(hand, u), rtol=1e-10, atol=1e-10)


# ------------------------------------------------------------------------------------------------ diagnose
def _record(n: int, seed: int) -> tuple[Dataset, float]:
    """The oracle: m x'' + d x' + k x + k3 x^3 = u(t), solve_ivp, noise 0.1 % of rms(x)."""
    t, u, x, sigma = so.record(n=n, seed=seed, noise=1e-3, params={"k": K, "d": D, "k3": K3}, band=1.0,
                               scale=so.SCALE * K / so.TRUE["k"])
    data = Dataset(path=f"spring{seed}.csv", columns={"u": u, "x": x}, time=t, n_rows=n, sample_time=so.T,
                   max_step_deviation=0.0, sha256="", source_columns={"u": "u", "x": "x"}, time_column="time")
    return data, sigma


def test_diagnose_finds_the_hardening_spring_at_the_position():
    # the case: a mass on a hardening spring to ground, the chart linear (about 4 s)
    train, _ = _record(1000, 0)
    val, _ = _record(500, 7)
    effects = [BUILTIN_EFFECTS[n] for n in ("spring", "damping", "friction", "cogging")]
    report = diagnose(_chart(), train, [val], DiagnoseSettings(rounds=1), effects=effects).report
    assert report["accepted"] and report["accepted"][0]["effect"] == "spring", report["candidates"][:3]
    assert report["accepted"][0]["at"] == "x"
    first = report["rounds"][0]
    assert first["validation_rms_after"] < first["validation_rms_before"] / 4, first

"""Effects at positions: where a position is, the learned spring to ground, and cogging reading the chart's angle.

Oracles: signs derived by hand from the physics (a spring to ground pulls the mass back), hand-written
equivalent charts; for the diagnosis a mass on a hardening spring to ground (tests/smooth_oracle.py) and a
two-mass drive with an unbalanced load (written here), both simulated by scipy's solve_ivp (DOP853, rtol
1e-10), not by the network under test, and the unbalance's amplitude and phase as the oracle drew them.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
import smooth_oracle as so
from diagnose_bench import DATA, aprbs_input, chart, simulate
from scipy.integrate import solve_ivp

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import Dataset
from flowchart2sdnn.diagnose.effects import (
    BUILTIN_EFFECTS,
    Cogging,
    Scales,
    Spring,
    effect_library,
    select_effects,
)
from flowchart2sdnn.diagnose.graph import Place, positions, signal_place, speeds, states
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagnose.usereffects import load_effects_file
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


def test_a_position_without_a_spring_is_offered_none():
    # a mass with no spring to ground (EMPS's linear axis): a learned curve of its position is not offered
    bare = diagram_from_text(LINEAR.replace("{extra}", "").replace("{x_in}", "v").replace("-Fk, ", ""))
    assert [p.at for p in positions(bare)] == ["x"] and Spring().places(bare) == ()
    assert [p.at for p in Spring().places(_chart())] == ["x"]


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
@functools.cache
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


# a two-mass drive (the diagnose bench's numbers) whose load carries an unbalance m g l sin(phi2 + phase),
# spinning at about 30 rad/s: one period a revolution is near 5 Hz, below the 10 Hz shaft resonance
TMS = {"J1": 0.1912, "J2": 0.3838, "c": 477.2, "d": 0.2406, "b1": 0.05}
MGL, PHASE, W0 = 1.5, 0.7, 30.0


def _drive(n: int, seed: int, noise: float = 0.01) -> Dataset:
    """The oracle: the drive with the unbalance, solve_ivp (DOP853), started spinning at W0."""
    rng = np.random.default_rng(seed)
    f, a, ph = rng.uniform(0.2, 3.0, 12), rng.uniform(0.3, 1.0, 12) / 4, rng.uniform(0, 2 * np.pi, 12)

    def torque(t):
        return W0 * TMS["b1"] + np.sum(a[:, None] * np.sin(2 * np.pi * f[:, None] * np.atleast_1d(t)[None, :]
                                                          + ph[:, None]), axis=0)

    def rhs(t, s):
        w1, w2, dphi, phi2 = s
        shaft = TMS["c"] * dphi + TMS["d"] * (w1 - w2)
        return [(torque(t)[0] - shaft - TMS["b1"] * w1) / TMS["J1"],
                (shaft - MGL * np.sin(phi2 + PHASE)) / TMS["J2"], w1 - w2, w2]

    t = np.arange(n) * 1e-3
    sol = solve_ivp(rhs, (0, t[-1]), [W0, W0, 0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-12)
    noisy = np.random.default_rng(seed + 1000)
    cols = {"M1": torque(t), "w1": sol.y[0] + noise * noisy.standard_normal(n),
            "w2": sol.y[1] + noise * noisy.standard_normal(n)}
    return Dataset(path=f"drive{seed}.csv", columns=cols, time=t, n_rows=n, sample_time=1e-3, max_step_deviation=0.0,
                   sha256="", source_columns={k: k for k in cols}, time_column="time")


def test_diagnose_finds_the_unbalance_of_the_load_one_period_a_revolution():
    # the chart of the bench, its speeds started from the data (the drive is spinning); about 8 s
    text = (DATA / "two_mass_nominal.yaml").read_text()
    text = text.replace("in: acc1, unit", "in: acc1, init: data, unit").replace("in: acc2, unit", "in: acc2, init: data, unit")
    effects = select_effects(["cogging", "friction", "damping"], effect_library(harmonics=(1, 2, 6)))
    report = diagnose(diagram_from_text(text), _drive(2000, 1), [_drive(1300, 2)], DiagnoseSettings(rounds=1),
                      effects=effects).report
    assert [(a["effect"], a["at"], a["option"]) for a in report["accepted"]] == [("cogging", "w2", 1)], \
        report["candidates"][:3]
    first = report["rounds"][0]
    assert first["validation_rms_after"] < first["validation_rms_before"] / 4, first
    # -(A sin phi2 + B cos phi2) = -m g l sin(phi2 + phase): A = mgl cos(phase), B = mgl sin(phase)
    p = first["parameters"]
    assert p["cog1_A_w2"] == pytest.approx(MGL * np.cos(PHASE), rel=0.05)
    assert p["cog1_B_w2"] == pytest.approx(MGL * np.sin(PHASE), rel=0.05)


def test_diagnose_accepts_a_user_cubic_spring_read_from_the_position(tmp_path):
    # the refit: a user effect that reads the position, k3 x^3, here with the oracle's own law (about 4 s)
    (tmp_path / "fx.yaml").write_text("""sdnn_effects: 1
effects:
  cubic:
    at: x
    parameters: {"{name}_k3": {init: 0}}
    blocks:
      "{name}": {type: product, in: ["{at}", "{at}", "{at}"], k: "{name}_k3"}
    output: "{name}"
""")
    effects = select_effects(["cubic", "damping"], effect_library(user=load_effects_file(tmp_path / "fx.yaml")))
    report = diagnose(_chart(), _record(1000, 0)[0], [_record(500, 7)[0]], DiagnoseSettings(rounds=1),
                      effects=effects).report
    assert [(a["effect"], a["at"]) for a in report["accepted"]] == [("cubic", "x")], report["candidates"][:3]
    first = report["rounds"][0]
    assert first["validation_rms_after"] < first["validation_rms_before"] / 4, first
    assert first["parameters"]["cubic_x_k3"] == pytest.approx(K3, rel=0.05)


def test_one_period_a_revolution_stays_on_offer_at_an_angle_that_only_swings():
    # a position of 0.3 rms: 2 pi / p <= 0.6 keeps p >= 10.5 (the travel rule); on an angle (rad) p = 1 stays, the
    # law of an unbalance m g l sin(phi + phase); on a length (m) it goes, as on EMPS
    cog = Cogging(harmonics=(1, 2, 12))
    swing = Scales({"x": 0.3})
    for unit, expected in (("rad", (1, 12)), ("m", (12,)), (None, (12,))):
        text = LINEAR.replace("{extra}", "").replace("{x_in}", "v").replace(", unit: m}", "}" if unit is None
                                                                              else f", unit: {unit}}}")
        lin = diagram_from_text(text)
        assert cog.options(lin, speeds(lin)[0], swing) == expected, unit

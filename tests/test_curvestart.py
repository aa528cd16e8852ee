"""identify.offline.curvestart: the learned curves' stick-slip start, against hand-derived oracles.

Oracle for the slope limit: one inertia with a learned friction curve, explicit Euler at step T,
w(t) = w(t-1) + T/J (M - f(w(t-1))), has the rest eigenvalue 1 - T f'(0) / J: it chatters (< -1) from
f'(0) = 2 J / T on (network.stability's docstring, derived by hand, not by the code under test).
Data come from the continuous plant (simulate.excitation), never from the model tested.
"""

from __future__ import annotations

import numpy as np
import pytest

from flowchart2sdnn.api import dataset_from_frame
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.identify.offline.curvestart import (
    STICK_FRACTION,
    curve_start,
    slope_limit,
    startable_curves,
    stick_template,
)
from flowchart2sdnn.identify.offline.optimize import lm_options
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.identify.settings import IdentifySettings
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

T = 0.001

PLANT = """
sdnn: 1
name: one_mass_plant
sample_time: 0.001
substeps: 1
inputs:
  M: {unit: N*m}
outputs:
  w: {unit: rad/s}
parameters:
  J: {init: 0.5}
  Fc: {init: 0.8}
  b: {init: 0.05}
blocks:
  MB: {type: sum, in: [M, -Fr, -Fv]}
  acc: {type: gain, in: MB, k: 1/J}
  w: {type: integrator, in: acc}
  sg: {type: function, f: tanh, in: w, k: 20}
  Fr: {type: gain, in: sg, k: Fc}
  Fv: {type: gain, in: w, k: b}
"""


def chart(j: float = 0.5, curve: str = "{type: nonlinear, in: w, neurons: 3, basis: neurons}") -> str:
    return f"""
sdnn: 1
name: one_mass
sample_time: 0.001
substeps: 1
inputs:
  M: {{unit: N*m}}
outputs:
  w: {{unit: rad/s}}
parameters:
  J: {{init: {j}, min: 0}}
blocks:
  MB: {{type: sum, in: [M, -F]}}
  acc: {{type: gain, in: MB, k: 1/J}}
  w: {{type: integrator, in: acc}}
  F: {curve}
"""


@pytest.fixture(scope="module")
def record():
    plant = diagram_from_text(PLANT, "plant.yaml")
    frame = excite(plant, ExcitationSettings(seconds=1.0, seed=3, noise_std=0.01))
    return dataset_from_frame(frame, time="time", inputs=["M"], outputs=["w"], name="one mass")


def problem_of(text: str, record):
    return build_problem(diagram_from_text(text, "chart.yaml"), record, seed=1)


@pytest.mark.parametrize("j", [0.5, 0.05])
def test_the_slope_limit_is_where_euler_feedback_flips_sign(record, j):
    p = problem_of(chart(j), record)
    curves = startable_curves(p)
    assert list(curves) == ["F"]
    assert slope_limit(p, p.compiled.theta0(), "F", curves) == pytest.approx(2 * j / T, rel=1e-6)


def test_the_template_is_a_step_at_the_stick_fraction_of_the_limit_then_a_log_grid(record):
    p = problem_of(chart(0.5), record)
    x, limits = stick_template(p, p.compiled.theta0())
    w = dict(zip(p.names, x, strict=True))
    assert limits["F"] == pytest.approx(2 * 0.5 / T, rel=1e-6)
    assert w["F.a1"] * w["F.v1"] == pytest.approx(STICK_FRACTION * 2 * 0.5 / T, rel=1e-6)  # tanh'(0) = 1
    assert w["F.v2"] == w["F.v3"] == 0.0
    assert w["F.a2"] / w["F.a3"] == pytest.approx(10.0)
    # a2 = 1 / RMS (top = 1) of the curve's input in a free run: of the record's speed, here measured
    rms = float(np.sqrt(np.mean(np.asarray(record.columns["w"]) ** 2)))
    assert 0.3 / rms < w["F.a2"] < 3 / rms


def test_after_the_brief_fit_the_step_keeps_the_stick_fraction_at_the_fitted_inertia(record):
    p = problem_of(chart(0.5 * 3), record)  # J drawn 3x too large: the limit at the start is 3x too
    lo, hi = p.bounds()
    warm = curve_start(p, p.compiled.theta0(), lo, hi, lm_options(IdentifySettings(seed=1), p))
    w = dict(zip(p.names, warm.x, strict=True))
    assert warm.curves == ("F",) and 0 < warm.iterations <= 150  # three brief fits of at most 50
    # the limit is re-measured at the fitted J: 2 J / T again, by hand
    assert warm.limits["F"] == pytest.approx(2 * w["J"] / T, rel=1e-6)
    assert w["F.a1"] * w["F.v1"] == pytest.approx(STICK_FRACTION * 2 * w["J"] / T, rel=1e-6)
    assert abs(w["J"] / 0.5 - 1) < 0.2  # the brief fit moved J most of the way from 1.5 to the plant's 0.5


@pytest.mark.parametrize("curve", [
    "{type: nonlinear, in: w, neurons: 2, basis: neurons, weights: {a: [1, 2], v: [0.1, 0.2]}}",  # stored weights: kept
    "{type: nonlinear, in: w, neurons: 2, basis: neurons, fixed: true, weights: {a: [1, 2], v: [0.1, 0.2]}}",
])
def test_curves_with_stored_or_fixed_weights_keep_the_chart_start(record, curve):
    p = problem_of(chart(0.5, curve), record)
    x0 = p.compiled.theta0()
    lo, hi = p.bounds()
    warm = curve_start(p, x0, lo, hi, lm_options(IdentifySettings(seed=1), p))
    assert warm.curves == () and warm.iterations == 0
    np.testing.assert_array_equal(warm.x, x0)


def test_a_curve_in_no_loop_keeps_the_chart_start(record):
    text = chart(0.5).replace("MB: {type: sum, in: [M, -F]}", "MB: {type: sum, in: [M, -F]}\n  G: {type: "
                              "nonlinear, in: M, neurons: 2, basis: neurons}").replace("outputs:\n  w: {unit: rad/s}",
                                                                        "outputs:\n  w: {unit: rad/s}")
    p = problem_of(text, record)
    curves = startable_curves(p)
    assert set(curves) == {"F", "G"}
    assert slope_limit(p, p.compiled.theta0(), "G", curves) == float("inf")
    x, limits = stick_template(p, p.compiled.theta0())
    assert set(limits) == {"F"}
    g = [i for i, n in enumerate(p.names) if n.startswith("G.")]
    np.testing.assert_array_equal(x[g], p.compiled.theta0()[g])


def test_with_sub_steps_the_step_is_set_from_the_limit_of_the_network_step(record):
    # at N sub-steps the chatter limit is 2 J / h = N * 2 J / T (hand-derived as above, h = T / N); the step
    # starts at the stick fraction of that limit, N times steeper than at one step per sample
    p = problem_of(chart(0.5).replace("substeps: 1", "substeps: 4"), record)
    curves = startable_curves(p)
    assert slope_limit(p, p.compiled.theta0(), "F", curves) == pytest.approx(2 * 0.5 * 4 / T, rel=1e-6)
    x, _ = stick_template(p, p.compiled.theta0(), curves)
    w = dict(zip(p.names, x, strict=True))
    assert w["F.a1"] * w["F.v1"] == pytest.approx(STICK_FRACTION * 2 * 0.5 * 4 / T, rel=1e-6)


def test_identify_reports_the_curves_start_and_random_keeps_the_chart_start(record):
    from flowchart2sdnn.identify.offline.run import identify

    diagram = diagram_from_text(chart(0.5), "chart.yaml")
    stick = identify(diagram, record, seed=1, floor_bias=False)
    assert stick.result["curve_start"]["curves"] == ["F"]
    assert stick.result["settings"]["curve_start"] == "stick"
    assert stick.result["curve_start"]["slope_limits"]["F"] == pytest.approx(2 * stick.result["parameters"]["J"]
                                                                             ["value"] / T, rel=0.05)
    random = identify(diagram, record, seed=1, floor_bias=False, curve_start="random")
    assert "curve_start" not in random.result
    # from random curves the fit's first cost is the chart's own start's
    p = problem_of(chart(0.5), record)
    e = p.residual(p.compiled.theta0())
    assert random.optimizer.cost_history[0] == pytest.approx(0.5 * float(e @ e), rel=1e-9)


def test_three_mass_learned_chart_reaches_the_noise_floor_from_the_truth():
    # The three-mass drive with a learned curve (the default tanh basis) plus a viscous term on each machine
    # (diagrams/three_mass_learned.yaml) on its Stribeck plant (sign smoothed over 1 mrad/s), 3 s, 0.01 rad/s
    # noise on each of the 3 speeds, started at the true physical values. Oracle: the noise floor,
    # 1/2 * rows * 3 * 0.01^2 (the noise excite adds). The curves enter linearly: no stick-slip start is needed
    # and the fit ends within tens of iterations.
    from flowchart2sdnn.diagram.validate import load_diagram
    from flowchart2sdnn.identify.offline.run import identify

    root = __import__("pathlib").Path(__file__).resolve().parents[1] / "diagrams"
    plant = load_diagram(root / "three_mass_stribeck_plant.yaml")
    frame = excite(plant, ExcitationSettings(seconds=3.0, seed=1, noise_std=0.01))
    data = dataset_from_frame(frame, time="time", inputs=["M1"], outputs=["w1", "w2", "w3"], name="three mass")
    out = identify(load_diagram(root / "three_mass_learned.yaml"), data, seed=1, floor_bias=False)
    floor = 0.5 * data.n_rows * 3 * 0.01**2
    assert out.converged and out.lm.iterations <= 60
    assert "curve_start" not in out.result
    assert out.lm.cost < 1.03 * floor

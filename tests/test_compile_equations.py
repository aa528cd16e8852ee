"""The compiled networks reproduce difference equations derived by hand (issue 2, acceptance 1).

Discretization (paper, section 5): integrators are implicit Euler, y(t) = y(t-1) + T*x(t); the feedback edges
chosen by loop analysis carry one sample of delay (which is explicit Euler seen from the feedback path: the
implicit integrator's output one sample late obeys y(t-1) = y(t-2) + T*x(t-1)); forward paths from the
inputs to the outputs carry no delay. History (t < 0): integrators at their init, other neurons 0, inputs
held at their first sample (network/model.py). The recursions below are written from the charts, not
from the compiler; the networks run with alignment "direct" (network input at step t is u(t)).
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text, load_diagram
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
EXAMPLES = sorted(p.stem for p in DIAGRAMS.glob("*.yaml"))
TOL = 1e-12


def _compiled(text: str, name: str) -> tuple[CompiledNetwork, float]:
    """The chart at the paper's scheme (one step per sample, the search's delays) unless it names its own."""
    diagram = diagram_from_text(text, name)
    diagram = replace(diagram, substeps=diagram.substeps or 1, delays=diagram.delays or "search")
    net = compile_diagram(diagram).network
    return CompiledNetwork(net), net.sample_time


def _neurons(text: str) -> str:
    """The chart with the paper's free-slope neurons for every learned curve (the recursions read a_i, v_i)."""
    text = re.sub(r",\s*neurons:\s*\d+", "", text)
    return text.replace("type: nonlinear,", "type: nonlinear, basis: neurons, neurons: 3,")


def _random_theta(cn: CompiledNetwork, rng: np.random.Generator) -> np.ndarray:
    """Parameters scaled by a random factor in [0.5, 2], free (friction) weights uniform in [-1.5, 1.5]."""
    theta = cn.theta0().copy()
    params = {p.name for p in cn.net.parameters}
    for i, name in enumerate(cn.names):
        theta[i] = theta[i] * rng.uniform(0.5, 2.0) if name in params else rng.uniform(-1.5, 1.5)
    return theta


def _curve(w: dict[str, float], block: str, x: float) -> float:
    """The odd friction curve of a `nonlinear` block without bias: sum_i v_i tanh(a_i x)."""
    n = sum(1 for k in w if k.startswith(block + ".a"))
    return sum(w[f"{block}.v{i}"] * np.tanh(w[f"{block}.a{i}"] * x) for i in range(1, n + 1))


def _excitation(rng: np.random.Generator, q: int, columns: int = 1) -> np.ndarray:
    steps = rng.uniform(-5, 5, size=(q // 20 + 1, columns)).repeat(20, axis=0)[:q]
    return steps + rng.normal(0, 1, size=(q, columns))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_mass_matches_the_hand_recursion(seed):
    rng = np.random.default_rng(seed)
    text = (DIAGRAMS / "two_mass.yaml").read_text().replace("fixed: true", "fixed: false")  # J1 random too
    paper = re.sub(r"(?m)^(substeps|delays):.*\n", "", text)  # at the paper's scheme, which the recursion follows
    cn, T = _compiled(_neurons(paper), "two_mass.yaml")
    theta = _random_theta(cn, rng)
    p, w = cn.values(theta)
    assert set(w) == {f"MR{m}.{r}{i}" for m in (1, 2) for r in "av" for i in (1, 2, 3)}
    q = 600
    u = _excitation(rng, q)
    y = cn.simulate(theta, u)
    J1, J2, c, d = p["J1"], p["J2"], p["c"], p["d"]
    w1 = w2 = dw = dphi = 0.0  # history
    expected = np.empty(q)
    for t in range(q):
        # feedback edges MR1->MB1, MC->MB1, MD->MB1, w2->dw, MR2->MB2 read the previous sample
        mb1 = u[t, 0] - c * dphi - d * dw - _curve(w, "MR1", w1)
        w1_new = w1 + T / J1 * mb1
        dw_new = w1_new - w2
        dphi_new = dphi + T * dw_new
        mb2 = c * dphi_new + d * dw_new - _curve(w, "MR2", w2)
        w2 = w2 + T / J2 * mb2
        w1, dw, dphi = w1_new, dw_new, dphi_new
        expected[t] = w2
    assert np.abs(expected).max() > 1e-2  # the test excites the system
    np.testing.assert_allclose(y[:, 0], expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))


def test_two_mass_delays_exactly_the_papers_feedback_edges():
    net = compile_diagram(replace(load_diagram(DIAGRAMS / "two_mass.yaml"), substeps=1, delays="search")).network
    got = {(e.source, e.target, e.delay) for e in net.delayed_edges}
    assert got == {("MR1", "MB1", 1), ("MC", "MB1", 1), ("MD", "MB1", 1), ("w2", "dw", 1), ("MR2", "MB2", 1)}
    for e in net.delayed_edges:  # each names a loop through the delayed edge, starting at its target
        assert e.loop[0] == e.target and e.loop[-1] == e.source


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_engine_matches_the_hand_recursion(seed):
    rng = np.random.default_rng(seed)
    paper = re.sub(r"(?m)^(substeps|delays):.*\n", "", (DIAGRAMS / "engine.yaml").read_text())  # its own scheme
    cn, T = _compiled(_neurons(paper), "engine.yaml")  # at the paper's, which the hand recursion follows
    theta = _random_theta(cn, rng)
    p, w = cn.values(theta)
    q = 500
    u = _excitation(rng, q)
    y = cn.simulate(theta, u)
    w1 = 0.0
    expected = np.empty(q)
    for t in range(q):
        mb1 = u[t, 0] - _curve(w, "MR1", w1)  # friction at the previous speed (delayed MR1 -> MB1)
        w1 = w1 + T / p["J1"] * mb1
        expected[t] = w1
    assert np.abs(expected).max() > 1e-3
    np.testing.assert_allclose(y[:, 0], expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))
    assert {(e.source, e.target) for e in cn.net.delayed_edges} == {("MR1", "MB1")}


def test_mass_spring_damper_matches_the_hand_recursion():
    rng = np.random.default_rng(5)
    cn, T = _compiled((DIAGRAMS / "mass_spring_damper.yaml").read_text(), "msd.yaml")
    theta = _random_theta(cn, rng)
    p, _ = cn.values(theta)
    q = 400
    u = _excitation(rng, q)
    y = cn.simulate(theta, u)
    v = x = 0.0
    expected = np.empty(q)
    for t in range(q):
        fnet = u[t, 0] - p["k"] * x - p["b"] * v
        v = v + T / p["m"] * fnet
        x = x + T * v
        expected[t] = x
    np.testing.assert_allclose(y[:, 0], expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))


def test_dc_motor_matches_the_hand_recursion():
    rng = np.random.default_rng(6)
    cn, T = _compiled((DIAGRAMS / "dc_motor.yaml").read_text(), "dc_motor.yaml")
    theta = _random_theta(cn, rng)
    p, _ = cn.values(theta)
    q = 400
    u = 10 * _excitation(rng, q)
    y = cn.simulate(theta, u)
    i = w = 0.0
    expected = np.empty((q, 2))
    for t in range(q):
        ul = u[t, 0] - p["R"] * i - p["Ke"] * w
        i = i + T / p["L"] * ul
        mb = p["Kt"] * i - p["b"] * w
        w = w + T / p["J"] * mb
        expected[t] = i, w
    order = [cn.output_names.index(n) for n in ("i", "w")]
    np.testing.assert_allclose(y[:, order], expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))


KITCHEN_SINK = """\
sdnn: 1
name: kitchen_sink
sample_time: 0.01
inputs:
  u: {}
outputs:
  y: {}
  z: {}
  c2: {}
parameters:
  a: {init: 2.0}
  g: {init: 0.5}
blocks:
  ud:  {type: delay, in: u, n: 3}
  s:   {type: sum, in: [ud, -fb, off]}
  off: {type: constant, k: 0.25*a}
  y:   {type: integrator, in: s, init: 1.5}
  f:   {type: function, f: sin, in: y, k: g}
  fb:  {type: gain, in: f, k: a}
  z:   {type: nonlinear, in: y, neurons: 2, bias: true, basis: neurons}
  c2:  {type: gain, in: y, k: -3}
"""


def test_delay_constant_function_bias_and_init_match_the_hand_recursion():
    """Folded delay (3 samples), constant bias, function neuron, biased nonlinear read-out, nonzero init."""
    rng = np.random.default_rng(7)
    cn, T = _compiled(KITCHEN_SINK, "kitchen_sink.yaml")
    theta = _random_theta(cn, rng)
    p, w = cn.values(theta)
    q = 60
    u = _excitation(rng, q)
    out = cn.simulate(theta, u)
    a, g = p["a"], p["g"]
    y, f = 1.5, 0.0  # integrator at its init, the function neuron at 0
    expected = np.empty((q, 3))
    for t in range(q):
        ud = u[max(t - 3, 0), 0]  # inputs before t = 0 are held at their first sample
        s = ud - a * f + 0.25 * a  # fb -> s is the delayed feedback edge
        y = y + T * s
        f = np.sin(g * y)
        z = sum(w[f"z.v{i}"] * np.tanh(w[f"z.a{i}"] * y + w[f"z.b{i}"]) for i in (1, 2))
        expected[t] = y, z, -3 * y
    order = [cn.output_names.index(n) for n in ("y", "z", "c2")]
    np.testing.assert_allclose(out[:, order], expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))
    assert {(e.source, e.target) for e in cn.net.delayed_edges} == {("fb", "s")}


@pytest.mark.parametrize("name", EXAMPLES)
def test_a_step_reaches_every_output_in_the_same_sample(name):
    """Forward paths carry no delay: with alignment 'direct', a step at sample k changes every output at k.

    With implicit Euler even a double integral responds at once (x(k) = x(k-1) + T*v(k), v(k) = ... + T*F(k)).
    """
    diagram = load_diagram(DIAGRAMS / f"{name}.yaml")
    cn = CompiledNetwork(compile_diagram(diagram).network)
    theta = cn.theta0()
    k, q = 5, 12
    base = np.zeros((q, cn.n_inputs))
    step = base.copy()
    step[k:] = 1.0
    y0 = run_aligned(cn, theta, base, "direct")
    y1 = run_aligned(cn, theta, step, "direct")
    np.testing.assert_array_equal(y0[:k], y1[:k])
    assert np.all(np.abs(y1[k] - y0[k]) > 0), f"{name}: outputs {cn.output_names} at the step: {y1[k] - y0[k]}"
    # the default alignment for logged data (zoh) shifts the input by one sample at the data interface
    z0 = run_aligned(cn, theta, base, "zoh")
    z1 = run_aligned(cn, theta, step, "zoh")
    np.testing.assert_array_equal(z0[: k + 1], z1[: k + 1])
    assert np.all(np.abs(z1[k + 1] - z0[k + 1]) > 0)
    np.testing.assert_array_equal(z1[1:], y1[:-1])  # same network, input one row later


BASIS_CHART = """\
sdnn: 1
name: basis
sample_time: 0.01
inputs:
  u: {}
outputs:
  y: {}
parameters:
  J: {init: 2.0}
blocks:
  s:   {type: sum, in: [u, -f]}
  y:   {type: integrator, in: s, k: 1}
  acc: {type: gain, in: s, k: 1/J}
  f:   {type: nonlinear, in: y, span: 4.0}
"""


def test_the_tanh_basis_is_fixed_slopes_over_the_span_plus_a_linear_term():
    """The default basis: seven tanh functions whose slopes are log-spaced over three decades of the span (the
    widest 1/span, the steepest 1000/span), only their output weights and the linear term c learned."""
    text = BASIS_CHART.replace("  y:   {type: integrator, in: s, k: 1}\n", "").replace(
        "  acc: {type: gain, in: s, k: 1/J}", "  acc: {type: gain, in: s, k: 1/J}\n  y:   {type: integrator, in: acc}")
    rng = np.random.default_rng(3)
    cn, T = _compiled(text, "basis.yaml")
    assert set(cn.names) == {"J"} | {f"f.v{i}" for i in range(1, 8)} | {"f.c"}
    theta = _random_theta(cn, rng)
    p, w = cn.values(theta)
    slopes = [10.0 ** (k / 2) / 4.0 for k in range(7)]
    q = 200
    u = _excitation(rng, q)
    y_net = cn.simulate(theta, u)[:, 0]
    y, f = 0.0, 0.0
    expected = np.empty(q)
    for t in range(q):
        s = u[t, 0] - f  # the curve's torque comes back one sample late (the loop's delayed edge)
        y = y + T / p["J"] * s
        f = sum(w[f"f.v{i + 1}"] * np.tanh(slopes[i] * y) for i in range(7)) + w["f.c"] * y
        expected[t] = y
    np.testing.assert_allclose(y_net, expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))

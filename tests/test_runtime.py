"""Simulation of the GDNN runtime against hand-derived recursions of eq. (1)-(2) and closed forms."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from randomnet import hand_network, random_gdnn

from flowchart2sdnn.network.model import InitialState, WeightSpec
from flowchart2sdnn.network.runtime import CompiledNetwork

TRANSFER = {"linear": lambda x: x, "tanh": np.tanh, "sin": np.sin, "cos": np.cos}


def reference_simulate(net, u, init=None):
    """Naive eq. (1)-(2) straight over the WeightSpec list (independent of flat.py and the kernels)."""
    values = net.weight_values()
    n_steps = u.shape[0]
    hist = [np.zeros(la.size) for la in net.layers]
    for s in net.initial_states:
        hist[s.layer][s.neuron] = init[s.data] if s.data is not None else s.value
    a = [np.zeros((n_steps, la.size)) for la in net.layers]
    for t in range(n_steps):
        for m, la in enumerate(net.layers):
            n = np.zeros(la.size)
            for w, v in zip(net.weights, values, strict=True):
                if w.layer != m:
                    continue
                s = t - w.delay
                if w.matrix == "LW":
                    x = a[w.source][s, w.col] if s >= 0 else hist[w.source][w.col]
                elif w.matrix == "IW":
                    x = u[max(s, 0), w.source]
                else:
                    x = 1.0
                n[w.row] += v * x
            a[m][t] = [TRANSFER[neuron.transfer](n[k]) for k, neuron in enumerate(la.neurons)]
    return np.column_stack([a[o.layer][:, o.neuron] for o in net.outputs])


def integrator(T="0.01", y0=None, data=False):
    """y(t) = y(t-1) + T u(t): implicit Euler integrator, one linear neuron."""
    states = []
    if data:
        states = [InitialState(0, data="y")]
    elif y0 is not None:
        states = [InitialState(0, value=y0)]
    return hand_network(
        layers=[("y", "linear")],
        weights=[
            WeightSpec("LW", 0, 0, source=0, delay=1, coef="1"),
            WeightSpec("IW", 0, 0, source=0, delay=0, coef=T),
        ],
        outputs=[("y", 0)],
        initial_states=states,
    )


@pytest.fixture(scope="module")
def u1():
    return np.random.default_rng(11).normal(size=(300, 1))


def test_integrator_is_a_cumulative_sum(u1):
    cn = CompiledNetwork(integrator())
    y = cn.simulate(cn.theta0(), u1)
    assert y.shape == (300, 1)
    np.testing.assert_allclose(y[:, 0], 0.01 * np.cumsum(u1[:, 0]), rtol=1e-12, atol=1e-14)


def test_integrator_with_parameter_and_initial_state(u1):
    net = integrator(T="T", y0=2.5)
    net = hand_network(
        layers=[("y", "linear")],
        weights=net.weights,
        outputs=[("y", 0)],
        parameters={"T": 0.02},
        initial_states=net.initial_states,
    )
    cn = CompiledNetwork(net)
    assert cn.names == ("T",)
    y = cn.simulate([0.05], u1)
    np.testing.assert_allclose(y[:, 0], 2.5 + 0.05 * np.cumsum(u1[:, 0]), rtol=1e-12)
    params, free = cn.values([0.05])
    assert params == {"T": 0.05} and free == {}


def test_first_order_lag_with_delayed_feedback(u1):
    # e(t) = u(t) - y(t-1);  y(t) = y(t-1) + (T/tau) e(t)  (explicit Euler in the feedback path)
    net = hand_network(
        layers=[("e", "linear"), ("y", "linear")],
        weights=[
            WeightSpec("IW", 0, 0, source=0, coef="1"),
            WeightSpec("LW", 0, 0, source=1, delay=1, coef="-1"),
            WeightSpec("LW", 1, 0, source=1, delay=1, coef="1"),
            WeightSpec("LW", 1, 0, source=0, delay=0, coef="0.01/tau"),
        ],
        outputs=[("y", 1)],
        parameters={"tau": 0.05},
        initial_states=[InitialState(1, value=-0.3)],
    )
    cn = CompiledNetwork(net)
    tau = 0.08
    y = cn.simulate([tau], u1)[:, 0]
    ref = np.empty(len(u1))
    prev = -0.3
    for t in range(len(u1)):
        prev = prev + 0.01 / tau * (u1[t, 0] - prev)
        ref[t] = prev
    np.testing.assert_allclose(y, ref, rtol=1e-12, atol=1e-14)
    sig = cn.signals([tau], u1)
    assert set(sig) == {"e", "y"}
    np.testing.assert_allclose(sig["y"], ref, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(sig["e"], u1[:, 0] - np.r_[-0.3, ref[:-1]], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        dict(
            n_inputs=2,
            layers=(4, 3, 2),
            input_delays=(0, 2),
            feedback_delays=(1, 3),
            internal_delays=(1, 2),
            transfers=("tanh", "sin", "linear"),
        ),
        dict(layers=(3, 2), transfers=("cos", "tanh"), internal_delays=()),
    ],
)
def test_random_gdnn_matches_naive_loop(kwargs):
    net = random_gdnn(3, **kwargs)
    u = np.random.default_rng(5).uniform(-1, 1, size=(120, len(net.inputs)))
    cn = CompiledNetwork(net)
    y = cn.simulate(cn.theta0(), u)
    np.testing.assert_allclose(y, reference_simulate(net, u), rtol=1e-11, atol=1e-13)
    # other theta than the file's initial values: the runtime must use theta, not the inits
    theta = np.random.default_rng(6).uniform(-0.8, 0.8, cn.n_theta)
    fv = dict(zip(cn.names, theta, strict=True))
    moved = replace(net, free_weights=tuple(replace(f, init=fv[f.name]) for f in net.free_weights))
    # summation order differs from the naive loop; the recursion amplifies rounding a little
    np.testing.assert_allclose(cn.simulate(theta, u), reference_simulate(moved, u), rtol=1e-9, atol=1e-10)
    sig = cn.signals(theta, u)
    assert len(sig) == sum(la.size for la in net.layers)


def test_default_random_gdnn_has_pyrenn_weight_count():
    net = random_gdnn(0)
    assert len(net.weights) == 57 == len(net.free_weights)
    init = np.array([f.init for f in net.free_weights])
    assert np.all(np.abs(init) <= 0.5)
    assert not np.array_equal(init, [f.init for f in random_gdnn(1).free_weights])
    assert np.array_equal(init, [f.init for f in random_gdnn(0).free_weights])


def test_inputs_before_start_are_held_at_first_sample():
    net = hand_network(
        layers=[("y", "linear")],
        weights=[WeightSpec("IW", 0, 0, source=0, delay=2, coef="1")],
        outputs=[("y", 0)],
    )
    u = np.array([[3.0], [4.0], [5.0], [6.0]])
    y = CompiledNetwork(net).simulate([], u)
    np.testing.assert_array_equal(y[:, 0], [3.0, 3.0, 3.0, 4.0])


def test_history_of_deeper_delays_and_unlisted_neurons():
    # y(t) = a(t-2) + 10 b(t-1), a has initial state 7, b none (0); a(t) = u(t), b(t) = u(t)
    net = hand_network(
        layers=[("a", "linear"), ("b", "linear"), ("y", "linear")],
        weights=[
            WeightSpec("IW", 0, 0, source=0, coef="1"),
            WeightSpec("IW", 1, 0, source=0, coef="1"),
            WeightSpec("LW", 2, 0, source=0, delay=2, coef="1"),
            WeightSpec("LW", 2, 0, source=1, delay=1, coef="10"),
        ],
        outputs=[("y", 2)],
        initial_states=[InitialState(0, value=7.0)],
    )
    u = np.array([[1.0], [2.0], [3.0], [4.0]])
    y = CompiledNetwork(net).simulate([], u)[:, 0]
    np.testing.assert_array_equal(y, [7.0 + 0.0, 7.0 + 10.0, 1.0 + 20.0, 2.0 + 30.0])


def test_data_initialised_state(u1):
    cn = CompiledNetwork(integrator(data=True))
    y = cn.simulate(cn.theta0(), u1, init={"y": -1.25})
    np.testing.assert_allclose(y[:, 0], -1.25 + 0.01 * np.cumsum(u1[:, 0]), rtol=1e-12)
    with pytest.raises(ValueError, match="init"):
        cn.simulate(cn.theta0(), u1)
    with pytest.raises(ValueError, match="init"):
        cn.simulate(cn.theta0(), u1, init={"z": 1.0})
    with pytest.raises(ValueError, match="not finite"):
        cn.jacobian(cn.theta0(), u1, init={"y": np.nan})


def test_weights_on_the_same_cell_add_and_outputs_keep_their_order():
    net = hand_network(
        layers=[("x", ["linear", "tanh"])],
        weights=[
            WeightSpec("IW", 0, 0, source=0, coef="2"),
            WeightSpec("IW", 0, 0, source=0, coef="k", free="g"),
            WeightSpec("IW", 0, 1, source=0, coef="1"),
        ],
        outputs=[("second", 0, 1), ("first", 0, 0)],
        parameters={"k": 3.0},
        free_weights={"g": 0.5},
    )
    cn = CompiledNetwork(net)
    assert cn.output_names == ("second", "first") and cn.names == ("k", "g")
    u = np.array([[0.2], [-0.7]])
    y = cn.simulate(cn.theta0(), u)
    np.testing.assert_allclose(y, np.column_stack([np.tanh(u[:, 0]), (2 + 3.0 * 0.5) * u[:, 0]]), rtol=1e-14)
    assert set(cn.signals(cn.theta0(), u)) == {"x[0]", "x[1]"}


def test_errors(u1):
    cn = CompiledNetwork(integrator())
    theta = cn.theta0()
    for bad in (u1[:, 0], np.zeros((10, 2)), np.zeros((0, 1)), np.zeros((2, 3, 1))):
        with pytest.raises(ValueError, match="shape|no samples"):
            cn.simulate(theta, bad)
    for value in (np.nan, np.inf):
        u = u1.copy()
        u[17, 0] = value
        with pytest.raises(ValueError, match="sample 17"):
            cn.jacobian(theta, u)
    with pytest.raises(ValueError, match="theta"):
        cn.simulate([1.0], u1)
    net = hand_network(
        layers=[("y", "linear")],
        weights=[WeightSpec("IW", 0, 0, source=0, coef="J")],
        outputs=[("y", 0)],
        parameters={"K": 1.0},
    )
    with pytest.raises(ValueError, match="unknown parameter"):
        CompiledNetwork(net)


def test_unstable_network_returns_non_finite_without_raising():
    net = hand_network(
        layers=[("y", "linear")],
        weights=[WeightSpec("LW", 0, 0, source=0, delay=1, coef="a"), WeightSpec("b", 0, 0, coef="1")],
        outputs=[("y", 0)],
        parameters={"a": 1e3},
    )
    cn = CompiledNetwork(net)
    u = np.zeros((400, 1))
    y = cn.simulate(cn.theta0(), u)
    assert not np.isfinite(y[-1, 0])
    y2, dy = cn.jacobian(cn.theta0(), u)
    assert not np.isfinite(y2[-1, 0]) and not np.isfinite(dy[-1]).all()


def test_rest_stability_of_overflowing_weights_is_unbounded_not_a_crash():
    """A trial point (or a fuzzed chart) whose weights overflow has no finite linearisation at rest: the guard
    reads it as unbounded growth instead of raising numpy's LinAlgError (found by the chart fuzzer)."""
    from flowchart2sdnn.compiler import compile_diagram
    from flowchart2sdnn.diagram.validate import load_diagram
    from flowchart2sdnn.network.runtime import CompiledNetwork
    from flowchart2sdnn.network.stability import rest_radii

    net = compile_diagram(load_diagram(Path(__file__).resolve().parent.parent / "diagrams" / "engine.yaml")).network
    cn = CompiledNetwork(net)
    params, free = cn.values(cn.theta0())
    values = np.array(net.weight_values(params, free), dtype=float)
    finite = rest_radii(net, values)
    assert all(np.isfinite(finite))
    with np.errstate(over="ignore"):
        values = values * 1e308 * 1e10  # every nonzero weight overflows to +-inf
    chatter, growth = rest_radii(net, values)
    assert growth == np.inf and chatter == 0.0

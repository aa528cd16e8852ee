"""The RTRL Jacobian against central finite differences of the simulation (and a few hand derivatives)."""

from __future__ import annotations

import numpy as np
import pytest
from randomnet import hand_network, random_gdnn

from flowchart2sdnn.network.model import FreeWeightSpec, InitialState, ParameterSpec, WeightSpec
from flowchart2sdnn.network.runtime import CompiledNetwork


def finite_differences(cn, theta, u, init=None):
    """Central differences of simulate, step 1e-6 * max(1, |theta_i|) per quantity: (Q, n_out, P)."""
    theta = np.asarray(theta, dtype=float)
    cols = []
    for i in range(theta.size):
        h = 1e-6 * max(1.0, abs(theta[i]))
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        cols.append((cn.simulate(up, u, init) - cn.simulate(down, u, init)) / (2 * h))
    return np.stack(cols, axis=-1)


def assert_jacobian_matches(cn, theta, u, init=None, rtol=1e-6):
    y, dy = cn.jacobian(theta, u, init)
    np.testing.assert_allclose(y, cn.simulate(theta, u, init), rtol=1e-13, atol=1e-13)
    fd = finite_differences(cn, theta, u, init)
    assert dy.shape == fd.shape == (u.shape[0], cn.n_outputs, cn.n_theta)
    total = np.linalg.norm(fd)
    for i, name in enumerate(cn.names):
        # per column, so that a wrong small column cannot hide behind a large one
        err = np.linalg.norm(dy[..., i] - fd[..., i])
        scale = max(np.linalg.norm(fd[..., i]), 1e-6 * total)
        assert err <= rtol * scale, f"d/d{name}: relative error {err / scale:.2e}"
    return dy


@pytest.mark.parametrize(
    "seed, kwargs",
    [
        (0, {}),
        (
            1,
            dict(
                n_inputs=2,
                layers=(4, 3, 2),
                input_delays=(0, 2),
                feedback_delays=(1, 3),
                internal_delays=(1, 2),
                transfers=("tanh", "tanh", "linear"),
            ),
        ),
    ],
)
def test_random_gdnn_jacobian_matches_finite_differences(seed, kwargs):
    net = random_gdnn(seed, **kwargs)
    cn = CompiledNetwork(net)
    u = np.random.default_rng(seed + 10).uniform(-1, 1, size=(250, len(net.inputs)))
    assert_jacobian_matches(cn, cn.theta0(), u)
    # away from the file's values, but not so far that the recursion nears instability (where the O(h^2)
    # error of the differences, not RTRL, would dominate)
    theta = cn.theta0() + np.random.default_rng(seed + 20).uniform(-0.1, 0.1, cn.n_theta)
    assert_jacobian_matches(cn, theta, u)


def inertia_network(fixed_c=False):
    """A motor with spring and friction: parameters enter as 1/J, a product coef*free weight, shared cells.

    w(t)   = w(t-1) + 0.001/J1 * (u(t) - Mc(t-1) - v * tanh(a * w(t-1) + b0))      (speed, layer 2)
    phi(t) = phi(t-1) + 0.001 * w(t)                                              (angle, layer 3)
    Mc(t)  = c*0.001 * phi(t) * 1000 + d * w(t)                                   (shaft torque, layer 4)
    """
    return hand_network(
        layers=[("fr", "tanh"), ("x", "linear"), ("w", "linear"), ("phi", "linear"), ("Mc", "linear")],
        weights=[
            WeightSpec("LW", 0, 0, source=2, delay=1, coef="1", free="a"),
            WeightSpec("b", 0, 0, coef="1", free="b0"),
            WeightSpec("LW", 1, 0, source=0, delay=0, coef="1", free="v"),  # x = v * fr
            WeightSpec("LW", 2, 0, source=2, delay=1, coef="1"),
            WeightSpec("IW", 2, 0, source=0, coef="0.001/J1"),
            WeightSpec("LW", 2, 0, source=4, delay=1, coef="-0.001/J1"),
            WeightSpec("LW", 2, 0, source=1, delay=0, coef="-0.001/J1"),
            WeightSpec("LW", 3, 0, source=3, delay=1, coef="1"),
            WeightSpec("LW", 3, 0, source=2, delay=0, coef="0.001"),
            WeightSpec("LW", 4, 0, source=3, delay=0, coef="c*0.001"),
            WeightSpec("LW", 4, 0, source=3, delay=0, coef="c*0.001*999"),  # same cell: adds
            WeightSpec("LW", 4, 0, source=2, delay=0, coef="d", free="s"),  # coef(param) * free weight
        ],
        outputs=[("w", 2), ("Mc", 4)],
        parameters={
            "J1": 0.2,
            "c": ParameterSpec("c", 5.0, fixed=fixed_c),
            "d": 0.05,
        },
        free_weights={"a": 2.0, "b0": 0.1, "v": 0.3, "s": 1.0},
        initial_states=[InitialState(2, data="w"), InitialState(3, value=0.01)],
    )


def test_parameters_entering_as_inverse_inertia():
    cn = CompiledNetwork(inertia_network())
    assert cn.names == ("J1", "c", "d", "a", "b0", "v", "s")
    u = np.random.default_rng(2).normal(size=(300, 1))
    init = {"w": 0.4}
    dy = assert_jacobian_matches(cn, cn.theta0(), u, init)
    assert np.abs(dy[:, 0, 0]).max() > 1e-3  # J1 really matters


def test_first_step_derivative_by_hand():
    # at t = 0: w(0) = w0 + 0.001/J1 * (u0 - Mc(-1) - v tanh(a w0 + b0)), Mc(-1) = 0
    cn = CompiledNetwork(inertia_network())
    theta = cn.theta0()
    u = np.array([[1.7]])
    J1, w0, a, b0, v = 0.2, 0.4, 2.0, 0.1, 0.3
    _, dy = cn.jacobian(theta, u, {"w": w0})
    force = 1.7 - v * np.tanh(a * w0 + b0)
    assert dy[0, 0, 0] == pytest.approx(-0.001 / J1**2 * force, rel=1e-12)  # d/dJ1
    assert dy[0, 0, 5] == pytest.approx(-0.001 / J1 * np.tanh(a * w0 + b0), rel=1e-12)  # d/dv
    assert dy[0, 0, 3] == pytest.approx(-0.001 / J1 * v * (1 - np.tanh(a * w0 + b0) ** 2) * w0, rel=1e-12)


def test_fixed_parameters_are_not_differentiated():
    cn_all = CompiledNetwork(inertia_network())
    cn = CompiledNetwork(inertia_network(fixed_c=True))
    assert "c" not in cn.names and cn.names == ("J1", "d", "a", "b0", "v", "s")
    u = np.random.default_rng(3).normal(size=(200, 1))
    init = {"w": -0.2}
    dy = assert_jacobian_matches(cn, cn.theta0(), u, init)
    _, dy_all = cn_all.jacobian(cn_all.theta0(), u, init)
    np.testing.assert_allclose(dy, np.delete(dy_all, 1, axis=-1), rtol=1e-13, atol=1e-16)
    with pytest.raises(ValueError, match="fixed"):
        CompiledNetwork(inertia_network(fixed_c=True), free=["c"])
    with pytest.raises(ValueError, match="neither"):
        CompiledNetwork(inertia_network(), free=["J2"])


def test_explicit_subset_of_theta():
    cn = CompiledNetwork(inertia_network(), free=["v", "J1"])
    assert cn.names == ("v", "J1")
    np.testing.assert_array_equal(cn.theta0(), [0.3, 0.2])
    u = np.random.default_rng(4).normal(size=(200, 1))
    assert_jacobian_matches(cn, [0.25, 0.3], u, {"w": 0.0})
    params, free = cn.values([0.25, 0.3])
    assert params["J1"] == 0.3 and free["v"] == 0.25 and free["a"] == 2.0 and params["c"] == 5.0


def test_sin_and_cos_neurons():
    net = hand_network(
        layers=[("h", ["sin", "cos"]), ("y", "linear")],
        weights=[
            WeightSpec("IW", 0, 0, source=0, coef="k"),
            WeightSpec("LW", 0, 0, source=1, delay=1, coef="1", free="f0"),
            WeightSpec("IW", 0, 1, source=0, delay=1, coef="1", free="f1"),
            WeightSpec("LW", 0, 1, source=0, col=1, delay=2, coef="1", free="f2"),
            WeightSpec("b", 0, 1, coef="1", free="b1"),
            WeightSpec("LW", 1, 0, source=0, col=0, coef="1", free="v0"),
            WeightSpec("LW", 1, 0, source=0, col=1, coef="k*k", free="v1"),
            WeightSpec("LW", 1, 0, source=1, delay=1, coef="0.5"),
        ],
        outputs=[("y", 1)],
        parameters={"k": 1.3},
        free_weights={"f0": 0.4, "f1": -0.8, "f2": 0.6, "b1": 0.2, "v0": 0.9, "v1": -0.5},
    )
    cn = CompiledNetwork(net)
    u = np.random.default_rng(7).uniform(-2, 2, size=(300, 1))
    assert_jacobian_matches(cn, cn.theta0(), u)


def test_fixed_free_weight_and_no_theta():
    net = random_gdnn(4, layers=(2, 1))
    fixed = {net.free_weights[0].name, net.free_weights[3].name}
    net = hand_network(
        layers=[(la.name, [n.transfer for n in la.neurons]) for la in net.layers],
        weights=net.weights,
        outputs=[(o.name, o.layer, o.neuron) for o in net.outputs],
        free_weights={
            f.name: FreeWeightSpec(f.name, f.init, fixed=f.name in fixed) for f in net.free_weights
        },
    )
    cn = CompiledNetwork(net)
    assert fixed.isdisjoint(cn.names) and cn.n_theta == len(net.free_weights) - 2
    u = np.random.default_rng(8).normal(size=(200, 1))
    assert_jacobian_matches(cn, cn.theta0(), u)
    empty = CompiledNetwork(net, free=[])
    y, dy = empty.jacobian([], u)
    assert dy.shape == (200, 1, 0)
    np.testing.assert_allclose(y, cn.simulate(cn.theta0(), u), rtol=1e-14)

"""The `sat` function (hard clip to [-1, 1]): chart -> network -> runtime, against hand-computed values."""

import numpy as np

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.continuous import simulate_continuous

CHART = """
sdnn: 1
name: clipped_lag
sample_time: 0.01
substeps: 1        # the hand recursion and the quasi-online kernel: one step per sample
inputs: {u: {}}
outputs: {y: {}}
parameters:
  L: {init: 0.5, min: 0}
  a: {init: 2.0}
blocks:
  s:   {type: function, f: sat, in: u, k: 1/L}
  us:  {type: gain, in: s, k: L}
  e:   {type: sum, in: [us, -ay]}
  ay:  {type: gain, in: y, k: a}
  y:   {type: integrator, in: e}
"""


def _hand(u, L, a, T):
    # implicit Euler on the forward path, the feedback a*y delayed one sample (explicit)
    y, out = 0.0, []
    for uk in u:
        y = y + T * (np.clip(uk, -L, L) - a * y)
        out.append(y)
    return np.array(out)


def test_sat_network_matches_hand_recursion_and_jacobian_matches_differences():
    d = diagram_from_text(CHART)
    net = compile_diagram(d).network
    cn = CompiledNetwork(net)
    u = np.sin(np.linspace(0, 12, 300))[:, None] * 1.3
    theta = np.array([0.5, 2.0])
    y = cn.simulate(theta, u)[:, 0]
    np.testing.assert_allclose(y, _hand(u[:, 0], 0.5, 2.0, 0.01), rtol=0, atol=1e-12)
    _, jac = cn.jacobian(theta, u)
    for i in range(2):
        h = 1e-6
        tp, tm = theta.copy(), theta.copy()
        tp[i] += h
        tm[i] -= h
        fd = (cn.simulate(tp, u)[:, 0] - cn.simulate(tm, u)[:, 0]) / (2 * h)
        np.testing.assert_allclose(jac[:, 0, i], fd, rtol=1e-5, atol=1e-8)


def test_sat_continuous_oracle_clips():
    d = diagram_from_text(CHART)
    u = np.full((200, 1), 3.0)
    y = simulate_continuous(d, u)[:, 0]
    # dy/dt = L - a*y with the input clipped to L = 0.5: y -> L/a
    t = np.arange(200) * 0.01
    np.testing.assert_allclose(y, 0.25 * (1 - np.exp(-2.0 * t)), atol=1e-6)


def test_sat_in_the_quasi_online_kernel_matches_the_runtime():
    """The online kernel runs its own copy of the network: on noise-free data made by the runtime at the true
    values, it must see zero error (a wrong clip would leave a residual and move the parameters)."""
    from flowchart2sdnn.identify.online.run import OnlineOptions, quasi_online

    d = diagram_from_text(CHART)
    cn = CompiledNetwork(compile_diagram(d).network)
    u = np.sin(np.linspace(0, 12, 300))[:, None] * 1.3
    theta = np.array([0.5, 2.0])
    assert np.any(np.abs(u) > 0.5)  # the clip is active in this record
    y = cn.simulate(theta, u)
    res = quasi_online(cn, u, y, theta, options=OnlineOptions(window=50, average=10, block=20))
    assert res.mean_cost < 1e-20
    np.testing.assert_allclose(res.theta_final, theta, rtol=1e-9)

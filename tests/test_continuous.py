"""The continuous oracle against scipy (solve_ivp per ZOH interval, exact ZOH discretization) and hand rules."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from continuous_charts import FRICTION1, FRICTION2, TMS_PARAMETERS, block, chart, two_mass
from scipy.integrate import solve_ivp
from scipy.signal import cont2discrete

from flowchart2sdnn.diagram.model import NonlinearWeights
from flowchart2sdnn.simulate.continuous import RelayFeedback, simulate_continuous


def zoh_reference(rhs, x0, u, T):
    """States at t_k: integrate each interval separately with the input held (DOP853, tight tolerances)."""
    xs = [np.asarray(x0, dtype=float)]
    for k in range(len(u) - 1):
        sol = solve_ivp(lambda t, x, uk=u[k]: rhs(x, uk), (0.0, T), xs[-1], method="DOP853", rtol=1e-10,
                        atol=1e-12)
        assert sol.success
        xs.append(sol.y[:, -1])
    return np.array(xs)


def staircase(rng, q, hold, scale):
    """A piecewise-constant test input (levels changing every `hold` samples)."""
    return np.repeat(rng.uniform(-scale, scale, q // hold + 1), hold)[:q]


def lag_chart(T=0.01):
    return chart(["u"], ["y"], [
        block("Ku", "gain", "u", k="K"),
        block("e", "sum", "Ku", "-y"),
        block("dy", "gain", "e", k="1/tau"),
        block("y", "integrator", "dy", init=0.5),
    ], {"K": 2.0, "tau": 0.05}, T)


def msd_chart(T=0.005):
    return chart(["F"], ["x", "v"], [
        block("Fnet", "sum", "F", "-Fd", "-Fk"),
        block("acc", "gain", "Fnet", k="1/m"),
        block("v", "integrator", "acc", init=0.0),
        block("x", "integrator", "v", init=0.1),
        block("Fd", "gain", "v", k="c"),
        block("Fk", "gain", "x", k="k"),
    ], {"m": 0.5, "c": 0.8, "k": 120.0}, T)


def test_first_order_lag_matches_solve_ivp_and_closed_form():
    T, q = 0.01, 120
    u = staircase(np.random.default_rng(1), q, 7, 3.0)
    K, tau = 1.5, 0.08  # overrides of the chart's values
    y = simulate_continuous(lag_chart(T), u[:, None], parameters={"K": K, "tau": tau})
    ref = zoh_reference(lambda x, uk: (K * uk - x) / tau, [0.5], u, T)
    np.testing.assert_allclose(y, ref, atol=1e-9)
    a = np.exp(-T / tau)
    exact = [0.5]
    for k in range(q - 1):
        exact.append(a * exact[-1] + (1 - a) * K * u[k])
    np.testing.assert_allclose(y[:, 0], exact, atol=1e-9)
    assert y[0, 0] == 0.5  # row 0 holds the initial value


def test_mass_spring_damper_matches_solve_ivp_and_exact_zoh():
    T, q = 0.005, 200
    m, c, k = 0.5, 0.8, 120.0
    u = staircase(np.random.default_rng(2), q, 9, 5.0)
    y = simulate_continuous(msd_chart(T), u)  # 1-D input accepted for one input
    A = np.array([[0.0, 1.0], [-k / m, -c / m]])
    B = np.array([[0.0], [1.0 / m]])
    ref = zoh_reference(lambda x, uk: A @ x + B[:, 0] * uk, [0.1, 0.0], u, T)
    np.testing.assert_allclose(y, ref, atol=1e-9)
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), T, method="zoh")
    x = np.array([0.1, 0.0])
    exact = [x]
    for j in range(q - 1):
        x = Ad @ x + Bd[:, 0] * u[j]
        exact.append(x)
    np.testing.assert_allclose(y, np.array(exact), atol=1e-9)


def friction(w, weights):
    b = np.zeros(len(weights.a)) if weights.b is None else np.asarray(weights.b)
    return float(np.sum(np.asarray(weights.v) * np.tanh(np.asarray(weights.a) * w + b)))


def tms_rhs(x, m1, p=TMS_PARAMETERS):
    """The two-mass system written from the physics (not from the chart): x = (w1, dphi, w2)."""
    w1, dphi, w2 = x
    shaft = p["c"] * dphi + p["d"] * (w1 - w2)
    return np.array([
        (m1 - shaft - friction(w1, FRICTION1)) / p["J1"],
        w1 - w2,
        (shaft - friction(w2, FRICTION2)) / p["J2"],
    ])


def test_two_mass_with_tanh_friction_matches_solve_ivp():
    T, q = 1e-3, 300
    u = staircase(np.random.default_rng(3), q, 23, 7.0)
    sig = simulate_continuous(two_mass(T), u[:, None], signals=True)
    ref = zoh_reference(tms_rhs, [0.0, 0.0, 0.0], u, T)
    np.testing.assert_allclose(sig["w1"], ref[:, 0], atol=1e-8)
    np.testing.assert_allclose(sig["dphi"], ref[:, 1], atol=1e-9)
    np.testing.assert_allclose(sig["w2"], ref[:, 2], atol=1e-8)
    assert np.ptp(ref[:, 0]) > 0.5  # the test moved the plant
    np.testing.assert_allclose(sig["M1"], u)
    y = simulate_continuous(two_mass(T), u[:, None])
    np.testing.assert_array_equal(y, np.column_stack([sig["w2"], sig["w1"]]))


def test_block_order_does_not_matter():
    T, q = 1e-3, 200
    u = staircase(np.random.default_rng(4), q, 17, 7.0)[:, None]
    base = two_mass(T)
    y0 = simulate_continuous(base, u)
    perm = np.random.default_rng(5).permutation(len(base.blocks))
    shuffled = dataclasses.replace(base, blocks=tuple(base.blocks[i] for i in perm))
    np.testing.assert_allclose(simulate_continuous(shuffled, u), y0, rtol=0, atol=1e-12)


def test_memoryless_blocks():
    u = np.linspace(-2.0, 2.0, 41)
    w = NonlinearWeights(a=(3.0, 0.5), v=(1.5, -0.7), b=(0.2, -1.0))
    c = chart(["u"], ["nl", "th", "sn", "cs", "sg", "sg2", "one"], [
        block("nl", "nonlinear", "-u", weights=w),
        block("th", "function", "u", f="tanh", k="2"),
        block("sn", "function", "u", f="sin", k="g"),
        block("cs", "function", "u", f="cos"),
        block("sg", "function", "u", f="sign_smooth"),
        block("sg2", "function", "u", f="sign_smooth", k="3", eps=0.5),
        block("one", "constant", k="2*g"),
    ], {"g": 1.3})
    y = simulate_continuous(c, u)
    np.testing.assert_allclose(y[:, 0], 1.5 * np.tanh(-3.0 * u + 0.2) - 0.7 * np.tanh(-0.5 * u - 1.0))
    np.testing.assert_allclose(y[:, 1], np.tanh(2 * u))
    np.testing.assert_allclose(y[:, 2], np.sin(1.3 * u))
    np.testing.assert_allclose(y[:, 3], np.cos(u))
    np.testing.assert_allclose(y[:, 4], np.tanh(u / 1e-3))
    np.testing.assert_allclose(y[:, 5], np.tanh(3 * u / 0.5))
    np.testing.assert_allclose(y[:, 6], 2.6)


def test_delay_of_an_input_and_of_a_state():
    T, q, n = 0.01, 30, 3
    u = np.random.default_rng(6).uniform(-1, 1, q)
    c = chart(["u"], ["d", "y", "dy", "d0"], [
        block("d", "delay", "u", n=n),
        block("y", "integrator", "d", init=0.7),  # integrates the delayed input
        block("dy", "delay", "y", n=2),
        block("d0", "delay", "-u", n=0),
    ], sample_time=T)
    out = simulate_continuous(c, u)
    expect_d = u[np.maximum(np.arange(q) - n, 0)]  # before t_0 the operand's value at t_0
    np.testing.assert_allclose(out[:, 0], expect_d)
    expect_y = 0.7 + T * np.concatenate([[0.0], np.cumsum(expect_d[:-1])])
    np.testing.assert_allclose(out[:, 1], expect_y, atol=1e-12)
    np.testing.assert_allclose(out[:, 2], expect_y[np.maximum(np.arange(q) - 2, 0)], atol=1e-12)
    np.testing.assert_allclose(out[:, 3], -u)


def test_delay_held_over_the_interval():
    # y' = d with d the delayed input: within an interval d is constant, so y grows by exactly T * d_k
    T = 0.1
    c = chart(["u"], ["y"], [block("d", "delay", "u", n=1), block("y", "integrator", "d", init=0.0)],
              sample_time=T)
    y = simulate_continuous(c, np.array([1.0, 2.0, 3.0, 4.0]), substeps=1)
    np.testing.assert_allclose(y[:, 0], [0.0, 0.1, 0.2, 0.4])


def test_discrete_loop_through_a_delay_starts_from_zero():
    # s = z^-1 y, y = s + u is an accumulator: y_k = u_0 + ... + u_k
    u = np.random.default_rng(7).normal(size=25)
    c = chart(["u"], ["y", "s"], [block("y", "sum", "s", "u"), block("s", "delay", "y", n=1)])
    out = simulate_continuous(c, u)
    np.testing.assert_allclose(out[:, 0], np.cumsum(u), atol=1e-12)
    np.testing.assert_allclose(out[:, 1], np.concatenate([[0.0], np.cumsum(u)[:-1]]), atol=1e-12)


def test_init_data_and_nonlinear_override():
    c = chart(["u"], ["y"], [
        block("f", "nonlinear", "y"),
        block("e", "sum", "u", "-f"),
        block("y", "integrator", "e", init="data"),
    ], sample_time=0.01)
    u = np.ones(50)
    with pytest.raises(ValueError, match="init"):
        simulate_continuous(c, u, nonlinear={"f": NonlinearWeights((1.0,), (1.0,))})
    with pytest.raises(ValueError, match="nonlinear block without weights"):
        simulate_continuous(c, u, init={"y": 0.2})
    w = NonlinearWeights((1.0,), (2.0,))
    y = simulate_continuous(c, u, init={"y": 0.2}, nonlinear={"f": w})
    ref = zoh_reference(lambda x, uk: np.array([uk - 2.0 * np.tanh(x[0])]), [0.2], u, 0.01)
    np.testing.assert_allclose(y, ref, atol=1e-10)


def test_algebraic_loop_is_named():
    c = chart(["u"], ["a"], [block("a", "sum", "u", "-b"), block("b", "gain", "a", k="2")])
    with pytest.raises(ValueError, match=r"algebraic loop.*(a -> b -> a|b -> a -> b)"):
        simulate_continuous(c, np.zeros(5))
    # a zero-sample delay is a sample-and-hold, which feeds through: still a loop
    c0 = chart(["u"], ["a"], [block("a", "sum", "u", "-b"), block("b", "delay", "a", n=0)])
    with pytest.raises(ValueError, match="algebraic loop"):
        simulate_continuous(c0, np.zeros(5))


def test_blow_up_names_the_time():
    c = chart(["u"], ["y"], [block("g", "gain", "y", k="1e4"), block("y", "integrator", "g", init=1.0)],
              sample_time=0.01)
    with pytest.raises(ValueError, match=r"non-finite at t = \d"):
        simulate_continuous(c, np.zeros(200))


@pytest.mark.parametrize("kwargs, match", [
    ({"parameters": {"tauu": 1.0}}, "unknown parameter 'tauu'"),
    ({"parameters": {"tau": 0.0}}, "cannot evaluate k"),
    ({"substeps": 0}, "substeps"),
    ({"init": {"nope": 1.0}}, "'nope', which is not an integrator"),
    ({"init": {"e": 1.0}}, "'e', which is not an integrator"),
    ({"init": {"y": float("inf")}}, "not finite"),
    ({"nonlinear": {"y": NonlinearWeights((1.0,), (1.0,))}}, "not a nonlinear block"),
    ({"controller": RelayFeedback(input="u", measured="Ku")}, "depends on 'u'"),
    ({"controller": RelayFeedback(input="y", measured="y")}, "not a chart input"),
])
def test_argument_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        simulate_continuous(lag_chart(), np.zeros((10, 1)), **kwargs)


def test_input_shape_errors():
    with pytest.raises(ValueError, match="shape"):
        simulate_continuous(lag_chart(), np.zeros((10, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        simulate_continuous(lag_chart(), np.full((10, 1), np.nan))
    with pytest.raises(TypeError):
        simulate_continuous(lag_chart(), np.zeros((10, 1)), controller=object())


def test_signals_dict_has_inputs_and_blocks():
    sig = simulate_continuous(lag_chart(), np.ones((5, 1)), signals=True)
    assert list(sig) == ["u", "Ku", "e", "dy", "y"]
    np.testing.assert_allclose(sig["Ku"], 2.0)
    np.testing.assert_allclose(sig["e"], sig["Ku"] - sig["y"])


ENGINE_YAML = """
sdnn: 1
name: engine
sample_time: 0.001
inputs: {M1: {}}
outputs: {w1: {}}
parameters: {J1: 0.1912, Fs: 1.2, Fc: 0.8, b: 0.02, ws: 1.0}
blocks:
  MB1:  {type: sum, in: [M1, -MR1]}
  acc1: {type: gain, in: MB1, k: 1/J1}
  w1:   {type: integrator, in: acc1}
  sg:   {type: function, f: sign_smooth, in: w1, eps: 0.001}
  st:   {type: function, f: tanh, in: w1, k: 1/ws}
  Fsg:  {type: gain, in: sg, k: Fs}
  Fst:  {type: gain, in: st, k: Fs-Fc}
  Fv:   {type: gain, in: w1, k: b}
  MR1:  {type: sum, in: [Fsg, -Fst, Fv]}
"""


def test_stiff_stribeck_friction_from_yaml_matches_radau():
    from flowchart2sdnn.diagram import diagram_from_text

    T, q = 1e-3, 300
    J1, Fs, Fc, b, ws = 0.1912, 1.2, 0.8, 0.02, 1.0
    u = staircase(np.random.default_rng(8), q, 37, 4.0)  # often below the breakaway torque: sticking

    def rhs(x, m1):
        w = x[0]
        return np.array([(m1 - Fs * np.tanh(w / 1e-3) + (Fs - Fc) * np.tanh(w / ws) - b * w) / J1])

    xs = [np.zeros(1)]
    for k in range(q - 1):
        sol = solve_ivp(lambda t, x, uk=u[k]: rhs(x, uk), (0.0, T), xs[-1], method="Radau", rtol=1e-10,
                        atol=1e-12)
        xs.append(sol.y[:, -1])
    y = simulate_continuous(diagram_from_text(ENGINE_YAML), u[:, None])
    np.testing.assert_allclose(y[:, 0], np.array(xs)[:, 0], atol=1e-6)
    assert np.ptp(y) > 0.5 and np.mean(np.abs(y) < 0.01) > 0.05  # it both slid and stuck

"""Levenberg-Marquardt trainer: one step by hand, convergence against scipy and NIST, bounds, divergence."""

import inspect

import nist_misra1a as misra
import numpy as np
import pytest
from scipy.optimize import least_squares

from flowchart2sdnn.fit import lm as lm_module
from flowchart2sdnn.fit.lm import STATUS_MESSAGES, LMOptions, levenberg_marquardt

# a small line fit: yhat = a * t + b
T5 = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
Y5 = np.array([1.1, 2.9, 5.2, 7.1, 8.8])


def line(p):
    return Y5 - (p[0] * T5 + p[1]), np.column_stack([T5, np.ones_like(T5)])


def test_one_iteration_matches_the_hand_computation():
    x0 = np.array([0.5, -1.0])
    mu = 0.5
    e0, J = line(x0)
    # eq. (11) with e = y - yhat: w1 = w0 + (J^T J + mu I)^-1 J^T e, J = d yhat / dw
    expected = x0 + np.linalg.solve(J.T @ J + mu * np.eye(2), J.T @ e0)
    res = levenberg_marquardt(line, x0, ["a", "b"], options=LMOptions(max_iter=1, mu0=mu))
    np.testing.assert_allclose(res.x, expected, rtol=1e-13)
    assert res.status == "max_iter" and res.iterations == 1
    e1 = Y5 - (expected[0] * T5 + expected[1])
    np.testing.assert_allclose(res.cost_history, [0.5 * e0 @ e0, 0.5 * e1 @ e1], rtol=1e-13)
    np.testing.assert_allclose(res.mu_history, [mu, mu * 0.1])
    np.testing.assert_allclose(res.residual, e1, rtol=1e-12)
    np.testing.assert_allclose(res.jac, J)


def test_one_bounded_iteration_is_taken_in_internal_coordinates():
    x0 = np.array([0.5, -1.0])
    lo_a, mu = 0.2, 0.5
    e0, J = line(x0)
    u0 = np.array([np.sqrt((x0[0] - lo_a + 1) ** 2 - 1), x0[1]])
    Ju = J * np.array([u0[0] / np.sqrt(u0[0] ** 2 + 1), 1.0])
    u1 = u0 + np.linalg.solve(Ju.T @ Ju + mu * np.eye(2), Ju.T @ e0)
    expected = np.array([lo_a - 1 + np.sqrt(u1[0] ** 2 + 1), u1[1]])
    res = levenberg_marquardt(
        line, x0, ["a", "b"], lower=[lo_a, -np.inf], options=LMOptions(max_iter=1, mu0=mu)
    )
    np.testing.assert_allclose(res.x, expected, rtol=1e-12)


def test_mu_schedule_and_monotone_cost():
    # a strongly nonlinear fit from far away forces rejected steps
    t = np.linspace(0, 2, 30)
    y = 3.0 * np.exp(-1.7 * t)

    def fun(p):
        ex = np.exp(-p[1] * t)
        return y - p[0] * ex, np.column_stack([ex, -p[0] * t * ex])

    res = levenberg_marquardt(fun, [1.0, 8.0], ["A", "k"], options=LMOptions(max_iter=200))
    assert res.converged
    np.testing.assert_allclose(res.x, [3.0, 1.7], rtol=1e-8)
    assert res.rejected_cost > 0
    costs = np.array(res.cost_history)
    assert np.all(np.diff(costs) < 0)
    # between accepted steps mu is multiplied by mu_dec once and by mu_inc some k >= 0 times
    ratios = np.array(res.mu_history[1:]) / np.array(res.mu_history[:-1])
    k = np.log(ratios / 0.1) / np.log(10.0)
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)
    assert np.all(np.round(k) >= 0) and np.any(np.round(k) > 0)


def test_a_step_that_raises_the_cost_is_rejected():
    def fun(p):  # yhat = sin(x), y = 0
        return -np.sin(p), np.cos(p)[:, None]

    # the undamped step from 1.2 lands at 1.2 - tan(1.2) = -1.372, where the cost is 1.1x higher
    assert np.sin(1.2 - np.tan(1.2)) ** 2 > np.sin(1.2) ** 2
    evaluated = []

    def traced(p):
        evaluated.append(0.5 * np.sin(p[0]) ** 2)
        return fun(p)

    res = levenberg_marquardt(traced, [1.2], ["x"], options=LMOptions(mu0=1e-9, max_iter=1))
    assert res.rejected_cost >= 1
    assert res.cost < evaluated[0] and res.cost == min(evaluated)
    # mu grew by mu_inc at each rejection, then shrank once by mu_dec
    assert res.mu_history[1] == pytest.approx(1e-9 * 10.0**res.rejected_cost * 0.1)


def test_rosenbrock_as_residuals():
    def fun(p):
        e = np.array([10 * (p[1] - p[0] ** 2), 1 - p[0]])
        de = np.array([[-20 * p[0], 10.0], [-1.0, 0.0]])
        return e, -de  # J = d yhat / dx = -de/dx

    res = levenberg_marquardt(fun, [-1.2, 1.0], ["x1", "x2"])
    assert res.converged, res.message
    assert res.status != "min_grad" or res.mu == res.mu_history[-1]
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-8)


def test_exponential_decay_matches_scipy():
    rng = np.random.default_rng(7)
    t = np.linspace(0, 5, 60)
    y = 2.5 * np.exp(-0.8 * t) + 0.3 + 0.02 * rng.normal(size=t.size)

    def model(p):
        return p[0] * np.exp(-p[1] * t) + p[2]

    def fun(p):
        ex = np.exp(-p[1] * t)
        return y - model(p), np.column_stack([ex, -p[0] * t * ex, np.ones_like(t)])

    ref = least_squares(lambda p: y - model(p), [1.0, 0.3, 0.0], xtol=1e-15, ftol=1e-15, gtol=1e-15)
    res = levenberg_marquardt(fun, [1.0, 0.3, 0.0], ["A", "k", "c"])
    assert res.converged, res.message
    np.testing.assert_allclose(res.x, ref.x, rtol=1e-6)
    np.testing.assert_allclose(res.cost, ref.cost, rtol=1e-9)


def test_nist_misra1a_start_1():
    res = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"])
    assert res.converged, res.message
    np.testing.assert_allclose(res.x, misra.CERTIFIED, rtol=1e-6)
    np.testing.assert_allclose(2 * res.cost, misra.RESIDUAL_SUM_OF_SQUARES, rtol=1e-8)


def test_residual_only_model_gives_the_same_fit_with_fewer_jacobians():
    plain = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"])
    split = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"], residual=misra.residual)
    np.testing.assert_allclose(split.x, plain.x, rtol=1e-12)
    assert split.iterations == plain.iterations
    assert split.njev == split.iterations + 1
    assert split.nfev > split.njev


def line_with_slope(a_true=2.0, b_true=1.0):
    t = np.linspace(0, 1, 11)
    y = a_true * t + b_true
    return t, y


@pytest.mark.parametrize(
    "lower, upper, a_end",
    [([-np.inf, -np.inf], [1.5, np.inf], 1.5), ([2.5, -np.inf], None, 2.5), ([-1.0, -5.0], [1.2, 5.0], 1.2)],
)
def test_bounds_are_never_violated_and_an_outside_optimum_ends_on_the_bound(lower, upper, a_end):
    t, y = line_with_slope()
    seen = []

    def fun(p):
        seen.append(p.copy())
        return y - (p[0] * t + p[1]), np.column_stack([t, np.ones_like(t)])

    def callback(it, x, cost, mu):
        seen.append(x.copy())

    def guard(x):
        seen.append(x.copy())

    x0 = [1.0 if a_end < 2 else 3.0, 0.0]
    res = levenberg_marquardt(
        fun, x0, ["a", "b"], lower, upper, options=LMOptions(max_iter=500), callback=callback, guard=guard
    )
    lo = np.array(lower, dtype=float)
    hi = np.full(2, np.inf) if upper is None else np.array(upper, dtype=float)
    seen = np.array(seen)
    assert len(seen) > 10
    assert np.all(seen >= lo) and np.all(seen <= hi)
    assert res.converged, res.message
    # with a fixed at its bound the best b is the mean of y - a t (closed form)
    np.testing.assert_allclose(res.x, [a_end, np.mean(y - a_end * t)], atol=1e-7)


def test_a_start_on_a_bound_can_leave_it():
    t, y = line_with_slope()

    def fun(p):
        return y - (p[0] * t + p[1]), np.column_stack([t, np.ones_like(t)])

    res = levenberg_marquardt(
        fun, [0.0, 0.0], ["a", "b"], lower=[0.0, -np.inf], options=LMOptions(max_iter=300)
    )
    np.testing.assert_allclose(res.x, [2.0, 1.0], atol=1e-7)


def decay_problem():
    t = np.linspace(0, 3, 25)
    y = np.exp(-1.3 * t)

    def fun(p):
        ex = np.exp(-p[0] * t)
        return y - ex, (-t * ex)[:, None]

    return fun


@pytest.mark.parametrize("how", ["nan", "none", "raise", "nan_jacobian"])
def test_a_diverging_region_is_rejected_and_the_result_is_finite(how):
    base = decay_problem()
    calls = []

    def fun(p):
        calls.append(p[0])
        if p[0] < 1.0:  # "the simulation blows up" for slow decay
            if how == "nan":
                return np.full(25, np.nan), np.zeros((25, 1))
            if how == "none":
                return None
            if how == "raise":
                raise FloatingPointError("overflow")
            e, J = base(p)
            return e, np.full_like(J, np.inf)
        return base(p)

    # from k = 6 the first Gauss-Newton-like step lands far below 1.0
    res = levenberg_marquardt(fun, [6.0], ["k"], options=LMOptions(mu0=1e-6, max_iter=200))
    assert min(calls) < 1.0, "the test must visit the diverging region"
    assert res.rejected_diverged > 0
    assert np.all(np.isfinite(res.x)) and np.isfinite(res.cost)
    assert all(np.isfinite(res.cost_history)) and all(np.isfinite(res.mu_history))
    np.testing.assert_allclose(res.x, [1.3], rtol=1e-8)


def test_divergence_at_the_start_is_reported():
    res = levenberg_marquardt(lambda p: None, [1.0, 2.0], ["a", "b"])
    assert res.status == "diverged_at_start"
    assert res.message == STATUS_MESSAGES["diverged_at_start"]
    assert "start values" in res.message
    np.testing.assert_array_equal(res.x, [1.0, 2.0])
    assert res.iterations == 0 and not res.converged


def test_guard_rejects_trial_steps_before_simulation():
    fun = decay_problem()
    simulated = []

    def wrapped(p):
        simulated.append(p[0])
        return fun(p)

    def guard(x):
        return "friction slope 12 exceeds 2J/T = 8" if x[0] < 0.0 else None

    # unguarded, the first step from k = 4 goes to about -1.1
    res = levenberg_marquardt(wrapped, [4.0], ["k"], options=LMOptions(mu0=1e-6), guard=guard)
    assert res.rejected_guard > 0
    assert res.last_guard_reason == "friction slope 12 exceeds 2J/T = 8"
    assert min(simulated) >= 0.0
    np.testing.assert_allclose(res.x, [1.3], rtol=1e-8)


def test_guard_message_appears_when_it_blocks_everything():
    fun = decay_problem()
    res = levenberg_marquardt(fun, [0.5], ["k"], guard=lambda x: "always unstable")
    assert res.status in ("mu_max", "max_mu_tries")
    assert "always unstable" in res.message
    assert res.status != "mu_max" or res.mu > LMOptions().mu_max
    np.testing.assert_array_equal(res.x, [0.5])


def test_callback_can_stop():
    seen = []

    def callback(it, x, cost, mu):
        seen.append((it, cost, mu))
        return it == 2

    res = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"], callback=callback)
    assert res.status == "callback_stop" and res.iterations == 2
    assert [s[0] for s in seen] == [1, 2]
    assert seen[-1][1] == res.cost and seen[-1][2] == res.mu_history[-1]


def test_keyboard_interrupt_returns_the_best_point_so_far():
    n = [0]

    def fun(b):
        n[0] += 1
        if n[0] == 6:
            raise KeyboardInterrupt
        return misra.fun(b)

    res = levenberg_marquardt(fun, [500.0, 1e-4], ["b1", "b2"])
    assert res.interrupted and res.status == "interrupted"
    e, _ = misra.fun(res.x)
    np.testing.assert_allclose(res.cost, 0.5 * e @ e, rtol=1e-14)
    assert res.cost == min(res.cost_history)
    assert len(res.cost_history) == res.iterations + 1 == len(res.mu_history)


def test_exact_fit_converges_and_max_iter_zero_returns_the_start():
    res = levenberg_marquardt(line, [0.0, 0.0], ["a", "b"], options=LMOptions(max_iter=0))
    assert res.status == "max_iter" and res.iterations == 0
    np.testing.assert_array_equal(res.x, [0.0, 0.0])
    t, y = line_with_slope()
    res = levenberg_marquardt(
        lambda p: (y - p[0] * t - p[1], np.column_stack([t, np.ones_like(t)])), [0.0, 0.0], ["a", "b"]
    )
    assert res.converged and res.status in ("min_grad", "small_step", "cost_goal")
    np.testing.assert_allclose(res.x, [2.0, 1.0], atol=1e-10)


def test_small_cost_change_stop():
    res = levenberg_marquardt(
        misra.fun, misra.START_1, ["b1", "b2"], options=LMOptions(min_rel_cost_change=1e-3)
    )
    assert res.status == "small_cost_change"
    assert (res.cost_history[-2] - res.cost_history[-1]) / res.cost_history[-2] < 1e-3


def test_damped_step_falls_back_to_least_squares_when_cholesky_fails():
    Ju = np.array([[1.0, 1.0], [2.0, 2.0], [0.0, 0.0]])  # rank 1: J^T J singular
    e = np.array([1.0, 0.5, 0.3])
    du = lm_module.damped_step(Ju, e, Ju.T @ Ju, Ju.T @ e, 0.0)
    np.testing.assert_allclose(du, np.linalg.lstsq(Ju, e, rcond=None)[0], rtol=1e-12)


def test_never_inverts_and_never_prints(capsys):
    from flowchart2sdnn.fit import uncertainty

    for module in (lm_module, uncertainty):
        source = inspect.getsource(module)
        assert "inv(" not in source and "print(" not in source
    levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"])
    assert capsys.readouterr() == ("", "")


def test_arguments_are_validated():
    with pytest.raises(ValueError, match=r"`b` = -1 is below its min 0"):
        levenberg_marquardt(line, [1.0, -1.0], ["a", "b"], lower=[0.0, 0.0])
    with pytest.raises(ValueError, match="`names` has 1 entries"):
        levenberg_marquardt(line, [1.0, -1.0], ["a"])
    with pytest.raises(ValueError, match="not unique: a"):
        levenberg_marquardt(line, [1.0, -1.0], ["a", "a"])
    with pytest.raises(ValueError, match="mu_inc"):
        LMOptions(mu_inc=0.5)
    with pytest.raises(ValueError, match="Jacobian must have shape"):
        levenberg_marquardt(lambda p: (Y5, np.ones((5, 3))), [1.0, -1.0], ["a", "b"])
    with pytest.raises(ValueError, match="residual changed length"):
        sizes = iter([5, 4, 4, 4])
        levenberg_marquardt(lambda p: (np.ones(k := next(sizes)), np.ones((k, 1))), [1.0], ["a"])


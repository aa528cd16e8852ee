"""The trust radius's trial bookkeeping (fit.lm): its stop at the cost's rounding and which first trials are
simulated with their Jacobian (``trial_jacobian``; LONG_STEP).

Oracles: scipy's least_squares (trf, a decay's minimum) and the minimum of Rosenbrock's function, (1, 1);
the documented rule itself checked on plain geometry (``scale = "none"``: the trainer's step lengths are the
Euclidean lengths of the steps between the points it simulates), from a log of the calls the trainer makes.
"""

import math

import numpy as np
from scipy.optimize import least_squares

from flowchart2sdnn.fit import lm, stopping
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt

#: every other convergence test off: only the trust radius's own stops can end a run
NO_TESTS = dict(damping="trust", bounds="box", min_grad=0.0, min_rel_step=0.0, min_rel_cost_change=0.0,
                stall_decrease=0.0, max_iter=60)


T = np.linspace(0.0, 4.0, 2000)
Y = 2.0 * np.exp(-1.3 * T) - 0.2 + 0.005 * np.random.default_rng(1).normal(size=T.size)


def _decay_residual(p):
    return Y - (p[0] * np.exp(-p[1] * T) + p[2])


def _decay(p):
    e = np.exp(-p[1] * T)
    return _decay_residual(p), np.column_stack([e, -p[0] * T * e, np.ones_like(T)])


def _decay_fit():
    return levenberg_marquardt(_decay, [1.0, 0.2, 0.5], ["a", "k", "c"], [0.0, 0.0, -np.inf], np.inf,
                               LMOptions(**NO_TESTS, scale="jac"), residual=_decay_residual)


def test_a_converged_trust_fit_stops_instead_of_refusing_rounding_level_trials():
    """A decay fitted to 2000 noisy samples: once at the minimum the Gauss-Newton step predicts a decrease at
    rounding level, and the fit ends there ("small_cost_change") instead of refusing ever shorter trials whose
    cost changes only by rounding."""
    r = _decay_fit()
    ref = least_squares(_decay_residual, [1.0, 0.2, 0.5], jac=lambda p: -_decay(p)[1], method="trf",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-7)
    assert r.status == "small_cost_change" and r.converged and "rounding" in r.message
    assert r.rejected_cost == 0


def test_without_the_rounding_stop_the_tail_of_refusals_comes_back(monkeypatch):
    """The test above can fail: with the stop disabled the same fit refuses trial after trial."""
    monkeypatch.setattr(stopping, "COST_ROUNDING", -math.inf)
    r = _decay_fit()
    assert r.status != "small_cost_change" and r.rejected_cost > 5


def _rosenbrock_logged(trial_jacobian: bool):
    """(result, calls ['fun' | 'res', x], accepted points) of a trust fit of Rosenbrock's function."""
    calls, accepted = [], []

    def fun(x):
        calls.append(("fun", np.array(x)))
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]]), -np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])

    def res(x):
        calls.append(("res", np.array(x)))
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def callback(it, x, cost, mu):
        accepted.append(np.array(x))

    opts = LMOptions(**{**NO_TESTS, "max_iter": 200}, scale="none", trial_jacobian=trial_jacobian)
    r = levenberg_marquardt(fun, [-1.2, 1.0], ["x1", "x2"], options=opts, callback=callback, residual=res)
    return r, calls, accepted


def test_a_trial_much_longer_than_the_last_step_is_simulated_without_its_jacobian():
    """With the trust radius every trial, first of its iteration or after a refusal, is simulated with its Jacobian
    unless its step is more than LONG_STEP times the last accepted one."""
    r, calls, accepted = _rosenbrock_logged(True)
    np.testing.assert_allclose(r.x, [1.0, 1.0], atol=1e-8)
    points = [calls[0][1]] + accepted  # the start, then every accepted point in order
    k, seen, i = 0, {"long": 0, "short": 0, "refused": 0}, 1
    while i < len(calls):
        kind, x = calls[i]
        if kind == "res" and i + 1 < len(calls) and calls[i + 1][0] == "fun" and np.array_equal(calls[i + 1][1], x):
            i += 1  # a residual-first trial accepted: its Jacobian simulated at the same point
        last = np.linalg.norm(points[k] - points[k - 1]) if k > 0 else math.inf
        long = np.linalg.norm(x - points[k]) > lm.LONG_STEP * last
        seen["long" if long else "short"] += 1
        assert kind == ("res" if long else "fun"), f"trial {i} from point {k}"
        if k + 1 < len(points) and np.array_equal(x, points[k + 1]):
            k += 1
        else:
            seen["refused"] += 1
        i += 1
    assert k == len(points) - 1 and min(seen.values()) >= 1, seen  # the run exercised every case


def test_the_trial_jacobian_rule_changes_the_count_of_simulations_not_the_iterates():
    with_jac, _, _ = _rosenbrock_logged(True)
    without, _, _ = _rosenbrock_logged(False)
    np.testing.assert_array_equal(with_jac.cost_history, without.cost_history)
    np.testing.assert_array_equal(with_jac.x, without.x)
    assert with_jac.nfev < without.nfev

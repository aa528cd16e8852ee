"""LM's negligible-gain rule and the residual's effective samples, against closed forms: a linear least-squares
problem (Gauss-Newton exact, so one undamped step reaches the minimum), numpy's solve for 1/2 gᵀA⁻¹g, and the
AR(1) process's integrated autocorrelation time (1 + phi) / (1 - phi)."""

from __future__ import annotations

import numpy as np
import pytest

from flowchart2sdnn.fit.effective import autocorrelation_time, effective_samples
from flowchart2sdnn.fit.lm import CONVERGED_STATUSES, LMOptions, gauss_newton_gain, levenberg_marquardt
from flowchart2sdnn.fit.transforms import Bounds


def _linear_problem(seed: int = 0, m: int = 2000):
    rng = np.random.default_rng(seed)
    X = np.column_stack([np.ones(m), rng.normal(size=m), np.sin(np.linspace(0, 20, m))])
    y = X @ np.array([1.0, -2.0, 0.5]) + rng.normal(0, 0.1, m)
    return X, y


def test_gauss_newton_gain_is_half_g_a_inverse_g():
    X, y = _linear_problem()
    x = np.array([0.3, 0.1, -0.2])
    e = y - X @ x
    A, g = X.T @ X, X.T @ e
    assert gauss_newton_gain(A, g) == pytest.approx(0.5 * g @ np.linalg.solve(A, g), rel=1e-10)
    # and that is exactly the cost's fall to the least-squares minimum (the model is linear)
    best = np.linalg.lstsq(X, y, rcond=None)[0]
    fall = 0.5 * e @ e - 0.5 * np.sum((y - X @ best) ** 2)
    assert gauss_newton_gain(A, g) == pytest.approx(fall, rel=1e-8)


def test_a_linear_fit_stops_by_the_rule_at_the_least_squares_minimum():
    X, y = _linear_problem()

    def fun(x):
        return y - X @ x, X

    opts = LMOptions(max_iter=100, negligible_gain=0.1, min_grad=0.0, mu0=1e-6, mu_min=1e-20)
    r = levenberg_marquardt(fun, np.zeros(3), ["a", "b", "c"], options=opts)
    assert r.status == "negligible_gain" and r.status in CONVERGED_STATUSES and r.iterations <= 5
    np.testing.assert_allclose(r.x, np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-6)
    assert "units left by Gauss-Newton" in r.message


def test_a_quantity_pressed_against_its_bound_within_one_standard_error_is_held_there():
    X, y = _linear_problem()
    best = np.linalg.lstsq(X, y, rcond=None)[0]  # b near -2
    x = best.copy()
    x[1] = -1.99999  # the box says b >= -1.99999, the data want it just below: held at the bound
    e = y - X @ x
    A, g = X.T @ X, X.T @ e
    box = Bounds.make(["a", "b", "c"], [-np.inf, -1.99999, -np.inf], None)
    sigma2 = float(e @ e) / len(e)
    free = gauss_newton_gain(A, g, x, box, sigma2)
    # the oracle: the same gain with b's row and column removed
    keep = [0, 2]
    assert free == pytest.approx(0.5 * g[keep] @ np.linalg.solve(A[np.ix_(keep, keep)], g[keep]), rel=1e-9)
    assert free < gauss_newton_gain(A, g)


def test_the_pace_rule_stops_a_descent_that_gains_under_one_unit_in_ten_iterations():
    # gradient steps only (huge fixed damping): every iteration gains a little; the pace rule ends it once ten
    # together gain under one unit while Gauss-Newton's step predicts less than 3.84 units left
    X, y = _linear_problem()
    best = np.linalg.lstsq(X, y, rcond=None)[0]

    def fun(x):
        return y - X @ x, X

    opts = LMOptions(max_iter=5000, negligible_pace=1.0, pace_iterations=10, min_grad=0.0, mu0=1e3, mu_dec=0.999,
                     mu_inc=1.001, mu_min=1e2)
    r = levenberg_marquardt(fun, best + np.array([0.01, 0.01, 0.01]), ["a", "b", "c"], options=opts)
    assert r.status == "negligible_gain" and "gained by the last 10 iterations" in r.message
    c = np.array(r.cost_history)
    unit = c[-1] / len(y)
    assert (c[-11] - c[-1]) / unit < 1.0


def test_effective_samples_follow_the_autocorrelation_time_of_an_ar1_process():
    rng = np.random.default_rng(1)
    n, phi = 200_000, 0.8
    w = rng.normal(size=n)
    x = np.empty(n)
    x[0] = w[0]
    for k in range(1, n):
        x[k] = phi * x[k - 1] + w[k]
    assert autocorrelation_time(x) == pytest.approx((1 + phi) / (1 - phi), rel=0.1)
    assert autocorrelation_time(w) == pytest.approx(1.0, abs=0.05)
    # two outputs interleaved row by row: white and AR(1) of equal power, so tau is their mean
    white = w[:50_000] * np.std(x[:50_000]) / np.std(w[:50_000])
    both = np.column_stack([white, x[:50_000]]).ravel()
    expected = 100_000 / (0.5 * 1.0 + 0.5 * (1 + phi) / (1 - phi))
    assert effective_samples(both, 2) == pytest.approx(expected, rel=0.12)

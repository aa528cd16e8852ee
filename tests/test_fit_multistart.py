"""Multistart: reproducible seeded draws, the documented distributions, global vs local minima."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from scipy.stats import kstest

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.multistart import draw_starts, run_multistart

INF = np.inf


def test_draws_are_reproducible_and_start_with_x0():
    args = (["J2", "c", "d", "w"], [0.7, 100.0, -0.4, 0.0], [0.0, 0.0, -INF, -0.5], [INF, INF, INF, 0.5])
    a = draw_starts(*args, n=20, seed=3)
    b = draw_starts(*args, n=20, seed=3)
    c = draw_starts(*args, n=20, seed=4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(a[0], [0.7, 100.0, -0.4, 0.0])
    assert a.shape == (20, 4)
    # log-uniform decade around x0, sign-aware; uniform within finite bounds
    assert np.all((a[1:, 0] >= 0.07) & (a[1:, 0] <= 7.0))
    assert np.all((a[1:, 1] >= 10.0) & (a[1:, 1] <= 1000.0))
    assert np.all((a[1:, 2] <= -0.04) & (a[1:, 2] >= -4.0))
    assert np.all((a[1:, 3] >= -0.5) & (a[1:, 3] <= 0.5))


def test_distributions():
    s = draw_starts(["k", "w"], [2.0, 0.0], [0.0, -1.0], [INF, 3.0], n=2001, seed=1)
    # log10(k / 2) is uniform on [-1, 1]; w is uniform on [-1, 3]
    assert kstest((np.log10(s[1:, 0] / 2.0) + 1) / 2, "uniform").pvalue > 1e-3
    assert kstest((s[1:, 1] + 1) / 4, "uniform").pvalue > 1e-3
    # a bound inside the decade cuts it: log-uniform on [1, 20]
    s = draw_starts(["k"], [2.0], [1.0], None, n=2001, seed=2)
    assert s[1:].min() >= 1.0 and s[1:].max() <= 20.0
    assert kstest(np.log(s[1:, 0]) / np.log(20.0), "uniform").pvalue > 1e-3


def test_a_range_for_one_quantity_leaves_the_others_unchanged():
    base = draw_starts(["a", "b"], [1.0, 2.0], None, None, n=10, seed=9)
    ranged = draw_starts(["a", "b"], [1.0, 2.0], None, None, n=10, seed=9, ranges={"a": (-3.0, -2.0)})
    np.testing.assert_array_equal(base[:, 1], ranged[:, 1])
    assert np.all((ranged[1:, 0] >= -3.0) & (ranged[1:, 0] <= -2.0))


def test_draw_arguments_are_validated():
    with pytest.raises(ValueError, match="unknown quantities: z"):
        draw_starts(["a"], [1.0], None, None, n=3, seed=0, ranges={"z": (0, 1)})
    with pytest.raises(ValueError, match=r"leaves the bounds \[0, inf\]"):
        draw_starts(["a"], [1.0], [0.0], None, n=3, seed=0, ranges={"a": (-1, 1)})
    with pytest.raises(ValueError, match="`a` = -1 is below its min 0"):
        draw_starts(["a"], [-1.0], [0.0], None, n=3, seed=0)


def double_well(p):
    # E = 1/2 ((x^2 - 1)^2 + 0.09 (x - 1)^2): global minimum 0 at x = 1, a local one near x = -1.04
    x = p[0]
    return -np.array([x**2 - 1, 0.3 * (x - 1)]), np.array([[2 * x], [0.3]])


def local_minimum():
    # oracle: the root left of -1 of dE/dx = 2x^3 - 1.91x - 0.09 (times 2)
    roots = np.roots([4.0, 0.0, -4.0 + 0.18, -0.18])
    return min(r.real for r in roots if abs(r.imag) < 1e-12)


def fit_one(x0):
    return levenberg_marquardt(double_well, x0, ["x"], options=LMOptions(max_iter=200))


def test_double_well_finds_the_global_minimum_and_flags_the_local_one():
    starts = draw_starts(["x"], [-1.5], None, None, n=8, seed=12, ranges={"x": (-2.0, 2.0)})
    ms = run_multistart(fit_one, starts)
    assert len(ms.results) == 8
    np.testing.assert_allclose(ms.best.x, [1.0], atol=1e-8)
    assert 0 in ms.local_minima  # x0 = -1.5 runs into the local well
    x_local = local_minimum()
    for k in ms.local_minima:
        np.testing.assert_allclose(ms.results[k].x, [x_local], atol=1e-7)
    assert set(ms.near_best) | set(ms.local_minima) == set(range(8))
    assert "local minima" in ms.message and f"runs {ms.local_minima[0]}" in ms.message
    spread = ms.spread[0]
    assert spread.near_best_spread < 1e-8
    assert spread.others_min == pytest.approx(x_local, abs=1e-7)
    summary = ms.summary()
    assert summary["local_minima"] == list(ms.local_minima) and summary["best_index"] == ms.best_index


def test_order_is_deterministic_with_an_executor_and_callback_can_stop():
    starts = draw_starts(["x"], [-1.5], None, None, n=6, seed=12, ranges={"x": (-2.0, 2.0)})
    serial = run_multistart(fit_one, starts)
    with ThreadPoolExecutor(max_workers=2) as pool:
        parallel = run_multistart(fit_one, starts, executor=pool)
    np.testing.assert_array_equal(serial.costs, parallel.costs)
    assert serial.best_index == parallel.best_index and serial.local_minima == parallel.local_minima
    seen = []
    stopped = run_multistart(fit_one, starts, callback=lambda k, r: seen.append(k) or k == 2)
    assert seen == [0, 1, 2] and len(stopped.results) == 3 and stopped.interrupted


def test_diverged_runs_are_listed_apart():
    def fit(x0):
        return levenberg_marquardt(lambda p: None if p[0] < 0 else double_well(p), x0, ["x"])

    ms = run_multistart(fit, np.array([[-1.0], [0.5], [-0.2]]))
    assert ms.diverged == (0, 2) and ms.best_index == 1
    assert ms.local_minima == ()
    assert "diverged at the start: runs 0, 2" in ms.message

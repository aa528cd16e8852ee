"""Residual tests as `resid` does them: oracles are numpy's correlate and known correlated processes."""

from __future__ import annotations

import numpy as np
import pytest

from flowchart2sdnn.diagnose.residual import bound, signal_correlation, whiteness, xcorr


def test_xcorr_matches_numpy_correlate_with_the_biased_normalisation():
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal(500), rng.standard_normal(500)
    lags = np.arange(-7, 8)
    full = np.correlate(a - a.mean(), b - b.mean(), mode="full")  # full[k + N - 1] = sum_t a[t + k] b[t]
    oracle = full[lags + 499] / (500 * a.std() * b.std())
    np.testing.assert_allclose(xcorr(a, b, lags), oracle, rtol=1e-12, atol=1e-15)


def test_the_band_is_the_normal_quantile_over_sqrt_n():
    assert bound(10000) == pytest.approx(2.5758293 / 100, rel=1e-6)


def test_white_noise_stays_inside_the_99_percent_band_about_99_percent_of_the_time():
    outside = total = 0
    for seed in range(40):
        e = np.random.default_rng(seed).standard_normal((2000, 1))
        u = np.random.default_rng(1000 + seed).standard_normal((2000, 1))
        w = whiteness(e, u, ["y"], ["u"])
        outside += w["autocorrelation"]["y"]["outside"]
        total += 25
    assert 2 <= outside <= 30  # expected 10 of 1000 lags


def test_a_coloured_residual_is_not_white_and_the_input_lag_is_found():
    rng = np.random.default_rng(7)
    n = 5000
    u = rng.standard_normal(n)
    e = np.zeros(n)
    noise = rng.standard_normal(n)
    for t in range(1, n):
        e[t] = 0.6 * e[t - 1] + noise[t]
    e[3:] += 0.8 * u[:-3]  # the input leaks into the residual three samples later
    w = whiteness(e[:, None], u[:, None], ["y"], ["u"])
    assert not w["white"] and not w["independent"]
    cross = w["cross_correlation"]["y"]["u"]
    assert cross["lag_of_max"] == 3
    assert w["autocorrelation"]["y"]["outside"] >= 5


def test_signal_correlation_ranks_the_source_of_the_residual_first():
    rng = np.random.default_rng(3)
    n = 4000
    speed = np.cumsum(rng.standard_normal(n)) * 0.05
    other = rng.standard_normal(n)
    e = -0.3 * np.tanh(20 * speed) + 0.05 * rng.standard_normal(n)  # an unmodelled friction of `speed`
    rows = signal_correlation(e[:, None], {"other": other, "speed": speed, "flat": np.ones(n)}, ["y"])
    assert rows[0]["signal"] == "speed" and rows[0]["outside"] and rows[0]["r"] < 0
    assert "flat" not in {r["signal"] for r in rows}

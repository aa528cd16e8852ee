"""The score test's noise model (flowchart2sdnn/diagnose/noise.py): the variance of a score under the
residual's lag-window spectrum against a direct double sum over lags, and its tests against Monte Carlo:
under coloured noise and no effect their p-values are uniform or conservative (the white-noise chi-square's
are not); an effect present, or a clip on a few rows, is found."""

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.stats import chi2

from flowchart2sdnn.diagnose.noise import Layout, gain_test, noise_spectrum, score_test


def _ar1(rng, n, rho):
    return lfilter([1.0], [1.0, -rho], rng.standard_normal(n))


def _projected(X, e):
    return e - X @ np.linalg.lstsq(X, e, rcond=None)[0]


def test_the_covariance_is_the_double_sum_over_lags_of_the_windowed_covariances():
    rng = np.random.default_rng(3)
    layout = Layout((120, 80), 2)  # two records, two outputs interleaved row by row
    e = rng.standard_normal(layout.size)
    x = rng.standard_normal((layout.size, 2))
    window = 0.1
    got = noise_spectrum(e, layout, window).covariance(x)
    want = np.zeros((2, 2))
    for eb, xb in zip(layout.records(e), layout.records(x), strict=True):
        v = eb[:, :, 0] - eb[:, :, 0].mean(axis=0)
        n = v.shape[0]
        lags = int(round(window * n))
        for i in range(2):
            for j in range(2):
                for lag in range(-lags + 1, lags):
                    # gamma_ij(l) = (1/n) sum_t v_i,t v_j,t+l, Bartlett-weighted
                    a, b = (v[: n - lag, i], v[lag:, j]) if lag >= 0 else (v[-lag:, i], v[: n + lag, j])
                    gamma = (1 - abs(lag) / lags) * float(a @ b) / n
                    xa, xc = ((xb[: n - lag, i], xb[lag:, j]) if lag >= 0 else (xb[-lag:, i], xb[: n + lag, j]))
                    want += gamma * (xa.T @ xc)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def _draw(rng, n=30000, rho=0.97, effect=0.0):
    """A smooth regressor (a candidate's column) and coloured noise, as a fitted chart leaves them."""
    x = _ar1(rng, n, 0.995)
    x /= np.std(x)
    return x[:, None], effect * x + _ar1(rng, n, rho)


def test_no_effect_under_coloured_noise_is_rejected_at_its_level_and_the_white_test_is_not():
    rng = np.random.default_rng(7)
    layout = Layout((30000,), 1)
    p_noise, p_white = [], []
    for _ in range(200):
        X, e = _draw(rng)
        p_noise.append(score_test(layout, X, e, e)[2])
        g = float(X[:, 0] @ e)
        p_white.append(chi2.sf(g * g / float(X[:, 0] @ X[:, 0]) / np.var(_projected(X, e)), 1))
    p_noise, p_white = np.array(p_noise), np.array(p_white)
    # 200 draws of a 30 s record at 1 kHz: the rate at 5 % has a standard error of 1.5 %
    assert 0.01 <= np.mean(p_noise < 0.05) <= 0.10
    assert np.mean(p_white < 0.05) > 0.4


def test_an_effect_present_is_found_and_repeated_columns_count_once():
    rng = np.random.default_rng(8)
    X, e = _draw(rng, effect=1.0)  # the noise: standard deviation 4.3, memory 33 rows
    layout = Layout((30000,), 1)
    stat, k, p = score_test(layout, X, e, e)
    assert k == 1 and p < 1e-6
    assert score_test(layout, np.hstack([X, 2 * X]), e, e)[1] == 1


def test_the_gain_test_is_conservative_without_an_effect_and_finds_a_clip():
    """Two fits of one coloured record: the current (residual e) and a patched one that changes the prediction
    by δ on every row (a wrong option, fitted to what it can take) or on 100 rows only (a clip that is there)."""
    rng = np.random.default_rng(10)
    layout = Layout((30000,), 1)
    p = []
    for _ in range(200):
        e = _ar1(rng, 30000, 0.97)
        delta = _ar1(rng, 30000, 0.995)
        e_new = _projected(delta[:, None], e)
        p.append(gain_test(layout, 0.5 * (e @ e - e_new @ e_new), e_new, e - e_new)[1])
    assert np.mean(np.array(p) < 0.05) <= 0.10
    clip = np.zeros(30000)
    clip[1000:1100] = 30.0
    e = _ar1(rng, 30000, 0.97) + clip
    e_new = e - clip
    assert gain_test(layout, 0.5 * (e @ e - e_new @ e_new), e_new, clip)[1] < 1e-6


@pytest.mark.parametrize(("rows", "outputs"), [((100,), 1), ((100, 50), 2)])
def test_a_layout_gives_back_each_record_rows_by_outputs(rows, outputs):
    layout = Layout(rows, outputs)
    x = np.arange(layout.size, dtype=float)
    parts = list(layout.records(x))
    assert [p.shape for p in parts] == [(n, outputs, 1) for n in rows]
    assert np.array_equal(np.concatenate([p.ravel() for p in parts]), x)

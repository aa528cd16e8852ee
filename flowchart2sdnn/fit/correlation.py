"""Residual correlations as MATLAB's `resid` computes them: whiteness and independence from the inputs.

* whiteness: the normalised autocorrelation ``r_ee(tau)`` of each output's residual for lags 1..25;
* independence: the normalised cross-correlation ``r_eu(tau) = corr(e(t), u(t - tau))`` with each input for
  lags -25..25 (positive lags: the input leads);
* both against the 99 % band ``+-z / sqrt(N)`` (z = 2.576) that a white residual independent of the input
  stays inside (Ljung, System Identification, section 16.6).

Pure functions (arrays in, plain numbers out), used by diagnose's tests and by the residual-analysis figure of
``identify --plots``; they sit in fit/ because they know nothing of networks or charts.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.special import ndtri

from .. import rules

__all__ = ["MAX_LAG", "LEVEL", "xcorr", "bound", "whiteness"]

MAX_LAG = rules.value("whiteness_max_lag")
LEVEL = rules.value("whiteness_level")


def bound(n: int, level: float = LEVEL) -> float:
    """Half-width of the confidence band of a correlation estimate from n samples of white noise."""
    return float(ndtri(0.5 + level / 2) / np.sqrt(max(n, 1)))


def xcorr(a: np.ndarray, b: np.ndarray, lags: Sequence[int] | np.ndarray) -> np.ndarray:
    """Normalised cross-correlation ``r(tau) = sum_t a~(t) b~(t - tau) / (N std(a) std(b))``.

    Means are removed; the sum runs over the overlap and is divided by the full N (the biased estimate that
    `resid` and Ljung use). A constant signal gives zeros.
    """
    a = np.asarray(a, dtype=float) - np.mean(a)
    b = np.asarray(b, dtype=float) - np.mean(b)
    n = a.size
    if b.size != n:
        raise ValueError(f"signals differ in length: {n} and {b.size}")
    scale = n * np.std(a) * np.std(b)
    out = np.zeros(len(lags))
    if scale == 0 or not np.isfinite(scale):
        return out
    for i, tau in enumerate(lags):
        tau = int(tau)
        if abs(tau) >= n:
            continue
        out[i] = (a[tau:] @ b[: n - tau] if tau >= 0 else a[: n + tau] @ b[-tau:]) / scale
    return out


def _summary(r: np.ndarray, lags: np.ndarray, band: float) -> dict:
    outside = np.abs(r) > band
    k = int(np.argmax(np.abs(r))) if r.size else 0
    return {"lags": [int(x) for x in lags], "r": [round(float(x), 6) for x in r],
            "outside": int(np.sum(outside)), "max_abs": float(np.abs(r[k])) if r.size else 0.0,
            "lag_of_max": int(lags[k]) if r.size else 0}


def whiteness(residual: np.ndarray, inputs: np.ndarray, output_names: Sequence[str],
              input_names: Sequence[str], max_lag: int = MAX_LAG, level: float = LEVEL) -> dict:
    """The `resid` tests of a residual.

    Parameters
    ----------
    residual : (N, n_outputs) ndarray
        Measured minus simulated output.
    inputs : (N, n_inputs) ndarray
        The inputs on the same rows (with the zoh alignment: the input sample acting before each output row).
    output_names, input_names : sequences of str
    max_lag : int
    level : float
        Confidence level of the band.

    Returns
    -------
    dict
        ``{"bound", "level", "n", "autocorrelation": {output: summary}, "cross_correlation":
        {output: {input: summary}}, "white": bool, "independent": bool}``; a summary holds the lags, r, how
        many lags fall outside the band, the largest |r| and its lag. ``white`` (``independent``) is True when
        no more than 1 % of the lags (rounded down: for 25 or 51 lags, none) of any output fall outside.
    """
    e = np.atleast_2d(np.asarray(residual, dtype=float).T).T
    u = np.atleast_2d(np.asarray(inputs, dtype=float).T).T
    n = e.shape[0]
    band = bound(n, level)
    auto_lags = np.arange(1, max_lag + 1)
    cross_lags = np.arange(-max_lag, max_lag + 1)
    auto, cross = {}, {}
    for j, name in enumerate(output_names):
        auto[name] = _summary(xcorr(e[:, j], e[:, j], auto_lags), auto_lags, band)
        cross[name] = {iname: _summary(xcorr(e[:, j], u[:, i], cross_lags), cross_lags, band)
                       for i, iname in enumerate(input_names)}
    allowed_auto = int(0.01 * max_lag)
    allowed_cross = int(0.01 * (2 * max_lag + 1))
    white = all(s["outside"] <= allowed_auto for s in auto.values())
    independent = all(s["outside"] <= allowed_cross for d in cross.values() for s in d.values())
    return {"bound": band, "level": level, "n": int(n), "max_lag": int(max_lag), "autocorrelation": auto,
            "cross_correlation": cross, "white": bool(white), "independent": bool(independent)}

"""Residual analysis as MATLAB's `resid` does it, plus correlation with the chart's internal signals.

* whiteness: the normalised autocorrelation ``r_ee(tau)`` of each output's residual for lags 1..25;
* independence: the normalised cross-correlation ``r_eu(tau) = corr(e(t), u(t - tau))`` with each input for
  lags -25..25 (positive lags: the input leads);
* both against the 99 % band ``+-z / sqrt(N)`` (z = 2.576) that a white residual independent of the input
  stays inside (Ljung, System Identification, section 16.6);
* the internal signals of the chart (every neuron of the compiled network) ranked by their largest
  |correlation| with the residual over lags 0..25 (signal leading): where the residual comes from.

All functions are pure: arrays in, dictionaries of plain numbers out (JSON-ready).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.stats import norm

__all__ = ["MAX_LAG", "LEVEL", "xcorr", "bound", "whiteness", "signal_correlation"]

MAX_LAG = 25
LEVEL = 0.99


def bound(n: int, level: float = LEVEL) -> float:
    """Half-width of the confidence band of a correlation estimate from n samples of white noise."""
    return float(norm.ppf(0.5 + level / 2) / np.sqrt(max(n, 1)))


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


def signal_correlation(residual: np.ndarray, signals: Mapping[str, np.ndarray], output_names: Sequence[str],
                       max_lag: int = MAX_LAG, top: int = 8, level: float = LEVEL) -> list[dict]:
    """Internal signals ranked by their largest |correlation| with a residual, lags 0..max_lag.

    Returns a list of ``{"signal", "output", "lag", "r", "outside"}`` (best first, at most `top`), where
    ``outside`` says whether |r| exceeds the band of :func:`bound`. A constant signal is skipped.
    """
    e = np.atleast_2d(np.asarray(residual, dtype=float).T).T
    band = bound(e.shape[0], level)
    lags = np.arange(0, max_lag + 1)
    rows = []
    for name, s in signals.items():
        s = np.asarray(s, dtype=float)
        if s.shape[0] != e.shape[0] or not np.all(np.isfinite(s)) or np.std(s) == 0:
            continue
        for j, out in enumerate(output_names):
            r = xcorr(e[:, j], s, lags)
            k = int(np.argmax(np.abs(r)))
            rows.append({"signal": name, "output": out, "lag": int(lags[k]), "r": round(float(r[k]), 6),
                         "outside": bool(abs(r[k]) > band)})
    rows.sort(key=lambda d: -abs(d["r"]))
    return rows[:top]

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

# the resid tests live in fit/ (the identify figures draw them too); diagnose keeps its names
from ..fit.correlation import LEVEL, MAX_LAG, bound, whiteness, xcorr  # noqa: F401

__all__ = ["MAX_LAG", "LEVEL", "xcorr", "bound", "whiteness", "signal_correlation"]


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

"""The frequency response measured in data: Welch's H1 estimate of one input -> output pair.

H1(f) = S_uy(f) / S_uu(f) from averaged, Hann-windowed segments (scipy.signal), with the magnitude-squared
coherence |S_uy|^2 / (S_uu S_yy) beside it: where the coherence is well below 1 the estimate is noise, leakage
or nonlinearity (a friction that the linear model leaves out), or the input was fed back from the output (the
relay of the virtual bench), which biases H1. The data's zero-order hold adds half a sample of delay (phase
T omega / 2), which the continuous model does not show. Drawn over the linearised chart by
:mod:`flowchart2sdnn.report.bode`.

Layer: analysis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Empirical", "empirical_response", "lags_for", "MIN_LAGS", "MAX_LAGS"]


@dataclass(frozen=True, eq=False)
class Empirical:
    """An H1 estimate of one input -> output pair: frequencies (Hz), H1 (complex), coherence, segment length."""

    input: str
    output: str
    f: np.ndarray
    h: np.ndarray
    coherence: np.ndarray
    nperseg: int


def empirical_response(u: np.ndarray, y: np.ndarray, sample_time: float, input_name: str = "u",
                       output_name: str = "y", nperseg: int | None = None) -> Empirical:
    """Welch's H1 estimate from input samples `u` and output samples `y` (same rows, time step `sample_time`).

    `nperseg` defaults to the largest power of two giving at least 8 segments (at most 8192 samples).
    """
    from scipy.signal import coherence, csd, welch

    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if nperseg is None:
        nperseg = int(2 ** max(4, min(13, math.floor(math.log2(max(len(u) // 8, 16))))))
    fs = 1.0 / sample_time
    f, puu = welch(u, fs=fs, nperseg=nperseg)
    _, puy = csd(u, y, fs=fs, nperseg=nperseg)
    _, coh = coherence(u, y, fs=fs, nperseg=nperseg)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = puy / puu
    keep = f > 0
    return Empirical(input_name, output_name, f[keep], h[keep], coh[keep], nperseg)


#: the fewest and the most residual-correlation lags a page shows (25: MATLAB's `resid`; 1000 keeps the
#: figure readable and the correlation cheap)
MIN_LAGS, MAX_LAGS = 25, 1000


def lags_for(modes: list[dict], sample_time: float, n: int) -> tuple[int, str]:
    """(lags, why) of a residual's correlation test: enough to span the slowest dynamics of the model.

    `modes` as :meth:`~flowchart2sdnn.analysis.linearize.LinearModel.damp` gives them. A correlation left by
    a missing effect lasts about as long as the dynamics that carry it: the slowest oscillating mode's period
    (a shaft's twist), else the slowest stable time constant. At least 25 lags, at most 1000 and a fifth of
    the `n` samples (a longer lag rests on too few products).
    """
    periods = [1.0 / d["damped_hz"] for d in modes if d.get("damped_hz", 0) > 0]
    taus = [-1.0 / d["pole"].real for d in modes if d["pole"].real < 0 and not d.get("damped_hz", 0) > 0]
    if periods:
        span, why = max(periods), f"the slowest mode's period, {max(periods):.3g} s"
    elif taus:
        span, why = max(taus), f"the slowest time constant, {max(taus):.3g} s"
    else:
        return MIN_LAGS, "no stable mode to size them by"
    cap = max(MIN_LAGS, min(MAX_LAGS, n // 5))
    lags = int(min(cap, max(MIN_LAGS, math.ceil(span / sample_time - 1e-9))))  # 0.103 / 0.001 is 103
    return lags, why

"""How many independent samples a residual holds: its length over its integrated autocorrelation time.

A residual that is mostly what the model lacks (a missing friction, a coloured sensor noise) is correlated over
many samples; counting each sample as one observation overstates what a fall of the cost means by that factor.
The integrated autocorrelation time tau = 1 + 2 sum_k rho_k is read off the residual itself with Geyer's initial
positive sequence (sums of consecutive autocorrelation pairs, stopped at the first that is not positive; Geyer,
*Practical Markov Chain Monte Carlo*, Statistical Science 7(4), 1992), which needs no window to tune.

Layer: fit (numpy only).
"""

from __future__ import annotations

import numpy as np

__all__ = ["autocorrelation_time", "effective_samples"]


def _acf(x: np.ndarray) -> np.ndarray:
    n = x.size
    x = x - x.mean()
    size = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(x, size)
    acov = np.fft.irfft(f * np.conj(f), size)[:n]
    return acov / acov[0] if acov[0] > 0 else np.zeros(n)


def autocorrelation_time(x: np.ndarray) -> float:
    """tau of one series (1 for white noise, larger for a correlated one), by Geyer's initial positive sequence."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 4 or not np.ptp(x) > 0:
        return 1.0
    rho = _acf(x)
    pairs = rho[0:-1:2] + rho[1::2]  # Gamma_m = rho_2m + rho_2m+1, positive for a reversible process
    stop = np.flatnonzero(pairs <= 0)
    m = int(stop[0]) if stop.size else pairs.size
    tau = -1.0 + 2.0 * float(np.sum(pairs[:m]))
    return float(min(max(tau, 1.0), x.size))


def effective_samples(e: np.ndarray, stride: int = 1) -> float:
    """The independent samples in residual `e`, laid out as consecutive rows of `stride` outputs: the sum over
    outputs of rows / tau, each output weighted by its share of the squared residual."""
    e = np.asarray(e, dtype=float)
    stride = max(1, int(stride))
    if e.size % stride:
        stride = 1
    cols = e.reshape(-1, stride)
    rows = cols.shape[0]
    power = np.sum(cols**2, axis=0)
    total = float(power.sum())
    if not total > 0:
        return float(e.size)
    taus = np.array([autocorrelation_time(cols[:, j]) for j in range(stride)])
    return float(stride * rows / np.sum(power / total * taus))

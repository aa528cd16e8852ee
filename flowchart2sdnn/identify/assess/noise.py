"""The records' measurement noise, read off their high-frequency content: the one noise floor that multiple
shooting's merge rule, ``--shooting auto``'s second look, the crawl rule and diagnose compare costs with.

Layer: identify (below it: nothing but numpy and the rule book).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ... import rules

if TYPE_CHECKING:
    from ..offline.problem import Problem

__all__ = ["NOISE_MARGIN", "NOISE_ORDERS", "NOISE_BANDS", "noise_variance", "noise_level", "noise_cost"]

#: A multiple-shooting stage is at the noise floor when its residual RMS is at most this many times the noise
#: estimate (:mod:`flowchart2sdnn.identify.shooting.multiple`); auto's second look and diagnose read it too.
NOISE_MARGIN = rules.value("noise_margin")
#: higher difference orders the noise is read from besides the second (see noise_variance)
NOISE_ORDERS = rules.value("noise_orders")
#: frequency bands of the spectral reading (see noise_variance)
NOISE_BANDS = rules.value("noise_bands")


def noise_variance(y: np.ndarray) -> np.ndarray:
    """Each column's white-noise variance, (Q, n) -> (n,) (0 when Q is too short to tell).

    The second difference of white noise of variance sigma^2 has variance 6 sigma^2; its median absolute
    deviation (times 1.4826, robust against the few large differences of a torque step) is the reading for a
    record sampled fast against its changes. A smooth record sampled a few times per period keeps its
    curvature there: with 10 samples per resonance period a signal of RMS 0.66 read as 0.15 of 'noise' where
    the truth was 0.00066 (tests/test_noise_estimate.py). Two other readings, each of which can only overstate
    the noise, are taken then:

    * higher differences (NOISE_ORDERS): the n-th has C(2n, n) sigma^2 of noise, while a signal at w rad per
      sample keeps |2 sin(w/2)|^n of itself, which falls with n below six samples per period;
    * the spectrum's floor: the median of the Hann-windowed periodogram over each of NOISE_BANDS equal
      frequency bands is ln 2 sigma^2 where the band holds only noise (lines of a multisine or harmonics fill
      few bins and leave the median); the lowest band is the reading.

    The smallest of them replaces the second difference's when it is under a quarter of it (half the RMS):
    on a record whose second difference is noise all readings agree within their scatter and nothing changes.
    """
    y = np.asarray(y, dtype=float)
    base = _difference_variance(y, 2)
    other = np.full(y.shape[1], np.inf)
    for n in NOISE_ORDERS:
        if len(y) >= 8 * n:
            other = np.minimum(other, _positive(_difference_variance(y, n)))
    if len(y) >= 32 * NOISE_BANDS:
        other = np.minimum(other, _positive(_spectral_floor(y)))
    return np.where(other < 0.25 * base, other, base)


def _positive(v: np.ndarray) -> np.ndarray:
    return np.where(v > 0, v, np.inf)


def _difference_variance(y: np.ndarray, n: int) -> np.ndarray:
    d = np.diff(y, n=n, axis=0)
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return (1.4826 * mad) ** 2 / math.comb(2 * n, n)


def _spectral_floor(y: np.ndarray) -> np.ndarray:
    """sigma^2 of white noise from the quietest band of the periodogram (E|X_f|^2 = sigma^2 sum w^2 for
    white noise under the window w; a bin is sigma^2 times an Exp(1) variable, of median ln 2)."""
    q = len(y)
    k = np.arange(q)
    trend = np.polynomial.polynomial.polyfit(k, y, 1)
    r = y - (trend[0] + np.outer(k, trend[1]))
    w = np.hanning(q)
    p = np.abs(np.fft.rfft(r * w[:, None], axis=0)) ** 2 / np.sum(w ** 2)
    p = p[2:-1]  # DC and its neighbour carry the window's leakage of the mean; the Nyquist bin is real-valued
    bands = np.array_split(p, NOISE_BANDS, axis=0)
    return np.min([np.median(b, axis=0) for b in bands], axis=0) / math.log(2)


def noise_level(problem: Problem) -> float:
    """The measurement noise's variance, averaged over the outputs and weighted by the records' lengths, read
    off the records' differences (:func:`noise_variance`). Returns sigma^2 (0 when nothing is known)."""
    out, count = 0.0, 0
    for s in problem.segments:
        if len(s.targets) < 8:
            continue
        sigma2 = noise_variance(s.targets)
        out += float(np.sum(sigma2)) * len(s.targets)
        count += s.targets.shape[1] * len(s.targets)
    return out / count if count else 0.0


def noise_cost(problem: Problem, ratio: float) -> float:
    """The cost per sample (E over the records' targets, E = SSE / 2) of a residual at `ratio` x the noise RMS
    (:func:`noise_level`): the one noise floor that multiple shooting, auto's second look, the crawl rule and
    diagnose compare costs with."""
    return 0.5 * ratio ** 2 * noise_level(problem)

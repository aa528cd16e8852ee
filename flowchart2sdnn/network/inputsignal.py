"""What an input is between its samples, and what each network step sees of it.

An input sample stands for a continuous signal: under ``hold`` sample k acts on [t_k, t_k+1) (a drive holds
its torque command, the default); under ``linear`` the signal runs straight from sample k to sample k+1 (a
smooth measured voltage: MATLAB's iddata InterSample 'foh'). A dead time tau (seconds, possibly a fraction of a
sample and a fitted parameter) shifts that signal: the network sees u(t - tau).

Each network step of length h = T / N is fed the signal's *mean* over the step. That is what the speed
integrators need (the step adds h/J times the torque's integral over it), it is the held value itself under
``hold`` without a delay (so held charts run as before), the midpoint value under ``linear``, and it is
continuous and piecewise smooth in tau, with the exact derivative

    d/dtau mean_[a, b] u(t - tau) dt = -(u(b - tau) - u(a - tau)) / h

(a held signal's step means have a kink where a step boundary crosses a sample, e.g. at whole-sample delays:
there the mean of the two one-sided derivatives).

Before the first sample the signal is the first sample; after the last, under ``hold``, the last sample, under
``linear`` the line through the last two samples for one more sample, then constant (with the zoh alignment
the network's last sample interval ends at the record's last row, which the alignment has cut off).

Layer: network (numpy only).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["INTERSAMPLE", "step_inputs"]

INTERSAMPLE = ("hold", "linear")


def step_inputs(u: np.ndarray, substeps: int, linear: np.ndarray, shift: np.ndarray,
                with_derivative: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Every network step's input and, with `with_derivative`, its derivative with respect to each input's
    shift in samples (tau / T).

    Parameters
    ----------
    u : (Q, n) float
        Input samples (the network's, after alignment).
    substeps : int
        N network steps per sample.
    linear : (n,) bool
        Input i is ``linear`` (else ``hold``).
    shift : (n,) float
        Each input's dead time in samples (0: none).

    Returns
    -------
    p : (Q * N, n) float
        Step j of sample q gets the mean of u over [q + j / N, q + (j + 1) / N] - shift (in samples).
    dp : (Q * N, n) float or None
        d p / d shift.
    """
    q, n = u.shape
    start = np.arange(q * substeps) / substeps
    p = np.empty((q * substeps, n))
    dp = np.empty((q * substeps, n)) if with_derivative else None
    for i in range(n):
        knots, pad = _knots(u[:, i], bool(linear[i]), float(shift[i]))
        a = start - shift[i] + pad
        b = a + 1.0 / substeps
        p[:, i] = _mean(knots, a, b, bool(linear[i]))
        if dp is not None:
            dp[:, i] = -(_value(knots, b, bool(linear[i])) - _value(knots, a, bool(linear[i]))) * substeps
    return p, dp


def _knots(x: np.ndarray, linear: bool, shift: float) -> tuple[np.ndarray, int]:
    """The samples padded on both sides far enough for `shift` (first sample before, the held or extrapolated
    end after), and the number of pads in front."""
    pad = int(math.ceil(abs(shift))) + 2
    end = 2 * x[-1] - x[-2] if linear and len(x) > 1 else x[-1]
    return np.concatenate([np.full(pad, x[0]), x, [end] * (pad + 1)]), pad


#: a position this close to a whole sample is on a held signal's jump
ON_JUMP = 1e-9


def _value(knots: np.ndarray, s: np.ndarray, linear: bool) -> np.ndarray:
    """The signal at positions s (in samples from the first knot); on a held signal's jump the mean of its two
    sides, so that the derivative in tau there is the mean of its one-sided values (what central differences
    see) rather than whichever side rounding picks."""
    j = np.clip(np.floor(s).astype(np.int64), 0, len(knots) - 2)
    if not linear:
        whole = np.rint(s)
        jump = (np.abs(s - whole) < ON_JUMP) & (whole >= 1) & (whole <= len(knots) - 2)
        k = whole.astype(np.int64)
        return np.where(jump, 0.5 * (knots[np.clip(k - 1, 0, len(knots) - 1)] + knots[np.clip(k, 0, len(knots) - 1)]),
                        knots[j])
    r = s - j
    return knots[j] + r * (knots[j + 1] - knots[j])


def _mean(knots: np.ndarray, a: np.ndarray, b: np.ndarray, linear: bool) -> np.ndarray:
    """The signal's mean over [a, b] (b - a <= 1: at most two segments)."""
    j = np.clip(np.floor(a).astype(np.int64), 0, len(knots) - 3)
    r0 = a - j
    r1 = np.minimum(b - j, 1.0)
    total = _integral(knots, j, r0, r1, linear)
    over = b - (j + 1)
    spill = over > 0
    if np.any(spill):
        total[spill] += _integral(knots, j[spill] + 1, np.zeros(int(spill.sum())), over[spill], linear)
    return total / (b - a)


def _integral(knots: np.ndarray, j: np.ndarray, r0: np.ndarray, r1: np.ndarray, linear: bool) -> np.ndarray:
    """The integral over segment j from r0 to r1 (fractions of the segment)."""
    if not linear:
        return (r1 - r0) * knots[j]
    return (r1 - r0) * knots[j] + 0.5 * (r1 * r1 - r0 * r0) * (knots[j + 1] - knots[j])

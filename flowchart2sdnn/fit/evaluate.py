"""The model's callbacks, called the way the LM loop (:mod:`.lm`) needs them: a diverged simulation (None,
non-finite values, FloatingPointError or OverflowError) is a refused trial, never a NaN in the result; each
call is counted (:class:`Counters`); shapes are checked once, with messages naming the argument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

__all__ = ["Point", "Counters", "cost_of", "checked_residual", "call_fun", "call_residual", "readonly",
           "try_point"]


# ---------------------------------------------------------------------------------------------- helpers
@dataclass(frozen=True)
class Point:
    u: np.ndarray
    x: np.ndarray
    e: np.ndarray
    J: np.ndarray
    cost: float


@dataclass
class Counters:
    nfev: int = 0
    njev: int = 0
    rejected_cost: int = 0
    rejected_diverged: int = 0
    rejected_guard: int = 0
    last_guard_reason: str | None = None
    m: int | None = field(default=None)


def cost_of(e: np.ndarray) -> float:
    with np.errstate(over="ignore", invalid="ignore"):
        return 0.5 * float(e @ e)


def checked_residual(e, counters: Counters) -> np.ndarray | None:
    if e is None:
        return None
    e = np.array(e, dtype=float)
    if e.ndim != 1 or e.size == 0:
        raise ValueError(f"the residual must have shape (M,) with M >= 1, got shape {e.shape}")
    if counters.m is None:
        counters.m = e.size
    elif e.size != counters.m:
        raise ValueError(f"the residual changed length from {counters.m} to {e.size} between calls")
    return e if np.all(np.isfinite(e)) else None


def call_fun(fun, x, n_params, counters) -> tuple[np.ndarray, np.ndarray] | None:
    """fun(x) -> (e, J) validated; None when the simulation diverged."""
    counters.nfev += 1
    counters.njev += 1
    try:
        out = fun(x.copy())
    except (FloatingPointError, OverflowError):  # the model blew up at this x
        return None
    if out is None:
        return None
    e, J = out
    e = checked_residual(e, counters)
    if e is None or J is None:
        return None
    if sparse.issparse(J):  # a CSR float matrix as it is: a WideFirstCSR keeps its blocks
        J = J if sparse.isspmatrix_csr(J) and J.dtype == np.float64 else sparse.csr_matrix(J, dtype=float)
    else:
        J = np.array(J, dtype=float)
    if J.shape != (e.size, n_params):
        raise ValueError(f"the Jacobian must have shape (M, P) = ({e.size}, {n_params}), got {J.shape}")
    if not np.all(np.isfinite(J.data if sparse.issparse(J) else J)) or not math.isfinite(cost_of(e)):
        return None
    return e, J


def call_residual(residual, x, counters) -> np.ndarray | None:
    counters.nfev += 1
    try:
        e = checked_residual(residual(x.copy()), counters)
    except (FloatingPointError, OverflowError):
        return None
    if e is None or not math.isfinite(cost_of(e)):
        return None
    return e


def readonly(a):
    if sparse.issparse(a):  # scipy's sparse matrices have no write flag; the trainer keeps no reference
        return a
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def try_point(fun, residual, guard, u_t, x_t, cost, counters: Counters) -> Point | None:
    """Evaluate one trial; the accepted point, or None (rejected, counted by reason)."""
    if not np.all(np.isfinite(x_t)):  # a wild step (huge u) on an unbounded quantity
        counters.rejected_diverged += 1
        return None
    if guard is not None:
        reason = guard(x_t.copy())
        if reason:
            counters.rejected_guard += 1
            counters.last_guard_reason = str(reason)
            return None
    if residual is not None:
        e_t = call_residual(residual, x_t, counters)
        if e_t is None:
            counters.rejected_diverged += 1
            return None
        if not cost_of(e_t) < cost:
            counters.rejected_cost += 1
            return None
    out = call_fun(fun, x_t, u_t.size, counters)
    if out is None:
        counters.rejected_diverged += 1
        return None
    cost_t = cost_of(out[0])
    if not cost_t < cost:
        counters.rejected_cost += 1
        return None
    return Point(u_t, x_t, out[0], out[1], cost_t)

"""The Gauss-Newton numerics of the score test (:mod:`.score`): the decrease one least-squares step achieves on a
column-normalised Jacobian, its rank and the step itself, with quantities held on their bounds by an active set;
and what the current chart's own step leaves of a residual.

(J^T J)^+ is applied through the eigen-decomposition of the Gram matrix of the column-normalised J, with
eigenvalues below ``RCOND`` times the largest dropped (the "tiny" regularisation: directions the data do not
determine are not stepped along).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh

from .. import rules

__all__ = ["RCOND", "column_norms", "gram", "decrease", "solve", "gauss_newton_decrease", "current_basis", "after_current_step"]

RCOND = rules.value("rcond")


def column_norms(J: np.ndarray) -> np.ndarray:
    """The columns' norms, 1 for a zero column (which then stays zero when divided)."""
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    return norms


def gram(J: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gram matrix and gradient of the column-normalised Jacobian (zero columns stay zero)."""
    Js = J / column_norms(J)
    return Js.T @ Js, Js.T @ e


def decrease(G: np.ndarray, g: np.ndarray, rcond: float = RCOND, sign: np.ndarray | None = None):
    """1/2 g^T G^+ g and the rank; `sign[i]` = +1 (-1) keeps quantity i from stepping down (up): on a bound.

    Bounds by an active set: a quantity whose unconstrained step leaves its bound is held there (its column
    dropped) and the step recomputed, the worst offender first.
    """
    dec, rank, _ = solve(G, g, rcond, sign)
    return dec, rank


def solve(G: np.ndarray, g: np.ndarray, rcond: float = RCOND, sign: np.ndarray | None = None):
    """:func:`decrease` and the step itself, G^+ g in the Gram matrix's (column-normalised) units, 0 where held."""
    active = np.ones(G.shape[0], dtype=bool)
    full = np.zeros(G.shape[0])
    while True:
        idx = np.flatnonzero(active)
        if idx.size == 0:
            return 0.0, 0, full
        Gs, gs = G[np.ix_(idx, idx)], g[idx]
        w, V = eigh(Gs, check_finite=False)
        if not w.size or w[-1] <= 0:
            return 0.0, 0, full
        keep = w > rcond * w[-1]
        c = V[:, keep].T @ gs
        step = V[:, keep] @ (c / w[keep])
        if sign is not None and np.any(sign[idx] != 0):
            wrong = step * sign[idx]
            if np.any(wrong < 0):
                active[idx[int(np.argmin(wrong))]] = False
                continue
        full[idx] = step
        return 0.5 * float(np.sum(c * c / w[keep])), int(np.sum(keep)), full


def gauss_newton_decrease(J: np.ndarray, e: np.ndarray, rcond: float = RCOND,
                          sign: np.ndarray | None = None) -> tuple[float, int]:
    """Decrease of 1/2 ||e - J d||^2 achieved by the least-squares step d, and the numerical rank used.

    Parameters
    ----------
    J : (M, P) ndarray
    e : (M,) ndarray
    rcond : float
        Eigenvalues of the Gram matrix of the column-normalised J below ``rcond`` times the largest count as
        zero (singular values below ``sqrt(rcond)``).
    sign : (P,) ndarray, optional
        +1 for a quantity on its lower bound (it may only increase), -1 on its upper bound, 0 free.

    Returns
    -------
    (decrease, rank) : ``1/2 g^T (J^T J)^+ g`` with ``g = J^T e``, and the rank used.
    """
    if J.ndim != 2 or J.shape[0] != e.shape[0]:
        raise ValueError(f"J has shape {J.shape}, e has shape {e.shape}")
    return decrease(*gram(J, e), rcond, None if sign is None else np.asarray(sign, dtype=float))


def current_basis(J0: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the current chart's columns (directions below RCOND dropped, as in the score)."""
    Js = J0 / column_norms(J0)
    w, V = eigh(Js.T @ Js, check_finite=False)
    if not w.size or not w[-1] > 0:
        return np.zeros((J0.shape[0], 0))
    keep = w > RCOND * w[-1]
    return Js @ (V[:, keep] / np.sqrt(w[keep]))


def after_current_step(e: np.ndarray, basis: np.ndarray) -> float:
    """1/2 ||e - P e||^2, P the projector on the current chart's columns (`basis`, :func:`current_basis`): the
    cost a patched chart would reach by moving the current quantities along their current sensitivities (the
    cost of :func:`~.noise.step_residual`, the basis computed once for many residuals)."""
    r = e - basis @ (basis.T @ e)
    return 0.5 * float(r @ r)

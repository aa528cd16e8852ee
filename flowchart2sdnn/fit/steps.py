"""The step computations of Levenberg-Marquardt, apart from its loop (:mod:`.lm`): the normal equations
J_uᵀJ_u and J_uᵀe from the model Jacobian (dense or CSR), Moré's column scale D, the damped step
(JᵀJ + mu I) du = Jᵀe by Cholesky (least squares where it fails), the damping that fits a trust radius and the
radius's update, the step with some components held (box bounds, :mod:`.boxstep`), the model's predicted
decrease, and geodesic acceleration. Pure functions of arrays: no callbacks but the residual a geodesic step
evaluates, no options object, no stopping rule (those are :mod:`.stopping`).

``point`` arguments are the loop's points (``u`` internal coordinates, ``e`` residual, ``J`` Jacobian).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import sparse
from scipy.linalg import LinAlgError, cho_factor, cho_solve, lstsq, solve_triangular

from .. import rules
from .transforms import Bounds

__all__ = ["WideFirstCSR", "ScaledColumns", "gram", "times_columns", "over_columns", "column_sq_sums",
           "column_norms", "as_dense", "damped_step", "normal_equations", "column_scale", "scaled_system", "trust_accepted",
           "mu_for_radius", "held_step", "predicted_decrease", "geodesic_step", "WIDE_COLUMN", "RADIUS_TOLERANCE",
           "GEODESIC_H", "TRUST_POOR", "TRUST_GOOD", "TRUST_SHRINK", "TRUST_GROW"]


def times_columns(J, s: np.ndarray):
    """J with column j multiplied by s[j] (dense or CSR, as J)."""
    return J @ sparse.diags(s) if sparse.issparse(J) else J * s


def over_columns(J, s: np.ndarray):
    """J with column j divided by s[j] (dense or CSR, as J)."""
    return J @ sparse.diags(1.0 / s) if sparse.issparse(J) else J / s


#: A CSR Jacobian's columns with nonzeros in at least this fraction of the rows enter JᵀJ by dense products.
WIDE_COLUMN = rules.value("wide_column")


class WideFirstCSR(sparse.csr_matrix):
    """A CSR Jacobian whose caller also hands over its first ``wide.shape[1]`` columns as the dense array ``wide``
    and the others as the CSR matrix ``rest`` (the values of J[:, :k].toarray() and J[:, k:]; None: not given):
    JᵀJ then needs no column slicing of J nor a count of every column's nonzeros (5 of gram's 7 ms at 250
    segments, bench_shooting_iteration). A multiple-shooting Jacobian (identify.shooting.multiple) writes them from its
    kernels' results; anything scipy derives from it is a plain CSR matrix (or one without them)."""

    wide: np.ndarray | None = None
    rest: sparse.csr_matrix | None = None


def gram(J) -> np.ndarray:
    """JᵀJ, dense. A CSR J whose columns are partly wide (nonzero in most rows: the parameters of a
    multiple-shooting Jacobian, beside one short column block per segment's free start) is split: the wide
    columns' products by BLAS on their dense copy, the rest sparse; the sparse product of the whole matrix cost
    8.3 ms, the split 4.8 ms at 250 segments (bench_shooting_iteration, L = 100: a tenth of an iteration). A
    WideFirstCSR hands both parts over: 2.0 ms, where scipy's column slicing and the count of each column's
    nonzeros took 7.0 (the same products, the same bits)."""
    if not sparse.issparse(J):
        return J.T @ J
    n = J.shape[1]
    if isinstance(J, WideFirstCSR) and J.wide is not None and J.rest is not None:
        k = J.wide.shape[1]
        if 0 < k < n and J.wide.shape[0] == J.shape[0] and J.rest.shape == (J.shape[0], n - k):
            return _gram_blocks(J.wide, J.rest, slice(0, k), slice(k, n))
    wide = np.bincount(J.indices, minlength=n) >= WIDE_COLUMN * J.shape[0]
    if not wide.any() or wide.all():
        return (J.T @ J).toarray()
    d, s = _as_slice(np.flatnonzero(wide)), _as_slice(np.flatnonzero(~wide))
    return _gram_blocks(J[:, d].toarray(), J[:, s], d, s)


def _gram_blocks(Jd: np.ndarray, Js, d, s) -> np.ndarray:
    """JᵀJ of the J whose columns `d` are the dense Jd and columns `s` the CSR Js (slices or index arrays)."""
    n = Jd.shape[1] + Js.shape[1]
    A = np.empty((n, n))
    cross = np.asarray(Js.T @ Jd)
    if isinstance(d, slice) and isinstance(s, slice):
        A[d, d], A[s, d], A[d, s], A[s, s] = Jd.T @ Jd, cross, cross.T, (Js.T @ Js).toarray()
        return A
    d, s = np.arange(n)[d], np.arange(n)[s]
    A[np.ix_(d, d)], A[np.ix_(s, d)], A[np.ix_(d, s)] = Jd.T @ Jd, cross, cross.T
    A[np.ix_(s, s)] = (Js.T @ Js).toarray()
    return A


def _as_slice(index: np.ndarray):
    """A slice for ascending consecutive indices (column slices of a CSR matrix are cheaper than a list), else the
    indices."""
    return slice(int(index[0]), int(index[-1]) + 1) if index[-1] - index[0] + 1 == index.size else index


def column_sq_sums(J) -> np.ndarray:
    if sparse.issparse(J):
        return np.asarray(J.multiply(J).sum(axis=0)).ravel()
    return np.einsum("ij,ij->j", J, J)


def _column_peaks(J) -> np.ndarray:
    if sparse.issparse(J):
        return abs(J).max(axis=0).toarray().ravel() if J.shape[0] else np.zeros(J.shape[1])
    return np.max(np.abs(J), axis=0, initial=0.0)


def column_norms(J) -> np.ndarray:
    """Euclidean column norms, computed on columns divided by their peaks (no overflow of the squares)."""
    peak = _column_peaks(J)
    safe = np.where(peak > 0, peak, 1.0)
    if sparse.issparse(J):
        return np.sqrt(column_sq_sums(over_columns(J, safe))) * peak
    return np.linalg.norm(J / safe, axis=0) * peak


class ScaledColumns:
    """J·diag(s) as products only: the trainer's per-step work is matrix-vector, and forming J·diag(s) (and its
    column-scaled copy) cost a pass over the M×P matrix each, more than the products (dense or CSR J)."""

    def __init__(self, J, s: np.ndarray):
        self.J, self.s = J, s

    def __matmul__(self, v: np.ndarray) -> np.ndarray:
        return self.J @ (self.s * v)

    @property
    def T(self) -> _Transposed:
        return _Transposed(self)

    def dense(self) -> np.ndarray:
        M = times_columns(self.J, self.s)
        return M.toarray() if sparse.issparse(M) else M


class _Transposed:
    def __init__(self, op: ScaledColumns):
        self.op = op

    def __matmul__(self, w: np.ndarray) -> np.ndarray:
        return self.op.s * np.asarray(self.op.J.T @ w).ravel()


def as_dense(Ju) -> np.ndarray:
    if isinstance(Ju, (ScaledColumns, _Subset)):
        return Ju.dense()
    return Ju.toarray() if sparse.issparse(Ju) else Ju


def damped_step(Ju: np.ndarray, e: np.ndarray, A: np.ndarray, g: np.ndarray, mu: float) -> np.ndarray:
    """Solve (A + mu I) du = g with A = Ju^T Ju, g = Ju^T e.

    Cholesky first; if the matrix is not numerically positive definite, the least-squares solution of the
    augmented system [Ju; sqrt(mu) I] du = [e; 0] (same normal equations, better conditioned).
    """
    n = A.shape[0]
    try:
        factor = cho_factor(A + mu * np.eye(n), check_finite=False)
        du = cho_solve(factor, g, check_finite=False)
        if np.all(np.isfinite(du)):
            return du
    except LinAlgError:
        pass
    aug = np.vstack([as_dense(Ju), math.sqrt(mu) * np.eye(n)])
    rhs = np.concatenate([e, np.zeros(n)])
    return lstsq(aug, rhs, check_finite=False)[0]


def normal_equations(point, bounds: Bounds):
    """(Ju, A, g): J_u = J·diag(dx/du) as products, A = J_uᵀJ_u, g = J_uᵀe, from one JᵀJ and Jᵀe of the point;
    A is formed from J_u itself (column by column, as before) only where JᵀJ overflows."""
    s = bounds.dx_du(point.u)
    Ju = ScaledColumns(point.J, s)
    with np.errstate(over="ignore", invalid="ignore"):
        A = gram(point.J) * np.outer(s, s)
        if not np.all(np.isfinite(A)):
            A = gram(times_columns(point.J, s))
    return Ju, A, Ju.T @ point.e


def column_scale(Ju, previous: np.ndarray | None, groups: tuple[int, ...] = (), A: np.ndarray | None = None
                  ) -> np.ndarray:
    """Moré's D: the largest column norm of J_u seen so far (never shrinking, so a quantity that once mattered
    keeps its damping when its column fades near a bound); 1 for a column that was always zero.
    With a finite A = J_uᵀJ_u the norms are the roots of its diagonal; otherwise from J_u's columns themselves
    (divided by their peaks: no overflow of the squares)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if A is not None and np.all(np.isfinite(A)):
            norm = np.sqrt(np.maximum(np.diag(A), 0.0))
        else:
            norm = column_norms(as_dense(Ju) if isinstance(Ju, ScaledColumns) else Ju)
    norm[~np.isfinite(norm)] = 0.0
    if groups:
        if len(groups) != norm.size:
            raise ValueError(f"`scale_groups` has {len(groups)} entries, expected {norm.size} (one per quantity)")
        # each group's largest norm, by one pass (a multiple-shooting fit has a group per free start: hundreds)
        _, group = np.unique(np.asarray(groups), return_inverse=True)
        peak = np.full(group.max() + 1, -np.inf)
        np.maximum.at(peak, group, norm)
        norm = peak[group]
    if previous is not None:
        norm = np.maximum(norm, previous)
    return norm


def scaled_system(Ju, A: np.ndarray, g: np.ndarray, col: np.ndarray | None, e: np.ndarray):
    """The system a step solves: ``(Ju, Js, As, gs, scale)``, with ``As = D⁻¹AD⁻¹``, ``gs = D⁻¹g`` and
    ``Js = Ju D⁻¹`` for D = ``scale`` (the step in the quantities is then ``solve(As, gs) / scale``).

    D is Moré's column scale ``col`` (``scale="jac"``) where A and g are finite; where JᵀJ overflows (near a
    divergence) it is J_u's own column norms (Marquardt's scaling, which keeps the step finite; ``Ju`` is then
    returned dense); otherwise there is none (``Js``, ``scale`` None; ``As``, ``gs`` are A and g)."""
    scale, Js, gs = None, None, g
    if col is not None and np.all(np.isfinite(A)) and np.all(np.isfinite(g)):
        scale = np.where(col > 0, col, 1.0)
        Js = ScaledColumns(Ju.J, Ju.s / scale) if isinstance(Ju, ScaledColumns) else over_columns(Ju, scale)
        A, gs = A / np.outer(scale, scale), g / scale
    elif not np.all(np.isfinite(A)) or not np.all(np.isfinite(g)):
        # J^T J overflows near a divergence: solve with unit-norm columns instead (Marquardt's scaling), which
        # keeps the step finite; trainlm's plain mu*I is used everywhere else
        Ju = as_dense(Ju)
        with np.errstate(over="ignore", invalid="ignore"):
            scale = column_norms(Ju)
        scale[~(scale > 0) | ~np.isfinite(scale)] = 1.0
        Js = over_columns(Ju, scale)
        A, gs = gram(Js), Js.T @ e
    return Ju, Js, A, gs, scale


#: Moré's trust-radius update: a gain ratio below TRUST_POOR shrinks the radius to TRUST_SHRINK of the step
#: (so does a refusal), one above TRUST_GOOD grows it to TRUST_GROW times the step.
TRUST_POOR = rules.value("trust_poor_gain")
TRUST_GOOD = rules.value("trust_good_gain")
TRUST_SHRINK = rules.value("trust_shrink")
TRUST_GROW = rules.value("trust_grow")


def trust_accepted(radius: float, rho: float, step_norm: float) -> float:
    """The trust radius after an accepted step (Moré 1978): a quarter of the step where the model predicted
    badly, twice the step where it predicted well, unchanged between."""
    if rho < TRUST_POOR:
        return TRUST_SHRINK * step_norm
    if rho > TRUST_GOOD:
        return max(radius, TRUST_GROW * step_norm)
    return radius


#: The trust radius's step length is solved to this fraction of the radius (MINPACK's lmpar takes 0.1).
RADIUS_TOLERANCE = rules.value("radius_tolerance")


def mu_for_radius(A: np.ndarray, g: np.ndarray, radius: float) -> float:
    """The smallest damping whose step (A + mu I)^-1 g is no longer than ``radius`` (to RADIUS_TOLERANCE of it),
    0 where the Gauss-Newton step fits: Hebden's Newton iteration on 1/|p(mu)| (Moré 1978, as MINPACK's lmpar),
    one Cholesky factorization per iteration (no eigen-decomposition: a multiple-shooting fit has hundreds of
    quantities), kept within the bracket [|g|/radius - trace A, |g|/radius] where the secular function
    changes sign."""
    n = A.shape[0]
    eye = np.eye(n)

    def step(m):
        try:
            factor = cho_factor(A + m * eye, check_finite=False)
        except LinAlgError:
            return None, None
        p = cho_solve(factor, g, check_finite=False)
        if not np.all(np.isfinite(p)):
            return None, None
        R, lower = factor
        q = solve_triangular(R, p, trans="T" if not lower else "N", lower=lower, check_finite=False)
        return p, q

    p, _ = step(0.0)
    if p is not None and float(np.linalg.norm(p)) <= radius * (1.0 + RADIUS_TOLERANCE):
        return 0.0
    gnorm = float(np.linalg.norm(g))
    hi = gnorm / radius  # |p(mu)| <= |g| / mu
    lo = max(0.0, hi - float(np.trace(A)))  # |p(mu)| >= |g| / (mu + largest eigenvalue), which trace(A) bounds
    mu = hi if lo == 0.0 else math.sqrt(lo * hi)
    for _ in range(50):
        p, q = step(mu)
        if p is None:  # A + mu I not numerically positive definite: mu is too small
            lo, mu = mu, hi if lo == 0.0 else math.sqrt(mu * hi)
            continue
        length = float(np.linalg.norm(p))
        if abs(length - radius) <= RADIUS_TOLERANCE * radius:
            return mu
        if length > radius:
            lo = mu
        else:
            hi = mu
        qq = float(q @ q)
        newton = mu + (length / radius) * (length - radius) * length / qq if qq > 0 else math.nan
        mu = newton if lo < newton < hi else (0.5 * (lo + hi) if lo > 0 else 0.1 * hi)
    return hi


def held_step(Js, A, gs, scale, e, mu: float, held: np.ndarray, value: np.ndarray) -> np.ndarray:
    """The damped step in the quantities' coordinates with the ``held`` components at ``value`` and the others
    solving (A + mu I)_FF z_F = gs_F - A_FH z_H in the scaled coordinates z = scale * dx of ``A``, ``gs``."""
    free = ~held
    z_held = np.where(held, scale * value, 0.0)
    rhs = gs[free] - A[np.ix_(free, held)] @ z_held[held]
    z = damped_step(_Subset(Js, free), e - Js @ z_held, A[np.ix_(free, free)], rhs, mu)
    step = value.copy()
    step[free] = z / scale[free]
    return step


class _Subset:
    """Some columns of J (dense, CSR or ScaledColumns), formed only where damped_step falls back to lstsq."""

    def __init__(self, J, columns: np.ndarray):
        self.J, self.columns = J, columns

    def dense(self) -> np.ndarray:
        return as_dense(self.J)[:, self.columns]


def predicted_decrease(du: np.ndarray, g: np.ndarray, Ju) -> float:
    """The decrease of the cost the linear model predicts for the step du: du·g - ½|Ju du|², with g = Juᵀe
    (positive for a damped step); for a geodesic step, of the step taken."""
    Jdu = Ju @ du
    with np.errstate(over="ignore", invalid="ignore"):
        return float(du @ g) - 0.5 * float(Jdu @ Jdu)


GEODESIC_H = rules.value("geodesic_h")  # the finite-difference step, as a fraction of the step, of the second directional derivative


def geodesic_step(residual_at: Callable[[np.ndarray], np.ndarray | None], point, Ju, Jd, A, scale, du,
                  mu: float, alpha: float) -> np.ndarray:
    """The step with geodesic acceleration (Transtrum & Sethna, arXiv:1201.5885, 2012): du + a/2, where a solves
    the same damped system for the residuals' second derivative along du (one extra residual evaluation, by
    finite differences). In a narrow curved valley the plain step leaves the valley and is cut back to a crawl;
    the acceleration bends it along. Where the bend is large for the step, 2|a|/|du| > alpha, the quadratic model
    is not to be trusted and the plain step is tried (refusing it instead raises mu: measured, a tank chart's fit
    then took 376 iterations instead of 9)."""
    u_h = point.u + GEODESIC_H * du
    e_h = residual_at(u_h)  # the residual at internal coordinates u_h, None where the model diverged
    if e_h is None:
        return du
    with np.errstate(over="ignore", invalid="ignore"):
        e_vv = (2.0 / GEODESIC_H**2) * (e_h - point.e + GEODESIC_H * (Ju @ du))
        if not np.all(np.isfinite(e_vv)):
            return du
        acc = damped_step(Jd, e_vv, A, Jd.T @ e_vv, mu)
        if scale is not None:
            acc = acc / scale
        s = 1.0 if scale is None else scale
        if not 2.0 * float(np.linalg.norm(acc * s)) <= alpha * float(np.linalg.norm(du * s)):
            return du
    return du + 0.5 * acc

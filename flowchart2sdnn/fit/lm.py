"""Levenberg-Marquardt on the squared error (paper eqs. 4 and 11) with the ``trainlm`` damping schedule.

The trainer is generic: it sees a callback ``fun(x) -> (e, J)`` returning the residual ``e = y - yhat``
(shape (M,)) and the model Jacobian ``J = d yhat / d x`` (shape (M, P)), never a network.  With
``de/dx = -J`` the step of eq. (11) reads, in the internal (unbounded) coordinates ``u`` of
:mod:`flowchart2sdnn.fit.transforms`,

    (J_u^T J_u + mu I) du = J_u^T e,      J_u = J * dx/du,      cost E = 1/2 e^T e.

A trial step is accepted only if it lowers the cost (then ``mu *= mu_dec``); otherwise ``mu *= mu_inc``
and the step is recomputed (the schedule of :mod:`.damping`, shared with the quasi-online kernel; or Nielsen's,
``LMOptions.damping``).  A trial whose simulation diverges (``fun`` returns None, non-finite
values, or raises FloatingPointError/OverflowError) or that ``guard`` refuses is rejected the same way,
so the result never holds NaN.

``J`` may be a ``scipy.sparse`` matrix: the multiple-shooting Jacobian (identify.shooting) has a dense block
for the parameters and, per segment, a block for that segment's free start only; formed densely, its
products cost 13x a single-shooting iteration at 250 segments (benchmarks/bench_shooting_iteration.py).
The trainer only forms JᵀJ, Jᵀe and column norms, which sparse products give at the cost of the nonzeros.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.linalg import LinAlgError, cho_factor, cho_solve, lstsq, solve_triangular

from .. import rules
from .boxstep import feasible_step
from .damping import TRAINLM_MU0, first_mu, mu_accepted, mu_refused, nielsen_accepted, nielsen_refused
from .effective import effective_samples
from .transforms import Bounds

__all__ = ["LMOptions", "LMResult", "levenberg_marquardt", "damped_step", "STATUS_MESSAGES", "CONVERGED_STATUSES",
           "WideFirstCSR", "CRAWL_DETAIL", "gauss_newton_gain"]

#: Status code -> message (scipy style).  ``LMResult.message`` starts with one of these.
STATUS_MESSAGES: dict[str, str] = {
    "diverged_at_start": "the model diverged (no finite output) at the start values; choose other start values",
    "min_grad": "the gradient norm fell below `min_grad`",
    "cost_goal": "the cost reached `cost_goal`",
    "max_iter": "the iteration limit `max_iter` was reached",
    "mu_max": "mu exceeded `mu_max`: no damped step lowers the cost (a local minimum, or rejected steps)",
    "max_mu_tries": "`max_mu_tries` increases of mu in a row did not find a step that lowers the cost",
    "small_step": "the relative step fell below `min_rel_step`",
    "small_cost_change": "the cost stopped falling: its relative decrease fell below `min_rel_cost_change` in one "
                         "iteration, or below `stall_decrease` over the last `stall_iterations`, or, at the noise floor "
                         "(`crawl_cost`), below `crawl_decrease` over the last `crawl_iterations` (or, with the "
                         "trust radius, the model's best decrease is below the cost's rounding)",
    "negligible_gain": "what is left to gain is negligible (in units of -2 log-likelihood at the residual's own "
                       "variance)",
    "callback_stop": "stopped by the callback",
    "interrupted": "interrupted (KeyboardInterrupt); the best point so far is returned",
}

#: Statuses that mean "a (local) minimum was reached" rather than "stopped early".
CONVERGED_STATUSES = frozenset({"min_grad", "cost_goal", "mu_max", "small_step", "small_cost_change",
                                "negligible_gain"})


@dataclass(frozen=True)
class LMOptions:
    """Settings of :func:`levenberg_marquardt` (names and defaults follow MATLAB's ``trainlm``).

    ``mu_min`` keeps mu from underflowing after a long run of accepted steps, so that a later rejection
    can raise it back to a useful size within ``max_mu_tries`` tries.

    ``tau`` > 0 scales the first damping to the problem: ``mu = max(mu0, tau * max diag(JᵀJ))`` at the start
    (Madsen, Nielsen & Tingleff, *Methods for non-linear least squares problems*, 2004, section 3.2).
    trainlm's fixed ``mu0`` makes the first steps of a long record (diag(JᵀJ) of 1e6 and more) undamped
    Gauss-Newton steps that jump across narrow cost valleys; 0 keeps trainlm's behaviour.

    ``scale = "jac"`` damps each quantity in proportion to its own curvature, ``(JᵀJ + mu D²) du = Jᵀe`` with
    D the largest column norms of J_u seen so far (Moré 1978, MINPACK's ``lmder``, scipy's ``x_scale='jac'``):
    the step no longer depends on the units of the quantities (a stiffness of 500 N·m/rad next to an inertia
    of 0.4 kg·m²); ``mu`` is then relative (``tau * max diag`` becomes ``tau``). "none" is trainlm's ``mu I``.
    ``scale_groups`` (one integer per quantity, optional) makes quantities of one group share one D, the
    largest of their column norms: a learned curve's weights are numbers of one kind whose columns come and
    go with saturation, and damped apart they crawl (the bundled engine example: 1000 iterations unconverged
    with a D per weight, converged with one D for all of them).

    ``stall_decrease`` > 0 ends a fit as converged ("small_cost_change") once the cost has fallen by less than that fraction of itself
    over the last ``stall_iterations`` accepted iterations: one iteration's gain says little (a large mu makes
    it small), ten in a row that together gain nothing that matters do.

    ``crawl_decrease`` > 0 ends a fit as converged ("small_cost_change") once the cost, at or below
    ``crawl_cost``, has fallen by less than that fraction of itself over the last ``crawl_iterations`` accepted
    iterations. It is the stall rule over a longer window, for a fit that is already at the noise floor and creeps
    along a direction the data barely determine (a learned curve's slope traded against a viscous term: the
    three-mass learned chart's draw 9 gained 0.3-0.7 E/N per 100 iterations for more than 1000 iterations,
    above the stall rule's 0.1, with its cost within 1 % of the noise's).

    ``negligible_gain`` > 0 ends a fit as converged ("negligible_gain") wherever it is, at the noise floor or
    far above it, once the undamped Gauss-Newton step predicts a fall of -2 log-likelihood below that many units
    at the residual's own variance (m dE / E for m residuals: the Newton decrement, the step's length in the
    metric of the parameters' covariance, so it is blind to units and scaling) and the last accepted step
    gained less than that too. Quantities the step pushes against a bound they are within one standard error
    of (box bounds) are held there for the prediction. ``negligible_pace`` > 0 ends it the same way once the last
    ``pace_iterations`` accepted iterations together gained less than that many units while Gauss-Newton's
    unconstrained step predicts less than ``pace_left`` (3.84, what a test at the 5 % level can see): a descent
    held by bounds, the stability guard or a trust radius, near a minimum that step cannot reach. ``residual_stride`` > 0 (the residual laid out as rows of
    that many outputs) counts the residual's independent samples (:mod:`.effective`: its length over its
    autocorrelation time) instead of its entries: a residual that is mostly a missing effect or coloured noise
    weighs a fall of the cost by what it holds.

    ``damping = "nielsen"`` moves mu by the gain ratio rho of each accepted step (actual over predicted decrease):
    ``mu *= max(1/3, 1 - (2 rho - 1)^3)``, and by 2, 4, 8, ... on refusals in a row (:mod:`.damping`);
    "trainlm" is ``mu_dec`` / ``mu_inc``. ``damping = "trust"`` sets each step's length instead (Moré 1978, as
    MINPACK and scipy's trf): mu is the smallest damping whose scaled step fits a trust radius (0 where the
    Gauss-Newton step fits), the radius starts at the start's scaled size and becomes a quarter of the step after
    a refusal or a poor gain ratio (< 0.25), twice the step after a good one (> 0.75); ``mu_history`` then holds
    the radius. Where mu is small beside JᵀJ, raising it barely shortens the step, so Nielsen's x2, x4, ... take
    several refused trials to act; the radius acts at once. A trust-radius fit also ends as converged
    ("small_cost_change") when the Gauss-Newton step fits the radius, or a trial follows a refusal, and predicts a
    decrease below ``COST_ROUNDING`` of the cost, which the cost cannot show. ``trial_jacobian = True``
    simulates the first trial of an iteration with its Jacobian (``fun``) instead of ``residual`` alone:
    accepted, it needs no second simulation; later trials of the iteration (after a refusal) stay residual-only.
    With the trust radius every trial is simulated with its Jacobian (after a refusal the step is a quarter of the
    refused one, mostly accepted) except one more than ``LONG_STEP`` times longer (scaled) than the last accepted
    step (mostly refused). Either way the iterates are the same; only the count of simulations differs.
    ``bound_width`` > 0 makes each one-sided bound's transform bend within that fraction of the start's distance
    from the bound (:meth:`.transforms.Bounds.with_width`); 0 keeps the unit transform.

    ``bounds = "box"`` handles the bounds without a transform: steps in the physical (column-scaled) coordinates,
    each component held within 0.995 of its room to the bound it moves towards and the others re-solved around
    it (:mod:`.boxstep`), every iterate strictly feasible, as bounded trust-region methods do. It needs plain
    steps (``geodesic = 0``) and the unit transform's width (``bound_width = 0``). "transform" is the change of
    variables of :mod:`.transforms`.
    """

    max_iter: int = rules.value("lm_max_iter")
    mu0: float = TRAINLM_MU0
    mu_inc: float = rules.value("lm_mu_inc")
    mu_dec: float = rules.value("lm_mu_dec")
    mu_max: float = rules.value("lm_mu_max")
    min_grad: float = rules.value("lm_min_grad")
    cost_goal: float = rules.value("lm_cost_goal")
    min_rel_step: float = rules.value("lm_min_rel_step")
    min_rel_cost_change: float = rules.value("lm_min_rel_cost_change")
    stall_decrease: float = rules.value("lm_stall_decrease")
    stall_iterations: int = rules.value("lm_stall_iterations")
    crawl_decrease: float = rules.value("lm_crawl_decrease")
    crawl_iterations: int = rules.value("crawl_iterations")
    crawl_cost: float = rules.value("lm_crawl_cost")
    negligible_gain: float = rules.value("lm_negligible_gain")
    negligible_pace: float = rules.value("lm_negligible_pace")
    pace_iterations: int = rules.value("pace_iterations")
    pace_left: float = rules.value("pace_left")
    residual_stride: int = rules.value("lm_residual_stride")
    max_mu_tries: int = rules.value("lm_max_mu_tries")
    mu_min: float = rules.value("lm_mu_min")
    tau: float = rules.value("lm_tau")
    scale: str = "none"
    scale_groups: tuple[int, ...] = ()
    geodesic: float = rules.value("lm_geodesic")
    damping: str = "trainlm"
    trial_jacobian: bool = False
    bound_width: float = rules.value("lm_bound_width")
    bounds: str = "transform"

    def __post_init__(self) -> None:
        def need(cond: bool, text: str) -> None:
            if not cond:
                raise ValueError(text)

        for name in (
            "mu0",
            "mu_inc",
            "mu_dec",
            "mu_max",
            "min_grad",
            "cost_goal",
            "min_rel_step",
            "min_rel_cost_change",
            "stall_decrease",
            "crawl_decrease",
            "negligible_gain",
            "negligible_pace",
            "pace_left",
            "mu_min",
            "tau",
        ):
            need(math.isfinite(getattr(self, name)), f"`{name}` must be finite, got {getattr(self, name)}")
        need(
            isinstance(self.max_iter, int) and self.max_iter >= 0,
            f"`max_iter` must be an int >= 0, got {self.max_iter!r}",
        )
        need(
            isinstance(self.max_mu_tries, int) and self.max_mu_tries >= 1,
            f"`max_mu_tries` must be an int >= 1, got {self.max_mu_tries!r}",
        )
        need(0 < self.mu_min <= self.mu0 <= self.mu_max, "need 0 < `mu_min` <= `mu0` <= `mu_max`")
        need(self.mu_inc > 1, f"`mu_inc` must be > 1, got {self.mu_inc}")
        need(0 < self.mu_dec < 1, f"`mu_dec` must be in (0, 1), got {self.mu_dec}")
        need(isinstance(self.stall_iterations, int) and self.stall_iterations >= 1,
             f"`stall_iterations` must be an int >= 1, got {self.stall_iterations!r}")
        need(isinstance(self.crawl_iterations, int) and self.crawl_iterations >= 1,
             f"`crawl_iterations` must be an int >= 1, got {self.crawl_iterations!r}")
        need(not math.isnan(self.crawl_cost), "`crawl_cost` must be a number or inf, got nan")
        need(isinstance(self.pace_iterations, int) and self.pace_iterations >= 1,
             f"`pace_iterations` must be an int >= 1, got {self.pace_iterations!r}")
        need(isinstance(self.residual_stride, int) and self.residual_stride >= 0,
             f"`residual_stride` must be an int >= 0, got {self.residual_stride!r}")
        need(self.damping in ("trainlm", "nielsen", "trust"),
             f"`damping` must be 'trainlm', 'nielsen' or 'trust', got {self.damping!r}")
        need(self.scale in ("none", "jac"), f"`scale` must be 'none' or 'jac', got {self.scale!r}")
        need(all(isinstance(g, int) for g in self.scale_groups), "`scale_groups` must be integers, one per quantity")
        need(math.isfinite(self.bound_width) and self.bound_width >= 0,
             f"`bound_width` must be a finite number >= 0, got {self.bound_width}")
        need(math.isfinite(self.geodesic) and 0 <= self.geodesic < 2, f"`geodesic` must be in [0, 2), got {self.geodesic}")
        need(self.bounds in ("transform", "box"), f"`bounds` must be 'transform' or 'box', got {self.bounds!r}")
        need(self.bounds == "transform" or (self.geodesic == 0 and self.bound_width == 0),
             "`bounds='box'` takes plain steps in the physical coordinates: it needs `geodesic` = 0 and "
             f"`bound_width` = 0, got {self.geodesic} and {self.bound_width}")
        for name in ("min_grad", "cost_goal", "min_rel_step", "min_rel_cost_change", "stall_decrease", "crawl_decrease",
                     "tau"):
            need(getattr(self, name) >= 0, f"`{name}` must be >= 0, got {getattr(self, name)}")


@dataclass(frozen=True, eq=False)
class LMResult:
    """Outcome of :func:`levenberg_marquardt`; arrays are read-only.

    Attributes
    ----------
    x : ndarray (P,)            final (best) values, external coordinates
    cost : float                E = 1/2 e^T e at ``x`` (inf only for "diverged_at_start")
    status, message : str       a key of ``STATUS_MESSAGES`` and a sentence with details
    iterations : int            accepted steps
    cost_history, mu_history : tuple of float, length iterations + 1 (start value, then after each step; for
                                ``damping="trust"`` the trust radius)
    jac : ndarray (M, P)        last model Jacobian d yhat / d x at ``x`` (external coordinates; a CSR
                                matrix when ``fun`` returns sparse Jacobians)
    residual : ndarray (M,)     e = y - yhat at ``x``
    nfev, njev : int            residual and Jacobian evaluations
    interrupted : bool          True after a KeyboardInterrupt
    names : tuple of str        quantity names
    mu : float                  damping when the run stopped (may exceed ``mu_max``); a quasi-online
                                caller can start the next window from it
    rejected_cost, rejected_diverged, rejected_guard : int   trial steps rejected, by reason
    last_guard_reason : str or None                          the guard's last refusal
    stages : tuple of dict      earlier stages of a staged fit whose last stage this is (multiple shooting,
                                identify.shooting), each a summary; () for a plain fit
    """

    x: np.ndarray
    cost: float
    status: str
    message: str
    iterations: int
    cost_history: tuple[float, ...]
    mu_history: tuple[float, ...]
    jac: np.ndarray
    residual: np.ndarray
    nfev: int
    njev: int
    interrupted: bool = False
    names: tuple[str, ...] = ()
    mu: float = math.nan
    rejected_cost: int = 0
    rejected_diverged: int = 0
    rejected_guard: int = 0
    last_guard_reason: str | None = None
    stages: tuple = ()

    @property
    def converged(self) -> bool:
        """True when a stopping rule of ``CONVERGED_STATUSES`` ended the run."""
        return self.status in CONVERGED_STATUSES


# ---------------------------------------------------------------------------------------------- helpers
@dataclass(frozen=True)
class _Point:
    u: np.ndarray
    x: np.ndarray
    e: np.ndarray
    J: np.ndarray
    cost: float


@dataclass
class _Counters:
    nfev: int = 0
    njev: int = 0
    rejected_cost: int = 0
    rejected_diverged: int = 0
    rejected_guard: int = 0
    last_guard_reason: str | None = None
    m: int | None = field(default=None)


def _cost(e: np.ndarray) -> float:
    with np.errstate(over="ignore", invalid="ignore"):
        return 0.5 * float(e @ e)


def _check_e(e, counters: _Counters) -> np.ndarray | None:
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


def _call_fun(fun, x, n_params, counters) -> tuple[np.ndarray, np.ndarray] | None:
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
    e = _check_e(e, counters)
    if e is None or J is None:
        return None
    if sparse.issparse(J):  # a CSR float matrix as it is: a WideFirstCSR keeps its blocks
        J = J if sparse.isspmatrix_csr(J) and J.dtype == np.float64 else sparse.csr_matrix(J, dtype=float)
    else:
        J = np.array(J, dtype=float)
    if J.shape != (e.size, n_params):
        raise ValueError(f"the Jacobian must have shape (M, P) = ({e.size}, {n_params}), got {J.shape}")
    if not np.all(np.isfinite(J.data if sparse.issparse(J) else J)) or not math.isfinite(_cost(e)):
        return None
    return e, J


def _times_columns(J, s: np.ndarray):
    """J with column j multiplied by s[j] (dense or CSR, as J)."""
    return J @ sparse.diags(s) if sparse.issparse(J) else J * s


def _over_columns(J, s: np.ndarray):
    """J with column j divided by s[j] (dense or CSR, as J)."""
    return J @ sparse.diags(1.0 / s) if sparse.issparse(J) else J / s


#: A CSR Jacobian's columns with nonzeros in at least this fraction of the rows enter JᵀJ by dense products.
WIDE_COLUMN = rules.value("wide_column")


class WideFirstCSR(sparse.csr_matrix):
    """A CSR Jacobian whose caller also hands over its first ``wide.shape[1]`` columns as the dense array ``wide``
    and the others as the CSR matrix ``rest`` (the values of J[:, :k].toarray() and J[:, k:]; None: not given):
    JᵀJ then needs no column slicing of J nor a count of every column's nonzeros (5 of _gram's 7 ms at 250
    segments, bench_shooting_iteration). A multiple-shooting Jacobian (identify.shooting) writes them from its
    kernels' results; anything scipy derives from it is a plain CSR matrix (or one without them)."""

    wide: np.ndarray | None = None
    rest: sparse.csr_matrix | None = None


def _gram(J) -> np.ndarray:
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


def _column_sq_sums(J) -> np.ndarray:
    if sparse.issparse(J):
        return np.asarray(J.multiply(J).sum(axis=0)).ravel()
    return np.einsum("ij,ij->j", J, J)


def _column_peaks(J) -> np.ndarray:
    if sparse.issparse(J):
        return abs(J).max(axis=0).toarray().ravel() if J.shape[0] else np.zeros(J.shape[1])
    return np.max(np.abs(J), axis=0, initial=0.0)


def _column_norms(J) -> np.ndarray:
    """Euclidean column norms, computed on columns divided by their peaks (no overflow of the squares)."""
    peak = _column_peaks(J)
    safe = np.where(peak > 0, peak, 1.0)
    if sparse.issparse(J):
        return np.sqrt(_column_sq_sums(_over_columns(J, safe))) * peak
    return np.linalg.norm(J / safe, axis=0) * peak


class _ScaledColumns:
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
        M = _times_columns(self.J, self.s)
        return M.toarray() if sparse.issparse(M) else M


class _Transposed:
    def __init__(self, op: _ScaledColumns):
        self.op = op

    def __matmul__(self, w: np.ndarray) -> np.ndarray:
        return self.op.s * np.asarray(self.op.J.T @ w).ravel()


def _dense(Ju) -> np.ndarray:
    if isinstance(Ju, (_ScaledColumns, _Subset)):
        return Ju.dense()
    return Ju.toarray() if sparse.issparse(Ju) else Ju


def _call_residual(residual, x, counters) -> np.ndarray | None:
    counters.nfev += 1
    try:
        e = _check_e(residual(x.copy()), counters)
    except (FloatingPointError, OverflowError):
        return None
    if e is None or not math.isfinite(_cost(e)):
        return None
    return e


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
    aug = np.vstack([_dense(Ju), math.sqrt(mu) * np.eye(n)])
    rhs = np.concatenate([e, np.zeros(n)])
    return lstsq(aug, rhs, check_finite=False)[0]


def _readonly(a):
    if sparse.issparse(a):  # scipy's sparse matrices have no write flag; the trainer keeps no reference
        return a
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


# ---------------------------------------------------------------------------------------------- front door
def levenberg_marquardt(
    fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray] | None],
    x0: Sequence[float] | np.ndarray,
    names: Sequence[str],
    lower: Sequence[float] | np.ndarray | float | None = None,
    upper: Sequence[float] | np.ndarray | float | None = None,
    options: LMOptions = LMOptions(),
    callback: Callable[[int, np.ndarray, float, float], bool | None] | None = None,
    guard: Callable[[np.ndarray], str | None] | None = None,
    residual: Callable[[np.ndarray], np.ndarray | None] | None = None,
) -> LMResult:
    """Minimise E(x) = 1/2 sum e(x)^2 by Levenberg-Marquardt within bounds.

    Parameters
    ----------
    fun : callable ``fun(x) -> (e, J)``
        ``x`` (P,) external values; ``e`` (M,) residual y - yhat; ``J`` (M, P) = d yhat / d x.  Returning
        None, non-finite values, or raising FloatingPointError/OverflowError means "the model diverged":
        that trial step is rejected.  Other exceptions propagate.
    x0 : array_like (P,)
        Start values, inside ``[lower, upper]`` (a value on a bound is allowed).
    names : sequence of str (P,)
        Quantity names for messages.
    lower, upper : array_like (P,), scalar or None
        Bounds, ``-inf``/``inf``/None for none; enforced by a transform, or with ``options.bounds = "box"`` by
        steps held inside them (:mod:`.boxstep`); never by clipping a step after the fact.
    options : LMOptions
    callback : callable ``callback(iteration, x, cost, mu) -> bool | None``, optional
        Called after each accepted step; returning True stops with status "callback_stop".
    guard : callable ``guard(x) -> str | None``, optional
        Called on each trial x before simulating it; a string rejects the trial (mu is increased) and is
        kept as ``last_guard_reason``.  The start ``x0`` is not checked.
    residual : callable ``residual(x) -> e | None``, optional
        A cheaper residual-only model: when given, trial steps are evaluated with it and ``fun`` is called
        only at accepted points (for the Jacobian), as ``trainlm`` does.

    Returns
    -------
    LMResult
        The best point found; ``x`` is finite and within bounds whatever the status.
    """
    x0 = np.array(x0, dtype=float)
    if x0.ndim != 1 or x0.size == 0:
        raise ValueError(f"`x0` must be a non-empty 1-D array, got shape {x0.shape}")
    names = tuple(str(n) for n in names)
    if len(names) != x0.size:
        raise ValueError(f"`names` has {len(names)} entries, `x0` has {x0.size}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"`names` are not unique: {', '.join(dup)}")
    bounds = Bounds.make(names, lower, upper)
    bounds.check(x0)
    if not isinstance(options, LMOptions):
        raise TypeError(f"`options` must be an LMOptions, got {type(options).__name__}")
    opt = options
    if opt.bound_width > 0:
        bounds = bounds.with_width(_widths(bounds, x0, opt.bound_width))
    box = None
    if opt.bounds == "box":  # the trainer's coordinates are the quantities themselves; the steps keep the box
        box, bounds = bounds, Bounds.make(names)
    n_params = x0.size
    counters = _Counters()

    u = bounds.start(x0)
    x = bounds.to_external(u)
    first = _call_fun(fun, x, n_params, counters)
    if first is None:
        return LMResult(
            x=_readonly(x0),
            cost=math.inf,
            status="diverged_at_start",
            message=STATUS_MESSAGES["diverged_at_start"],
            iterations=0,
            cost_history=(),
            mu_history=(),
            jac=_readonly(np.zeros((0, n_params))),
            residual=_readonly(np.zeros(0)),
            nfev=counters.nfev,
            njev=counters.njev,
            names=names,
            mu=opt.mu0,
        )
    point = _Point(u, x, first[0], first[1], _cost(first[0]))
    mu0 = _first_mu(point, bounds, opt) if opt.damping != "trust" else math.nan
    # One object holds the whole state so that a KeyboardInterrupt can never leave it half-updated.
    state = (point, mu0, (point.cost,), (mu0,))
    col = None  # the running column norms of "jac" scaling
    last_step = math.inf  # the scaled length of the last accepted step (_inner's trial_jacobian test)
    status, detail = None, ""
    try:
        while True:
            point, mu, costs, mus = state
            iteration = len(costs) - 1
            if point.cost <= opt.cost_goal:
                status = "cost_goal"
                break
            Ju, A, g = _normal_equations(point, bounds)  # g = Juᵀe = -dE/du
            gnorm = float(np.linalg.norm(g))
            if gnorm < opt.min_grad:
                status, detail = "min_grad", f"|grad| = {gnorm:.3g}"
                break
            if iteration >= opt.max_iter:
                status = "max_iter"
                break
            if mu > opt.mu_max and opt.damping != "trust":
                status = "mu_max"
                break
            if (opt.negligible_gain > 0 or opt.negligible_pace > 0) and len(costs) > 1:
                said = _negligible(point, A, g, costs, box, opt)
                if said is not None:
                    status, detail = "negligible_gain", said
                    break
            if opt.scale == "jac":
                col = _column_scale(Ju, col, opt.scale_groups, A)
            if opt.damping == "trust" and not math.isfinite(mu):  # the first radius: the start's scaled size
                mu = float(np.linalg.norm(point.u * (1.0 if col is None else np.where(col > 0, col, 1.0)))) or 1.0
                mus = (mu,)
            status, new_point, mu, tiny, rho, step = _inner(
                fun, residual, guard, bounds, point, Ju, g, mu, opt, counters, col, A, box, last_step
            )
            if status == "small_cost_change":
                detail = "the model's best decrease is below the cost's rounding"
            if new_point is not None:
                last_step = step
                rel_decrease = (point.cost - new_point.cost) / point.cost if point.cost > 0 else 0.0
                if opt.damping == "nielsen":
                    mu = nielsen_accepted(mu, rho, opt.mu_min)
                elif opt.damping == "trust":
                    pass  # _inner moved the radius
                else:
                    mu = mu_accepted(mu, opt.mu_dec, opt.mu_min)
                state = (new_point, mu, costs + (new_point.cost,), mus + (mu,))
                if tiny:
                    status = "small_step"
                elif 0 < opt.min_rel_cost_change and rel_decrease < opt.min_rel_cost_change:
                    status, detail = "small_cost_change", f"relative decrease {rel_decrease:.3g}"
                elif 0 < opt.stall_decrease and len(costs) > opt.stall_iterations:
                    gained = (costs[-opt.stall_iterations] - new_point.cost) / new_point.cost
                    if gained < opt.stall_decrease:
                        status = "small_cost_change"
                        detail = f"{gained:.3g} of the cost over the last {opt.stall_iterations} iterations"
                crawled = None if status is not None else _crawl_gain(costs + (new_point.cost,), opt)
                if crawled is not None:
                    status = "small_cost_change"
                    detail = f"{CRAWL_DETAIL}: {crawled:.3g} of the cost over the last {opt.crawl_iterations} iterations"
                if callback is not None and status is None:
                    if callback(iteration + 1, new_point.x.copy(), new_point.cost, mu):
                        status = "callback_stop"
            else:
                state = (point, mu, costs, mus)
            if status is not None:
                break
        interrupted = False
    except KeyboardInterrupt:
        status, interrupted = "interrupted", True

    point, mu, costs, mus = state
    iteration = len(costs) - 1
    message = f"{STATUS_MESSAGES[status]} (iteration {iteration}, cost {point.cost:.6g}, mu {mu:.3g}"
    message += f", {detail})" if detail else ")"
    if counters.last_guard_reason is not None and status in ("mu_max", "max_mu_tries"):
        message += f"; last step refused by the guard: {counters.last_guard_reason}"
    return LMResult(
        x=_readonly(point.x),
        cost=point.cost,
        status=status,
        message=message,
        iterations=iteration,
        cost_history=tuple(float(c) for c in costs),
        mu_history=tuple(float(m) for m in mus),
        jac=_readonly(point.J),
        residual=_readonly(point.e),
        nfev=counters.nfev,
        njev=counters.njev,
        interrupted=interrupted,
        names=names,
        mu=float(mu),
        rejected_cost=counters.rejected_cost,
        rejected_diverged=counters.rejected_diverged,
        rejected_guard=counters.rejected_guard,
        last_guard_reason=counters.last_guard_reason,
    )


def gauss_newton_gain(A: np.ndarray, g: np.ndarray, x: np.ndarray | None = None, box: Bounds | None = None,
                      sigma2: float = 1.0) -> float:
    """1/2 gᵀA⁺g, the cost E's fall the undamped Gauss-Newton step predicts, with quantities that the step
    pushes against a box bound closer than one standard error (sqrt(sigma2 (A⁺)_ii)) held at it."""
    d = np.sqrt(np.clip(np.diag(A), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    As, gs = A / np.outer(d, d), g / d
    free = np.ones(g.size, dtype=bool)
    for _ in range(3):
        idx = np.flatnonzero(free)
        if idx.size == 0:
            return 0.0
        w, V = np.linalg.eigh(As[np.ix_(idx, idx)])
        keep = w > max(float(w.max()), 0.0) * 1e-12
        inv = (V[:, keep] / w[keep]) @ V[:, keep].T
        ys = inv @ gs[idx]
        if box is None or x is None:
            break
        step, se = ys / d[idx], np.sqrt(np.clip(sigma2 * np.diag(inv), 0.0, None)) / d[idx]
        xi, lo, hi = x[idx], box.lower[idx], box.upper[idx]
        held = ((xi + step < lo) & (xi - lo < se)) | ((xi + step > hi) & (hi - xi < se))
        if not held.any():
            break
        free[idx[held]] = False
    return 0.5 * float(gs[idx] @ ys)


def _negligible(point: _Point, A, g, costs, box, opt: LMOptions) -> str | None:
    """The negligible-gain rule of :class:`LMOptions`: the detail of the status where it ends the fit."""
    m = point.e.size
    if not point.cost > 0 or m == 0:
        return None
    if opt.residual_stride > 0:  # a correlated residual holds fewer independent samples than it has entries
        m = effective_samples(point.e, opt.residual_stride)
    unit = point.cost / m  # one unit of -2 log-likelihood in E, at the residual's own variance
    k = opt.pace_iterations
    gained = (costs[-2] - costs[-1]) / unit
    paced = (costs[-1 - k] - costs[-1]) / unit if opt.negligible_pace > 0 and len(costs) > k else math.inf
    if gained >= opt.negligible_gain and paced >= opt.negligible_pace:
        return None
    left = gauss_newton_gain(A, g, point.x, box, 2.0 * unit) / unit
    if gained < opt.negligible_gain and left < opt.negligible_gain:
        return f"{left:.3g} units left by Gauss-Newton, {gained:.3g} gained by the last step"
    if paced < opt.negligible_pace and left < opt.pace_left:
        return f"{paced:.3g} units gained by the last {k} iterations, {left:.3g} left by Gauss-Newton"
    return None


#: The crawl rule's words in LMResult.message (identify warns on them).
CRAWL_DETAIL = "a crawl at the noise floor"


def _crawl_gain(costs: tuple[float, ...], opt: LMOptions) -> float | None:
    """The crawl rule of :class:`LMOptions` on the costs so far (start, then one per accepted step): the window's
    gain as a fraction of the cost where the rule ends the fit, else None."""
    if not (0 < opt.crawl_decrease and len(costs) > opt.crawl_iterations and costs[-1] <= opt.crawl_cost):
        return None
    gained = (costs[-1 - opt.crawl_iterations] - costs[-1]) / costs[-1]
    return gained if gained < opt.crawl_decrease else None


def _widths(bounds: Bounds, x0: np.ndarray, fraction: float) -> np.ndarray:
    """The one-sided transforms' widths: `fraction` of each start's distance from its bound, so that the bend
    sits at the same relative place whatever the quantity's unit; 1 (the unit transform) for a start on its
    bound, or a quantity with two bounds or none (their transforms do not use it)."""
    lo = np.where(np.isfinite(bounds.lower), bounds.lower, np.nan)
    hi = np.where(np.isfinite(bounds.upper), bounds.upper, np.nan)
    gap = np.where(np.isfinite(lo), x0 - lo, hi - x0)
    with np.errstate(invalid="ignore", over="ignore"):
        w = fraction * np.abs(gap)
    return np.where(np.isfinite(w) & (w > 0), w, 1.0)


def _normal_equations(point: _Point, bounds: Bounds):
    """(Ju, A, g): J_u = J·diag(dx/du) as products, A = J_uᵀJ_u, g = J_uᵀe, from one JᵀJ and Jᵀe of the point;
    A is formed from J_u itself (column by column, as before) only where JᵀJ overflows."""
    s = bounds.dx_du(point.u)
    Ju = _ScaledColumns(point.J, s)
    with np.errstate(over="ignore", invalid="ignore"):
        A = _gram(point.J) * np.outer(s, s)
        if not np.all(np.isfinite(A)):
            A = _gram(_times_columns(point.J, s))
    return Ju, A, Ju.T @ point.e


def _column_scale(Ju, previous: np.ndarray | None, groups: tuple[int, ...] = (), A: np.ndarray | None = None
                  ) -> np.ndarray:
    """Moré's D: the largest column norm of J_u seen so far (never shrinking, so a quantity that once mattered
    keeps its damping when its column fades near a bound); 1 for a column that was always zero.
    With a finite A = J_uᵀJ_u the norms are the roots of its diagonal; otherwise from J_u's columns themselves
    (divided by their peaks: no overflow of the squares)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if A is not None and np.all(np.isfinite(A)):
            norm = np.sqrt(np.maximum(np.diag(A), 0.0))
        else:
            norm = _column_norms(_dense(Ju) if isinstance(Ju, _ScaledColumns) else Ju)
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


def _first_mu(point: _Point, bounds: Bounds, opt: LMOptions) -> float:
    """trainlm's mu0, raised to tau * max diag(JᵀJ) (in the trainer's internal coordinates) when tau > 0."""
    if opt.tau <= 0:
        return opt.mu0
    if opt.scale == "jac":  # diag(D⁻¹JᵀJD⁻¹) is 1 at the start
        return float(first_mu(1.0, opt.mu0, opt.tau, opt.mu_max))
    Ju = _times_columns(point.J, bounds.dx_du(point.u))
    with np.errstate(over="ignore", invalid="ignore"):
        peak = float(np.max(_column_sq_sums(Ju), initial=0.0))
    return float(first_mu(peak, opt.mu0, opt.tau, opt.mu_max))


def _inner(fun, residual, guard, bounds: Bounds, point: _Point, Ju, g, mu: float, opt: LMOptions, counters,
           col: np.ndarray | None = None, A: np.ndarray | None = None, box: Bounds | None = None,
           last_step: float = math.inf):
    """Raise mu until a trial step lowers the cost (``col``: the column scale D of ``scale="jac"``; ``box``: the
    bounds of ``bounds="box"``, the trainer's coordinates then being the quantities themselves; ``last_step``:
    the scaled length of the last accepted step, inf before the first).

    Returns (status or None, accepted point or None, mu, tiny step flag, gain ratio of the accepted step, the
    accepted step's scaled length or nan).
    """
    if A is None:
        with np.errstate(over="ignore", invalid="ignore"):
            A = _gram(_dense(Ju))
    scale = None
    if col is not None and np.all(np.isfinite(A)) and np.all(np.isfinite(g)):
        scale = np.where(col > 0, col, 1.0)
        Js = _ScaledColumns(Ju.J, Ju.s / scale) if isinstance(Ju, _ScaledColumns) else _over_columns(Ju, scale)
        A, gs = A / np.outer(scale, scale), g / scale
    elif not np.all(np.isfinite(A)) or not np.all(np.isfinite(g)):
        # J^T J overflows near a divergence: solve with unit-norm columns instead (Marquardt's scaling), which
        # keeps the step finite; trainlm's plain mu*I is used everywhere else
        Ju = _dense(Ju)
        with np.errstate(over="ignore", invalid="ignore"):
            scale = _column_norms(Ju)
        scale[~(scale > 0) | ~np.isfinite(scale)] = 1.0
        Js = _over_columns(Ju, scale)
        A, gs = _gram(Js), Js.T @ point.e
    x_norm = float(np.linalg.norm(point.x))
    nu = 2.0  # Nielsen's growth of mu on refusals in a row
    radius = mu if opt.damping == "trust" else None
    for tries in range(opt.max_mu_tries):
        if radius is not None:
            mu = _mu_for_radius(A, g if scale is None else gs, radius)
        if scale is None:
            du = damped_step(Ju, point.e, A, g, mu)
        else:
            du = damped_step(Js, point.e, A, gs, mu) / scale
        if box is not None:
            solved = (Ju, A, g, np.ones_like(g)) if scale is None else (Js, A, gs, scale)
            du = feasible_step(point.x, du, box.lower, box.upper,
                               lambda held, value, s=solved, m=mu: _held_step(*s, point.e, m, held, value))
        if opt.geodesic > 0 and residual is not None:
            du = _accelerated(residual, bounds, point, Ju, Js if scale is not None else Ju, A, scale, du, mu,
                              opt.geodesic, counters)
        u_t = point.u + du
        if box is not None:  # rounding must not carry x + theta (bound - x) past the bound
            u_t = np.clip(u_t, box.lower, box.upper)
        x_t = bounds.to_external(u_t)
        tiny = float(np.linalg.norm(x_t - point.x)) <= opt.min_rel_step * (opt.min_rel_step + x_norm)
        step_norm = float(np.linalg.norm(du if scale is None else du * scale))
        predicted = _predicted_decrease(du, g, Ju) if opt.damping in ("nielsen", "trust") else math.nan
        if radius is not None and (tries > 0 or mu == 0.0) and predicted <= COST_ROUNDING * point.cost:
            # converged: the Gauss-Newton step fits the radius and its model decrease, the largest any step of this
            # model has, is below what the cost can show; or a longer step was refused and this shorter one's
            # is. Simulating it, then ever shorter steps, only draws rounding (the bench's L = 100 run refused
            # 14 such trials after converging)
            return "small_cost_change", None, radius, tiny, math.nan, math.nan
        # a trial likely accepted is simulated with its Jacobian at once (trial_jacobian) instead of a residual now
        # and the Jacobian's simulation again once accepted: the first trial of an iteration, and with the trust
        # radius a trial after a refusal too (a quarter of the refused step: 5 of 5 accepted on the shooting
        # bench, L = 2500); not a step much longer than the last accepted one (the radius doubled after a good
        # gain ratio, or a longer Gauss-Newton step), which leaves where the model was last confirmed and was
        # refused more often than not (bench_shooting_iteration: 6 of 9), a refused Jacobian costing 2-3 residuals
        with_jac = opt.trial_jacobian and (tries == 0 if radius is None else not step_norm > LONG_STEP * last_step)
        trial = _try(fun, None if with_jac else residual, guard, u_t, x_t, point.cost, counters)
        if trial is not None and opt.damping in ("nielsen", "trust"):
            # a model that predicted no decrease where the cost fell (rounding, or a geodesic bend) counts as good
            rho = (point.cost - trial.cost) / predicted if predicted > 0 and math.isfinite(predicted) else 1.0
        else:
            rho = math.nan
        if trial is not None:
            if radius is not None:
                radius = trust_accepted(radius, rho, step_norm)
                return None, trial, radius, tiny, rho, step_norm
            return None, trial, mu, tiny, rho, step_norm
        if tiny:  # the cost no longer decreases along steps at rounding level: converged
            return "small_step", None, mu if radius is None else radius, tiny, rho, math.nan
        if radius is not None:
            radius = 0.25 * step_norm
            continue
        if opt.damping == "nielsen":
            mu, nu = nielsen_refused(mu, nu, math.inf)
        else:
            mu = mu_refused(mu, opt.mu_inc, math.inf)  # no cap: past mu_max the run stops
        if mu > opt.mu_max:
            return "mu_max", None, mu, tiny, rho, math.nan
    return "max_mu_tries", None, mu, False, math.nan, math.nan


#: A trust-radius trial whose scaled step is longer than this many times the last accepted step's is simulated
#: without its Jacobian even with ``trial_jacobian`` (the radius doubles after a good gain ratio: such a step is
#: twice).
LONG_STEP = rules.value("long_step")
#: The trust radius's fit ends as converged when the Gauss-Newton step's predicted decrease is below this fraction
#: of the cost: a change the cost cannot show (on the two-mass bench, 50 000 residuals, trials at the minimum
#: changed the cost by up to 1.6e-13 of itself whatever the model predicted, 1e-17 or 1e-12 of it).
COST_ROUNDING = rules.value("cost_rounding")


def trust_accepted(radius: float, rho: float, step_norm: float) -> float:
    """The trust radius after an accepted step (Moré 1978): a quarter of the step where the model predicted
    badly, twice the step where it predicted well, unchanged between."""
    if rho < 0.25:
        return 0.25 * step_norm
    if rho > 0.75:
        return max(radius, 2.0 * step_norm)
    return radius


#: The trust radius's step length is solved to this fraction of the radius (MINPACK's lmpar takes 0.1).
RADIUS_TOLERANCE = rules.value("radius_tolerance")


def _mu_for_radius(A: np.ndarray, g: np.ndarray, radius: float) -> float:
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


def _held_step(Js, A, gs, scale, e, mu: float, held: np.ndarray, value: np.ndarray) -> np.ndarray:
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
    """Some columns of J (dense, CSR or _ScaledColumns), formed only where damped_step falls back to lstsq."""

    def __init__(self, J, columns: np.ndarray):
        self.J, self.columns = J, columns

    def dense(self) -> np.ndarray:
        return _dense(self.J)[:, self.columns]


def _predicted_decrease(du: np.ndarray, g: np.ndarray, Ju) -> float:
    """The decrease of the cost the linear model predicts for the step du: du·g - ½|Ju du|², with g = Juᵀe
    (positive for a damped step); for a geodesic step, of the step taken."""
    Jdu = Ju @ du
    with np.errstate(over="ignore", invalid="ignore"):
        return float(du @ g) - 0.5 * float(Jdu @ Jdu)


GEODESIC_H = rules.value("geodesic_h")  # the finite-difference step, as a fraction of the step, of the second directional derivative


def _accelerated(residual, bounds: Bounds, point: _Point, Ju, Jd, A, scale, du, mu: float, alpha: float, counters):
    """The step with geodesic acceleration (Transtrum & Sethna, arXiv:1201.5885, 2012): du + a/2, where a solves
    the same damped system for the residuals' second derivative along du (one extra residual evaluation, by
    finite differences). In a narrow curved valley the plain step leaves the valley and is cut back to a crawl;
    the acceleration bends it along. Where the bend is large for the step, 2|a|/|du| > alpha, the quadratic model
    is not to be trusted and the plain step is tried (refusing it instead raises mu: measured, a tank chart's fit
    then took 376 iterations instead of 9)."""
    u_h = point.u + GEODESIC_H * du
    e_h = _call_residual(residual, bounds.to_external(u_h), counters)
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


def _try(fun, residual, guard, u_t, x_t, cost, counters: _Counters) -> _Point | None:
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
        e_t = _call_residual(residual, x_t, counters)
        if e_t is None:
            counters.rejected_diverged += 1
            return None
        if not _cost(e_t) < cost:
            counters.rejected_cost += 1
            return None
    out = _call_fun(fun, x_t, u_t.size, counters)
    if out is None:
        counters.rejected_diverged += 1
        return None
    cost_t = _cost(out[0])
    if not cost_t < cost:
        counters.rejected_cost += 1
        return None
    return _Point(u_t, x_t, out[0], out[1], cost_t)

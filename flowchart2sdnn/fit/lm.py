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

This module is the loop: :func:`levenberg_marquardt` validates its arguments once, then repeats "ask the stopping
rules, form the normal equations, try damped steps until one lowers the cost". The step computations (normal
equations, column scale, damped solve, trust radius, box-held steps, geodesic acceleration) are
:mod:`.steps`; the stopping rules, each a named predicate with one status, are :mod:`.stopping`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from .. import rules
from . import stopping
from .boxstep import feasible_step
from .damping import TRAINLM_MU0, first_mu, mu_accepted, mu_refused, nielsen_accepted, nielsen_refused
from .steps import (
    WideFirstCSR,
    column_scale,
    column_sq_sums,
    damped_step,
    geodesic_step,
    held_step,
    mu_for_radius,
    normal_equations,
    predicted_decrease,
    scaled_system,
    times_columns,
    trust_accepted,
)
from .stopping import CONVERGED_STATUSES, CRAWL_DETAIL, STATUS_MESSAGES, Stop, gauss_newton_gain
from .transforms import Bounds

# damped_step, WideFirstCSR (steps) and the status tables and gauss_newton_gain (stopping) keep their old address
__all__ = ["LMOptions", "LMResult", "levenberg_marquardt", "damped_step", "STATUS_MESSAGES", "CONVERGED_STATUSES",
           "WideFirstCSR", "CRAWL_DETAIL", "gauss_newton_gain"]




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
    decrease below ``stopping.COST_ROUNDING`` of the cost, which the cost cannot show. ``trial_jacobian = True``
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




























def _call_residual(residual, x, counters) -> np.ndarray | None:
    counters.nfev += 1
    try:
        e = _check_e(residual(x.copy()), counters)
    except (FloatingPointError, OverflowError):
        return None
    if e is None or not math.isfinite(_cost(e)):
        return None
    return e




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
    # One object holds the whole state so that a KeyboardInterrupt can never leave it half-updated. With the trust
    # radius its `mu` (and mu_history) is the radius; the damping that fits it is found anew at each trial.
    state = (point, mu0, (point.cost,), (mu0,))
    col = None  # the running column norms of "jac" scaling
    last_step = math.inf  # the scaled length of the last accepted step (_trials' trial_jacobian test)
    model = _Model(fun, residual, guard, bounds, box, opt, counters)
    stop: Stop | None = None
    try:
        while True:
            point, mu, costs, mus = state
            iteration = len(costs) - 1
            stop = stopping.cost_goal(point.cost, opt)
            if stop is not None:
                break
            Ju, A, g = normal_equations(point, bounds)  # g = Juᵀe = -dE/du
            stop = (stopping.min_grad(g, opt) or stopping.max_iter(iteration, opt) or stopping.mu_max(mu, opt)
                    or stopping.negligible_gain(point, A, g, costs, box, opt))
            if stop is not None:
                break
            if opt.scale == "jac":
                col = column_scale(Ju, col, opt.scale_groups, A)
            if opt.damping == "trust" and not math.isfinite(mu):  # the first radius: the start's scaled size
                mu = float(np.linalg.norm(point.u * (1.0 if col is None else np.where(col > 0, col, 1.0)))) or 1.0
                mus = (mu,)
            out = _trials(model, point, Ju, A, g, mu, col, last_step)
            stop, mu = out.stop, out.mu
            if out.point is None:
                state = (point, mu, costs, mus)
                if stop is not None:
                    break
                continue
            new = out.point
            last_step = out.step
            if opt.damping == "nielsen":
                mu = nielsen_accepted(mu, out.rho, opt.mu_min)
            elif opt.damping != "trust":  # the trust radius was moved by _trials
                mu = mu_accepted(mu, opt.mu_dec, opt.mu_min)
            state = (new, mu, costs + (new.cost,), mus + (mu,))
            stop = (stopping.small_step(out.tiny) or stopping.min_rel_cost_change(point.cost, new.cost, opt)
                    or stopping.stall(costs, new.cost, opt) or stopping.crawl(costs + (new.cost,), opt))
            if stop is None and callback is not None and callback(iteration + 1, new.x.copy(), new.cost, mu):
                stop = Stop("callback_stop")
            if stop is not None:
                break
        interrupted = False
    except KeyboardInterrupt:
        stop, interrupted = Stop("interrupted"), True

    status, detail = stop.status, stop.detail
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






def _first_mu(point: _Point, bounds: Bounds, opt: LMOptions) -> float:
    """trainlm's mu0, raised to tau * max diag(JᵀJ) (in the trainer's internal coordinates) when tau > 0."""
    if opt.tau <= 0:
        return opt.mu0
    if opt.scale == "jac":  # diag(D⁻¹JᵀJD⁻¹) is 1 at the start
        return float(first_mu(1.0, opt.mu0, opt.tau, opt.mu_max))
    Ju = times_columns(point.J, bounds.dx_du(point.u))
    with np.errstate(over="ignore", invalid="ignore"):
        peak = float(np.max(column_sq_sums(Ju), initial=0.0))
    return float(first_mu(peak, opt.mu0, opt.tau, opt.mu_max))


@dataclass(frozen=True)
class _Model:
    """What every trial of one fit needs: the callbacks, the coordinates, the options, the counters."""

    fun: Callable
    residual: Callable | None
    guard: Callable | None
    bounds: Bounds
    box: Bounds | None  # the bounds of bounds="box" (the trainer's coordinates then are the quantities)
    opt: LMOptions
    counters: _Counters


@dataclass(frozen=True)
class _Outcome:
    """One iteration's trials: the accepted point, or the rule that stopped them (``stop``); ``mu`` the damping
    after them (with the trust radius: the radius); ``tiny`` whether the last step was below min_rel_step;
    ``rho`` the accepted step's gain ratio and ``step`` its scaled length (nan where none was accepted)."""

    stop: Stop | None
    point: _Point | None
    mu: float
    tiny: bool
    rho: float
    step: float


def _step(model: _Model, point: _Point, Ju, Js, A, g, gs, scale, mu: float) -> np.ndarray:
    """The damped step du at mu in the trainer's coordinates (:func:`.steps.scaled_system`'s system), held
    inside the box (bounds="box") and bent by geodesic acceleration (``geodesic`` > 0)."""
    opt, box = model.opt, model.box
    if scale is None:
        du = damped_step(Ju, point.e, A, g, mu)
    else:
        du = damped_step(Js, point.e, A, gs, mu) / scale
    if box is not None:
        solved = (Ju, A, g, np.ones_like(g)) if scale is None else (Js, A, gs, scale)
        du = feasible_step(point.x, du, box.lower, box.upper,
                           lambda held, value, s=solved, m=mu: held_step(*s, point.e, m, held, value))
    if opt.geodesic > 0 and model.residual is not None:
        def residual_at(u):
            return _call_residual(model.residual, model.bounds.to_external(u), model.counters)

        du = geodesic_step(residual_at, point, Ju, Js if scale is not None else Ju, A, scale, du, mu, opt.geodesic)
    return du


def _trials(model: _Model, point: _Point, Ju, A: np.ndarray, g: np.ndarray, mu: float, col: np.ndarray | None,
            last_step: float) -> _Outcome:
    """Raise mu (trainlm's or Nielsen's schedule), or shrink the trust radius ``mu`` (damping "trust"), until a
    trial step lowers the cost, at most ``max_mu_tries`` trials (``col``: the column scale D of ``scale="jac"``;
    ``last_step``: the scaled length of the last accepted step, inf before the first)."""
    opt, box = model.opt, model.box
    Ju, Js, A, gs, scale = scaled_system(Ju, A, g, col, point.e)
    x_norm = float(np.linalg.norm(point.x))
    nu = 2.0  # Nielsen's growth of mu on refusals in a row
    radius = mu if opt.damping == "trust" else None
    for tries in range(opt.max_mu_tries):
        if radius is not None:
            mu = mu_for_radius(A, g if scale is None else gs, radius)
        du = _step(model, point, Ju, Js, A, g, gs, scale, mu)
        u_t = point.u + du
        if box is not None:  # rounding must not carry x + theta (bound - x) past the bound
            u_t = np.clip(u_t, box.lower, box.upper)
        x_t = model.bounds.to_external(u_t)
        tiny = float(np.linalg.norm(x_t - point.x)) <= opt.min_rel_step * (opt.min_rel_step + x_norm)
        step_norm = float(np.linalg.norm(du if scale is None else du * scale))
        predicted = predicted_decrease(du, g, Ju) if opt.damping in ("nielsen", "trust") else math.nan
        if radius is not None:
            stop = stopping.rounding(tries, mu, predicted, point.cost)
            if stop is not None:
                return _Outcome(stop, None, radius, tiny, math.nan, math.nan)
        # a trial likely accepted is simulated with its Jacobian at once (trial_jacobian) instead of a residual now
        # and the Jacobian's simulation again once accepted: the first trial of an iteration, and with the trust
        # radius a trial after a refusal too (a quarter of the refused step: 5 of 5 accepted on the shooting
        # bench, L = 2500); not a step much longer than the last accepted one (the radius doubled after a good
        # gain ratio, or a longer Gauss-Newton step), which leaves where the model was last confirmed and was
        # refused more often than not (bench_shooting_iteration: 6 of 9), a refused Jacobian costing 2-3 residuals
        with_jac = opt.trial_jacobian and (tries == 0 if radius is None else not step_norm > LONG_STEP * last_step)
        trial = _try(model.fun, None if with_jac else model.residual, model.guard, u_t, x_t, point.cost,
                     model.counters)
        if trial is not None and opt.damping in ("nielsen", "trust"):
            # a model that predicted no decrease where the cost fell (rounding, or a geodesic bend) counts as good
            rho = (point.cost - trial.cost) / predicted if predicted > 0 and math.isfinite(predicted) else 1.0
        else:
            rho = math.nan
        if trial is not None:
            if radius is not None:
                radius = trust_accepted(radius, rho, step_norm)
                return _Outcome(None, trial, radius, tiny, rho, step_norm)
            return _Outcome(None, trial, mu, tiny, rho, step_norm)
        if tiny:  # the cost no longer decreases along steps at rounding level: converged
            return _Outcome(stopping.small_step(tiny), None, mu if radius is None else radius, tiny, rho, math.nan)
        if radius is not None:
            radius = 0.25 * step_norm
            continue
        if opt.damping == "nielsen":
            mu, nu = nielsen_refused(mu, nu, math.inf)
        else:
            mu = mu_refused(mu, opt.mu_inc, math.inf)  # no cap: past mu_max the run stops
        stop = stopping.mu_max(mu, opt)
        if stop is not None:
            return _Outcome(stop, None, mu, tiny, rho, math.nan)
    return _Outcome(stopping.max_mu_tries(), None, mu, False, math.nan, math.nan)


#: A trust-radius trial whose scaled step is longer than this many times the last accepted step's is simulated
#: without its Jacobian even with ``trial_jacobian`` (the radius doubles after a good gain ratio: such a step is
#: twice).
LONG_STEP = rules.value("long_step")


















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

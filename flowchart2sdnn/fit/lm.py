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

``J`` may be a ``scipy.sparse`` matrix: the multiple-shooting Jacobian (identify.shooting.multiple) has a dense block
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
from dataclasses import dataclass

import numpy as np

from .. import rules
from . import stopping
from .boxstep import feasible_step
from .damping import first_mu, mu_accepted, mu_refused, nielsen_accepted, nielsen_refused
from .evaluate import Counters, Point, call_fun, call_residual, cost_of, readonly, try_point
from .options import LMOptions, LMResult
from .steps import (
    TRUST_SHRINK,
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

# LMOptions, LMResult (options), damped_step, WideFirstCSR (steps), the status tables and gauss_newton_gain
# (stopping) keep their old address
__all__ = ["LMOptions", "LMResult", "levenberg_marquardt", "damped_step", "STATUS_MESSAGES", "CONVERGED_STATUSES",
           "WideFirstCSR", "CRAWL_DETAIL", "gauss_newton_gain"]


# ---------------------------------------------------------------------------------------------- front door
_DEFAULTS = LMOptions()  # frozen: one instance serves every call that gives none


def levenberg_marquardt(
    fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray] | None],
    x0: Sequence[float] | np.ndarray,
    names: Sequence[str],
    lower: Sequence[float] | np.ndarray | float | None = None,
    upper: Sequence[float] | np.ndarray | float | None = None,
    options: LMOptions = _DEFAULTS,
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
    counters = Counters()

    u = bounds.start(x0)
    x = bounds.to_external(u)
    first = call_fun(fun, x, n_params, counters)
    if first is None:
        return LMResult(
            x=readonly(x0),
            cost=math.inf,
            status="diverged_at_start",
            message=STATUS_MESSAGES["diverged_at_start"],
            iterations=0,
            cost_history=(),
            mu_history=(),
            jac=readonly(np.zeros((0, n_params))),
            residual=readonly(np.zeros(0)),
            nfev=counters.nfev,
            njev=counters.njev,
            names=names,
            mu=opt.mu0,
        )
    point = Point(u, x, first[0], first[1], cost_of(first[0]))
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
            if out.point is None:  # no trial lowered the cost; `stop` says which rule ended the trials
                state = (point, mu, costs, mus)
                break
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
        x=readonly(point.x),
        cost=point.cost,
        status=status,
        message=message,
        iterations=iteration,
        cost_history=tuple(float(c) for c in costs),
        mu_history=tuple(float(m) for m in mus),
        jac=readonly(point.J),
        residual=readonly(point.e),
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


def _first_mu(point: Point, bounds: Bounds, opt: LMOptions) -> float:
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
    counters: Counters


@dataclass(frozen=True)
class _Outcome:
    """One iteration's trials: the accepted point, or the rule that stopped them (``stop``); ``mu`` the damping
    after them (with the trust radius: the radius); ``tiny`` whether the last step was below min_rel_step;
    ``rho`` the accepted step's gain ratio and ``step`` its scaled length (nan where none was accepted)."""

    stop: Stop | None
    point: Point | None
    mu: float
    tiny: bool
    rho: float
    step: float


def _step(model: _Model, point: Point, Ju, Js, A, g, gs, scale, mu: float) -> np.ndarray:
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
            return call_residual(model.residual, model.bounds.to_external(u), model.counters)

        du = geodesic_step(residual_at, point, Ju, Js if scale is not None else Ju, A, scale, du, mu, opt.geodesic)
    return du


def _trials(model: _Model, point: Point, Ju, A: np.ndarray, g: np.ndarray, mu: float, col: np.ndarray | None,
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
        trial = try_point(model.fun, None if with_jac else model.residual, model.guard, u_t, x_t, point.cost,
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
            radius = TRUST_SHRINK * step_norm
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



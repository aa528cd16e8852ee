"""The optimizer runs behind identify(): the offline multi-start LM (with the learned curves' start), the
quasi-online runs, ``--shooting auto``'s second look, and the LM options an offline fit uses.

Each returns an :class:`Outcome` (the point, its status, the raw results behind it); :mod:`.run` turns it
into the typed answer with :mod:`.assemble`. Every start, serial or not, runs through an executor
(:class:`~flowchart2sdnn.executors.SerialExecutor` by default) and the one fitting function of :mod:`.workers`.
Never prints: progress goes through `progress(text, fraction)`.

Layer: identify (below it: fit, network, executors).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from ...executors import SerialExecutor
from ...fit.lm import LMOptions, LMResult
from ...fit.multistart import draw_starts, run_multistart
from ...notices import Notice
from ..assess.noise import noise_cost
from ..result import MultistartSummary
from ..settings import (
    CRAWL_DECREASE,
    CRAWL_ITERATIONS,
    CRAWL_NOISE,
    IDENTIFY_DAMPING,
    MIN_REL_COST_CHANGE,
    NEGLIGIBLE_GAIN,
    NEGLIGIBLE_PACE,
    PACE_ITERATIONS,
    IdentifySettings,
)
from ..shooting.auto import SUSPECT_PEAK, chaotic_at, second_look
from ..shooting.multiple import kept_stage
from .curvestart import curve_start
from .problem import Problem
from .workers import fit_start, fit_task, quasi_online_start, run_quasi_online_start, run_start

__all__ = ["Outcome", "lm_options", "with_second_look", "iteration_text", "recording", "fit_offline",
           "fit_online", "ONLINE_COST"]

ONLINE_COST = "mean window cost over the last K steps of each quasi-online run"


@dataclass(frozen=True, eq=False)
class Outcome:
    """What the optimizer left: the point, its status, and the raw results behind it."""

    x: np.ndarray
    status: str
    message: str
    interrupted: bool
    lm: LMResult | None = None
    online: object | None = None
    multistart: MultistartSummary | None = None
    multistart_warning: Notice | None = None
    curve_start: dict | None = None


def lm_options(settings: IdentifySettings, problem: Problem) -> LMOptions:
    """The LM options of an offline fit with these settings (benchmarks run LM exactly as identify does).

    With column scaling each physical parameter is damped by its own curvature and the learned curves' weights
    share one scale (see fit.lm.LMOptions.scale_groups).
    """
    # free-slope weights (the paper's neurons, a plain GDNN's) share one damping scale and need the transform's
    # geodesic steps; a tanh basis's output weights and linear term enter linearly and are damped like parameters
    linear_roles = ("v", "c")
    slopes = {w.name for w in problem.network.free_weights if w.role not in linear_roles}
    basis = {w.block for w in problem.network.free_weights if w.role == "a" and w.fixed}
    slopes |= {w.name for w in problem.network.free_weights if w.role == "v" and w.block not in basis}
    groups = tuple(-1 if n in slopes else i for i, n in enumerate(problem.names))
    learned = any(n in slopes for n in problem.names)
    curves = any(w.name in problem.names for w in problem.network.free_weights)
    bounds = settings.lm_bounds
    if bounds == "auto":  # the transform where learned curves are fitted (settings.LM_BOUNDS)
        bounds = "transform" if curves else "box"
    damping = settings.lm_damping
    if damping == "auto":  # trainlm's where learned curves are fitted (settings.IDENTIFY_DAMPING, LM_BOUNDS)
        damping = "trainlm" if learned else "trust" if bounds == "box" else IDENTIFY_DAMPING
    m = sum(s.targets.size for s in problem.segments)
    floor = noise_cost(problem, CRAWL_NOISE) * m  # the cost E at CRAWL_NOISE x the noise RMS
    return LMOptions(max_iter=settings.max_iter, min_rel_cost_change=MIN_REL_COST_CHANGE, tau=settings.lm_tau,
                     stall_decrease=settings.converged_decrease / max(1, problem.n_residuals),
                     crawl_decrease=CRAWL_DECREASE / max(1, problem.n_residuals) if floor > 0 else 0.0,
                     crawl_iterations=CRAWL_ITERATIONS, crawl_cost=floor, negligible_gain=NEGLIGIBLE_GAIN,
                     negligible_pace=NEGLIGIBLE_PACE, pace_iterations=PACE_ITERATIONS,
                     residual_stride=len(problem.compiled.output_names),
                     scale=settings.lm_scale, scale_groups=groups if settings.lm_scale == "jac" else (),
                     geodesic=settings.lm_geodesic if bounds == "transform" else 0.0, damping=damping,
                     trial_jacobian=damping in ("nielsen", "trust"), bounds=bounds)


def with_second_look(problem: Problem, x0, lower, upper, settings: IdentifySettings, starts: str, auto, out: Outcome,
                 progress, stop, executor):
    """(outcome, settings, auto): single shooting's when auto's second look (identify.shooting.auto.second_look) does
    not apply or multiple shooting does no better per sample, else multiple shooting's."""
    length = second_look(problem, auto, out.lm.cost)
    if length is None:
        return out, settings, auto
    m = max(1, sum(s.targets.size for s in problem.segments))
    again_settings = replace(settings, shooting=length, shooting_starts="free" if starts == "auto" else starts)
    again = fit_offline(problem, x0, lower, upper, again_settings, progress, stop, executor)
    if again.interrupted:  # Ctrl-C during the retry: its point so far, as any interrupted fit
        return again, again_settings, auto
    kept = kept_stage(again.lm.stages) if again.lm is not None and again.lm.stages else None
    per = kept["cost_per_sample"] if kept is not None else None
    better = per is not None and per < out.lm.cost / m
    segmented = better and kept is not again.lm.stages[-1]
    chaos = chaotic_at(problem, np.asarray(again.x, dtype=float)) if segmented else None
    reason = (f"single shooting ended off the noise floor on a chart whose moved start grew {auto.peak:.3g}-fold "
              f"(> {SUSPECT_PEAK:g}): tried again in segments of {length} samples")
    if chaos is False:  # a short stage kept, but the chart at its fit forgets a moved start: not chaos
        better = False
        reason += ("; its segmented stage was kept but the chart at that fit is not chaotic (a moved start does "
                   "not grow 1000-fold): single shooting kept")
    look = {"single_shooting_cost_per_sample": out.lm.cost / m, "length": length,
            "starts": again_settings.shooting_starts, "cost_per_sample": per, "chaotic_at_fit": chaos,
            "kept": "multiple shooting" if better else "single shooting", "reason": reason}
    auto = replace(auto, second_look=look)
    return (again, again_settings, auto) if better else (out, settings, auto)


def iteration_text(it: int, cost: float, before: float = math.nan) -> str:
    """The progress line of an LM iteration: its number, the cost, and the cost's fall since `before` (the
    cost last reported) in percent, e.g. ``LM iteration 12: cost 3.410e-02, -12 %``."""
    text = f"LM iteration {it}: cost {cost:.3e}"
    if math.isfinite(before) and before > 0:
        text += f", {100 * (cost - before) / before:+.2g} %"
    return text


def recording(cutoff, reasons: list[str]):
    """`cutoff` that also keeps the reason it gave in `reasons` (how identify tells a cut-off from Ctrl-C)."""
    if cutoff is None:
        return None

    def check(it: int, cost: float) -> bool:
        why = cutoff(it, cost)
        if why:
            reasons.append(why)
        return bool(why)
    return check


def fit_offline(problem: Problem, x0, lower, upper, settings: IdentifySettings, progress, stop, executor,
             cutoff=None) -> Outcome:
    options = lm_options(settings, problem)
    shooting = 0 if settings.shooting == "off" else settings.shooting

    last = [0, math.nan]  # the iteration and cost reported last: the line shows the cost's fall since then

    def callback(it, x, cost, mu):
        if progress:
            before = last[1] if it > last[0] else math.nan  # a lower count: the next start (or fit) began
            last[:] = [it, cost]
            progress(iteration_text(it, cost, before), None)  # no fraction: max_iter is a limit, not the goal
        if cutoff is not None and cutoff(it, cost):
            return True
        return bool(stop and stop())

    warm = None
    if settings.curve_start == "stick":  # learned curves in a loop: a stick-slip step and a brief fit first
        warm = curve_start(problem, x0, lower, upper, options, callback=callback if executor is None else None)
    if warm is not None and warm.stopped is not None:  # Ctrl-C during the curves' brief fits
        lm = warm.stopped
        return Outcome(np.asarray(lm.x, dtype=float), lm.status, lm.message, True, lm=lm,
                        curve_start=warm.to_dict())
    if warm is not None and warm.curves:
        starts = draw_starts(problem.names, warm.template, lower, upper, settings.starts, settings.seed,
                             ranges=settings.ranges or None)
        starts[0] = warm.x
    else:
        starts = draw_starts(problem.names, x0, lower, upper, settings.starts, settings.seed,
                             ranges=settings.ranges or None)
    if executor is None:  # in this process: progress and Ctrl-C after every LM iteration
        fit_one = functools.partial(run_start, problem, lower=lower, upper=upper, options=options,
                                    callback=callback, shooting=shooting, threads=settings.threads,
                                    shooting_starts=settings.shooting_starts)
    else:
        fit_one = functools.partial(fit_start, fit_task(problem, lower, upper, options, shooting,
                                                        settings.shooting_starts))

    def start_done(i, result):
        if progress and settings.starts > 1:
            progress(f"start {i + 1}/{settings.starts}: cost {result.cost:.6g} ({result.status})",
                     (i + 1) / settings.starts)
        return bool(stop and stop())

    ms = run_multistart(fit_one, starts, callback=start_done, executor=executor or SerialExecutor())
    best = ms.best
    interrupted = ms.interrupted or best.interrupted
    summary = _summary(ms, problem.names if settings.starts > 1 else None)
    return Outcome(np.asarray(best.x, dtype=float), "interrupted" if interrupted else best.status, best.message,
                    interrupted, lm=best, multistart=summary,
                    multistart_warning=_minima(ms) if settings.starts > 1 and ms.local_minima else None,
                    curve_start=warm.to_dict() if warm is not None and warm.curves else None)


def fit_online(problem: Problem, x0, lower, upper, settings: IdentifySettings, progress, stop, executor) -> Outcome:
    """Quasi-online from x0, or from `settings.starts` seeded starts.

    With several starts each run is a whole quasi-online pass; the one with the lowest mean window cost at
    the end of the record (the paper's error of a run) is reported, as a bank of online estimators would.
    """
    from ..online.run import OnlineOptions

    opts = OnlineOptions(window=min(settings.window, len(problem.inputs)),
                         average=settings.average, every=settings.every, start=settings.online_start)
    n = settings.starts

    def run_one(start: np.ndarray, label: str = "quasi-online"):
        return run_quasi_online_start(problem, start, lower, upper, opts,
                                callback=lambda f: _online_tick(progress, stop, f, label))

    if n == 1:
        best = run_one(x0).result
        return Outcome(np.asarray(best.theta_mean, dtype=float), best.status, best.message,
                        best.status == "interrupted", online=best)
    starts = draw_starts(problem.names, x0, lower, upper, n, settings.seed, ranges=settings.ranges or None)
    if executor is None:  # in this process: progress and Ctrl-C after every LM iteration
        counter = iter(range(1, n + 1))  # serial runs come in start order

        def fit_one(start: np.ndarray):
            return run_one(start, f"quasi-online, start {next(counter)}/{n}")
    else:
        fit_one = functools.partial(quasi_online_start, fit_task(problem, lower, upper, opts))

    def start_done(i, run):
        if progress:
            progress(f"start {i + 1}/{n}: mean window cost {run.cost:.6g} ({run.status})", (i + 1) / n)
        return bool(stop and stop())

    ms = run_multistart(fit_one, starts, callback=start_done, executor=executor or SerialExecutor())
    best = ms.best.result
    if ms.interrupted and best.status not in ("interrupted", "callback_stop"):
        best = replace(best, status="interrupted",
                       message="interrupted: the best of the runs finished so far is returned")
    return Outcome(np.asarray(best.theta_mean, dtype=float), best.status, best.message,
                    best.status == "interrupted", online=best, multistart=_summary(ms, problem.names, ONLINE_COST),
                    multistart_warning=_minima(ms) if ms.local_minima else None)


def _minima(ms) -> Notice:
    """The warning of starts that ended in different minima (the multi-start summary's sentence)."""
    costs = [float(c) for c in ms.costs]
    return Notice("CONV003", ms.message,
                  {"runs": len(ms.results), "best": ms.best_index, "cost": costs[ms.best_index],
                   "local_minima": list(ms.local_minima),
                   "local_costs": [costs[k] for k in ms.local_minima]},
                  "the best run is the result; compare its parameters with the others' (RESULT.json multistart)")


def _summary(ms, names, cost: str | None = None) -> MultistartSummary:
    """The multi-start summary; ``names`` are given with several starts."""
    s = ms.summary()
    return MultistartSummary(s["n"], s["best_index"], tuple(s["costs"]), tuple(s["near_best"]),
                             tuple(s["local_minima"]), tuple(s["diverged"]), tuple(tuple(r) for r in s["starts"]),
                             s["message"], tuple(names) if names is not None else None, cost)


def _online_tick(progress, stop, fraction: float, label: str = "quasi-online") -> bool:
    if progress:
        progress(label, fraction)
    return bool(stop and stop())

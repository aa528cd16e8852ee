"""identify(): fit a chart's physical parameters and learned curves to measured data.

Offline: Levenberg-Marquardt (eq. 11) on the cost of eq. (4) with the exact RTRL Jacobian, from one or several
seeded starts. Quasi-online (paper section 3.1): LM iterations on a sliding window as the record streams by,
the estimate the mean over the last K steps; with several starts, the run with the lowest final window cost.
Either way the answer is a typed :class:`~flowchart2sdnn.identify.result.Identification` with uncertainty, fit
metrics and everything needed to reproduce the run. Never prints: progress goes through
`progress(text, fraction)`.

Every start, serial or not, runs through an executor (:class:`~flowchart2sdnn.executors.SerialExecutor` by
default) and the one fitting function of :mod:`flowchart2sdnn.identify.offline.workers`.

Layer: identify (below it: simulate's oracle, fit, network, compiler, data, diagram, executors).
"""

from __future__ import annotations

import functools
import math
import platform
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..._version import __version__
from ...analysis.loops import delay_rule
from ...compiler.substeps import AUTO_CAP, requested_substeps
from ...data.csvdata import Dataset
from ...diagram.dump import with_values
from ...diagram.model import Diagram
from ...errors import SdnnError
from ...executors import SerialExecutor
from ...fit.lm import CONVERGED_STATUSES, CRAWL_DETAIL, LMOptions, LMResult
from ...fit.multistart import draw_starts, run_multistart
from ...notices import Notice, messages
from ..assess.evidence import (
    assess,
    no_excitation_message,
    on_bound_warnings,
    sqrt_domain_warnings,
    start_stability,
)
from ..assess.floor import FLOOR_WARN, floor_warnings, measure_floor, oracle_runs
from ..assess.floorbias import estimate_floor_bias, floor_bias_warnings
from ..assess.noise import noise_cost
from ..result import (
    ChartSource,
    Curve,
    DataInfo,
    Estimate,
    Fit,
    Identification,
    Metrics,
    MultistartSummary,
    OnlineTrace,
    OptimizerTrace,
    RecordInfo,
)
from ..settings import (
    CRAWL_DECREASE,
    CRAWL_ITERATIONS,
    CRAWL_NOISE,
    FAR_ABOVE_NOISE,
    HELD_CHATTER,
    IDENTIFY_DAMPING,
    MIN_REL_COST_CHANGE,
    NEGLIGIBLE_GAIN,
    NEGLIGIBLE_PACE,
    PACE_ITERATIONS,
    IdentifySettings,
)
from ..shooting.auto import SUSPECT_PEAK, chaotic_at, choose_shooting, second_look
from ..shooting.multiple import kept_stage
from .curvestart import curve_start
from .initstate import estimate_initial_state
from .perrecord import per_record_estimates
from .problem import Problem, build_problem, combined_metrics, data_init, metrics
from .workers import fit_start, fit_task, quasi_online_start, run_quasi_online_start, run_start

__all__ = ["IdentifySettings", "Identification", "identify", "lm_options", "with_floor_bias"]

_ONLINE_COST = "mean window cost over the last K steps of each quasi-online run"


@dataclass(frozen=True, eq=False)
class _Outcome:
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


@np.errstate(all="ignore")  # a diverging trial is expected and handled: no RuntimeWarnings on stderr
def identify(diagram: Diagram, train: Dataset | Sequence[Dataset], validation: Dataset | None = None,
             settings: IdentifySettings | None = None,
             progress: Callable[[str, float | None], None] | None = None,
             executor=None, stop: Callable[[], bool] | None = None,
             cutoff: Callable[[int, float], str | None] | None = None, **options) -> Identification:
    """Identify the chart's free quantities from `train`; see the module docstring.

    Settings come as an :class:`IdentifySettings` or as its fields by name (``starts=4, max_iter=300``; those
    override the fields of `settings`); a bad value raises ValueError naming the setting.

    `executor` (a :mod:`flowchart2sdnn.executors` executor, optional) runs the multi-start fits in worker
    processes or on a Dask cluster; the result is the same as without it (progress then comes per start).
    `stop` (optional) is polled after each LM iteration, start and online chunk; when it returns True the
    run ends early with status "interrupted" and the best point so far (the CLI's Ctrl-C).
    `cutoff` (optional, offline fits) is called as ``cutoff(iteration, cost)`` after each LM iteration; when it
    returns a reason the fit ends there with status "cut_off" and that reason as its message (diagnose's brief
    refits that can no longer reach the round's best).
    Several training records (a sequence) are fitted together, each simulated from its own initial state.
    """
    settings = settings or IdentifySettings()
    if options:
        unknown = sorted(set(options) - set(IdentifySettings.__dataclass_fields__))
        if unknown:
            raise TypeError(f"identify() got unknown settings: {', '.join(unknown)}")
        settings = replace(settings, **options)
    records = [train] if isinstance(train, Dataset) else list(train)
    if not records:
        raise ValueError("identify needs at least one training record")
    train, more = records[0], records[1:]
    if more and (settings.split is not None or settings.online):
        raise SdnnError.at("DATA003", "several training records cannot be combined with --split or --online (yet)",
                           more[0].path, hint="give one record, or drop that option")
    full = train
    if settings.split is not None:
        if validation is not None:
            raise ValueError("give either a validation record or a split, not both")
        train = full.slice(0, max(3, int(round(settings.split * train.n_rows))))
    problem = build_problem(diagram, train, settings.alignment, settings.seed, more=more)
    if settings.online and problem.compiled.estimates_starts:
        raise SdnnError.at("FIT004", "quasi-online identification cannot estimate initial states (init: estimate, "
                           "or init: <parameter>): its window forgets the record's start", diagram.file,
                           hint="identify offline, or give the integrator a number as init")
    x0 = problem.expand(problem.compiled.theta0())  # every record's own value starts at the chart's
    problem, warnings = start_stability(problem, x0)
    lower, upper = problem.bounds()
    warnings += on_bound_warnings(problem.names, x0, lower, upper)
    start_warnings = tuple(warnings)  # about the user's start: a refit from the fit's values keeps them

    auto, requested_shooting = None, settings.shooting
    if settings.shooting == "auto":  # the rule reads the records (identify.shooting.auto); the window has no shooting
        auto = choose_shooting(problem, x0) if problem.names and not settings.online else None
        settings = replace(settings, shooting=auto.length or "off" if auto is not None else "off")
    starts = settings.shooting_starts
    if starts == "auto":  # free on the records auto found chaotic (identify.settings)
        settings = replace(settings, shooting_starts="free" if auto is not None and auto.length else "data")
    if not problem.names:
        out = _Outcome(x0, "nothing_to_fit", "every parameter and curve is fixed; only the fit was evaluated", False)
    elif settings.online:
        out = _online(problem, x0, lower, upper, settings, progress, stop, executor)
    else:
        cut: list[str] = []
        out = _offline(problem, x0, lower, upper, settings, progress, stop, executor, _recording(cutoff, cut))
        if cut:
            out = replace(out, status="cut_off", message=f"cut off: {cut[0]}", interrupted=False)
        if auto is not None and out.lm is not None and not out.interrupted:
            out, settings, auto = _second_look(problem, x0, lower, upper, settings, starts, auto, out, progress,
                                               stop, executor)
    if out.multistart_warning:
        warnings.append(out.multistart_warning)
    shooting = _shooting(settings, out.lm, auto) if settings.shooting != "off" or auto is not None else None
    if shooting and shooting.get("predictable") is False:
        warnings.append(Notice("SHOOT001", shooting["note"], {"final_length": shooting["final_length"]},
                               f"validate the fit on horizons of up to {shooting['final_length']} samples "
                               f"(`sdnn compare --horizon {shooting['final_length']}`)"))
    x, status, message, interrupted = out.x, out.status, out.message, out.interrupted
    if status == "callback_stop" or message.startswith("stopped by the callback"):  # `stop`: the CLI's Ctrl-C
        status, interrupted = "interrupted", True
        message = "interrupted (Ctrl-C); the best point so far is returned" + _detail(message)

    evidence = assess(problem, x, diverged=status == "diverged_at_start")
    if evidence.no_excitation and not interrupted:  # nothing was identified: report the start values exactly
        status, message, x = "no_excitation", no_excitation_message(problem), x0
    converged = None if out.lm is None or status == "no_excitation" else status in CONVERGED_STATUSES
    if converged is False and not interrupted:
        warnings.append(Notice("CONV001", f"not converged: {message}; the parameters may be far from the minimum "
                               "(raise max_iter, or start closer)", {"status": status, "max_iter": settings.max_iter},
                               "raise max_iter, or start closer"))
    if converged and CRAWL_DETAIL in message:
        gain = message.split(CRAWL_DETAIL + ": ", 1)[-1].rstrip(")")  # "<fraction> of the cost over the last N ..."
        warnings.append(Notice("CONV002", f"converged at the noise floor while still creeping ({gain}): the fit "
                               "moves along a direction the data barely determine; read the parameters with their "
                               "ci95 and correlations", {"creep": gain},
                               "read the parameters with their ci95 and correlations"))
    warnings.extend(evidence.warnings)
    if status != "diverged_at_start":
        warnings.extend(sqrt_domain_warnings(problem, x))

    # x holds every record's own value of a per-record parameter; the chart and the rest see their mean
    xs, x = x, problem.mean_x(x)
    per_record, means = per_record_estimates(problem, xs, evidence, [d.path for d in [train] + more])
    params, _ = problem.compiled.values(x)
    curves = _curves(problem, x)
    index = {n: i for i, n in enumerate(problem.names)}
    parameters = {}
    for p in diagram.parameters:
        i = index.get(p.name)
        stderr = ci = None
        if p.name in means:
            _, stderr, ci = means[p.name]
        elif i is not None and evidence.stderr is not None and np.isfinite(evidence.stderr[i]):
            stderr, half = float(evidence.stderr[i]), float(evidence.half[i])
            ci = (float(params[p.name] - half), float(params[p.name] + half))
        parameters[p.name] = Estimate(float(params[p.name]), float(p.init), stderr, ci, p.unit, i is None, ci)

    chart = _resolved(with_values(diagram, params, curves), problem.network)
    fit, state = _fit(problem, xs, settings, train, more, full, validation)
    if out.lm is not None and not interrupted and status not in ("no_excitation", "diverged_at_start") and not (
            shooting and shooting.get("predictable") is False):  # an unpredictable chart already says so
        warnings.extend(_far_above_noise(problem, fit.train.cost))
    disc = discretization(diagram, problem.network)
    if status == "diverged_at_start":
        disc["floor"] = {"rms": None, "skipped": "the fit diverged at its start"}
    else:
        records = [train] + more
        try:  # the floor and the bias both compare with this run: simulate it once
            oracle = oracle_runs(chart, records, settings.alignment, problem.compiled)
        except (ValueError, KeyError):  # each reports the oracle's refusal as skipped
            oracle = None
        disc["floor"] = measure_floor(chart, problem.compiled, x, [(d, 0) for d in records], settings.alignment,
                                      oracle)
        # on records a free run cannot follow (multiple shooting kept) the floor measures the chaos, not the step
        finer = (_finer_substeps(diagram, problem, disc["floor"], fit.train.rms, out, status)
                 if settings.shooting == "off" else None)
        if finer is not None:  # auto's N read at the init is too coarse for what the data made of the chart
            given = full if settings.split is not None else (records if more else train)
            again = identify(replace(with_values(diagram, params, curves), substeps=finer), given, validation,
                             replace(settings, shooting=requested_shooting), progress, executor, stop)
            note = Notice("FLOOR002", f"substeps auto: N = {problem.network.substeps}, read at the chart's init, is "
                          f"too coarse for the fitted curves (the network's step error above {FLOOR_WARN:g}x the "
                          f"residual, or a mode held at the step's stability limit); refitted from that fit at N = "
                          f"{finer}", {"substeps": problem.network.substeps, "refitted_at": finer,
                                       "warn_at": FLOOR_WARN},
                          f"write `substeps: {finer}` (or more) in the chart to fit at once")
            inits = {p.name: float(p.init) for p in diagram.parameters}
            again_params = {n: replace(e, init=inits.get(n, e.init)) for n, e in again.parameters.items()}
            first = {"substeps": problem.network.substeps, "iterations": out.lm.iterations, "cost": float(out.lm.cost),
                     **({"then": again.extra["substeps_refit"]} if "substeps_refit" in again.extra else {})}
            disc_again = {**again.extra.get("discretization", {}), "requested": disc.get("requested")}
            kept = (note,) + start_warnings + tuple(w for w in again.notices if w not in start_warnings)
            return replace(again, parameters=again_params, warnings=messages(kept), notices=kept,
                           source=ChartSource(diagram.name, diagram.file, diagram.source_sha256),
                           extra={**again.extra, "discretization": disc_again, "substeps_refit": first})
        warnings.extend(floor_warnings(disc["floor"], fit.train.rms, diagram, problem.network))
        if settings.floor_bias and out.lm is not None and not interrupted and status != "no_excitation":
            free = {n: e for n, e in parameters.items() if not e.fixed and n not in means}
            disc["bias"], parameters, bias_warnings = _floor_bias(problem, chart, xs, records, settings, parameters,
                                                                  free, oracle)
            warnings.extend(bias_warnings)
    return Identification(
        status=status, message=message, interrupted=bool(interrupted), converged=converged, parameters=parameters,
        curves={b: Curve(tuple(c["a"]), tuple(c["v"]), tuple(c["b"]) if "b" in c else None, c["fixed"],
                         c.get("c"))
                for b, c in curves.items()},
        fit=fit, warnings=messages(warnings), notices=tuple(warnings), settings=settings, chart=chart,
        source=ChartSource(diagram.name, diagram.file, diagram.source_sha256),
        data=DataInfo(_record(full if settings.split is not None else train),
                      tuple(_record(d) for d in ([full] if settings.split is not None else [train] + more)),
                      _record(validation) if validation is not None else None),
        versions=_versions(),
        optimizer=_trace(out.lm) if out.lm is not None else None,
        multistart=out.multistart, uncertainty=evidence.uncertainty,
        online=_online_trace(out.online, problem.names, settings) if out.online is not None else None,
        problem=problem, x=x, lm=out.lm, online_run=out.online,
        extra={"discretization": disc,
               **({"shooting": shooting} if shooting else {}),
               **({"curve_start": out.curve_start} if out.curve_start else {}),
               **({"initial_states": {"validation": state.to_dict()}} if state is not None else {}),
               **({"parameters_per_record": per_record} if per_record else {})},
    )


def _finer_substeps(diagram: Diagram, problem: Problem, floor: dict, rms: dict, out: _Outcome,
                    status: str) -> int | None:
    """N x 4 (at most AUTO_CAP) when `substeps` is auto and, after a finished fit, the network's step error (the
    floor) exceeds FLOOR_WARN of the training residual on an output, or the fitted network's alternating mode at
    rest keeps more than HELD_CHATTER of its amplitude a step (a curve held by the scheme); else None."""
    if requested_substeps(diagram) not in (None, "auto") or out.lm is None or out.interrupted:
        return None
    if status not in CONVERGED_STATUSES or not floor.get("rms"):  # only a fit at its minimum says what N it needs
        return None
    n = problem.network.substeps
    if n >= AUTO_CAP:
        return None
    over = any(r is not None and rms.get(k) and r > FLOOR_WARN * rms[k] for k, r in floor["rms"].items())
    held = problem.stability(out.x)[0] > HELD_CHATTER
    return min(AUTO_CAP, 4 * n) if over or held else None


def _far_above_noise(problem: Problem, cost: float | None) -> list[Notice]:
    """The warning of a free-run training cost whose RMS is more than FAR_ABOVE_NOISE x the records' noise."""
    m = sum(s.targets.size for s in problem.segments)
    floor = noise_cost(problem, 1.0) * m  # the cost of a residual at the noise
    if cost is None or not floor > 0 or not cost > FAR_ABOVE_NOISE ** 2 * floor:
        return []
    ratio = math.sqrt(cost / floor)
    return [Notice("NOISE001", f"the training residual RMS is {ratio:.3g}x the noise read off the records' second "
                   f"differences (a complete chart at its minimum ends within about {FAR_ABOVE_NOISE:g}x): the chart "
                   "may lack an effect (try `sdnn diagnose`) or the fit may sit in a local minimum (try --starts 8, "
                   "or `init` values closer to the machine)", {"ratio": ratio, "warn_at": FAR_ABOVE_NOISE},
                   "try `sdnn diagnose`, or --starts 8, or `init` values closer to the machine")]


def with_floor_bias(ident: Identification, train: Sequence[Dataset]) -> Identification:
    """`ident` (an offline fit made with ``floor_bias`` off) with the discretization-bias analysis identify runs by
    default (:func:`~flowchart2sdnn.identify.assess.floorbias.estimate_floor_bias`) at its point, which stays as it is:
    RESULT.json's `discretization.bias`, ci95 widened by |beta| (ci95_noise unchanged) and the warning naming
    the parameters shifted by more than half a standard error. `train`: the records `ident` was fitted on, in
    order. Unchanged where the analysis does not apply (no offline fit, or already done)."""
    disc = dict(ident.extra.get("discretization") or {})
    problem = ident.problem
    if problem is None or ident.x is None or ident.chart is None or ident.lm is None or "bias" in disc:
        return ident
    free = {n: e for n, e in ident.parameters.items() if not e.fixed and n in problem.names}
    disc["bias"], parameters, bias_warnings = _floor_bias(problem, ident.chart, ident.x, list(train), ident.settings,
                                                          ident.parameters, free)
    notices = ident.notices + tuple(bias_warnings)
    return replace(ident, parameters=parameters, warnings=messages(notices), notices=notices,
                   settings=replace(ident.settings, floor_bias=True),
                   extra={**ident.extra, "discretization": disc})


def _floor_bias(problem: Problem, chart, x, records: list, settings: IdentifySettings, parameters: dict, free: dict,
                oracle=None) -> tuple[dict, dict, list[Notice]]:
    """(RESULT.json's `discretization.bias`, `parameters` with the reported ci95 covering the noise and the
    discretization's shift (ci95_noise keeps the former), the warnings) at the fitted point x."""
    lower, upper = problem.bounds()
    bias = estimate_floor_bias(problem, chart, x, records, lower, upper, lm_options(settings, problem),
                               {n: (e.value, e.stderr, e.ci95) for n, e in free.items()}, oracle)
    parameters = dict(parameters)
    for n, ci in (bias.get("widened") or {}).items():
        if ci is not None:
            parameters[n] = replace(parameters[n], ci95=(float(ci[0]), float(ci[1])))
    return bias, parameters, floor_bias_warnings(bias, {n: e.stderr for n, e in free.items()})


def discretization(diagram, network) -> dict:
    """RESULT.json's `discretization`: the sub-steps asked for and used, the step, the delay rule (identify adds
    `floor`, the network against the continuous chart: :mod:`flowchart2sdnn.identify.assess.floor`)."""
    return {"substeps": network.substeps, "requested": diagram.substeps, "sample_time": network.sample_time,
            "step": network.step, "delays": delay_rule(diagram)}


def _shooting(settings: IdentifySettings, lm: LMResult | None, auto=None) -> dict:
    """RESULT.json's `shooting`: the segment length used (`auto`: what the rule chose and why), the best start's
    stages, and which stage's fit is the result (`final_length`; `predictable` false when a merge was refused:
    a chaotic record, validated on short horizons only; identify.shooting.multiple)."""
    stages = [{k: None if isinstance(v, float) and not np.isfinite(v) else v for k, v in s.items()}
              for s in lm.stages] if lm is not None else []  # a diverged stage's cost is inf: JSON has no inf
    out = {"length": settings.shooting, "requested": "auto" if auto is not None else settings.shooting,
           "starts": settings.shooting_starts,
           **({"auto": auto.to_dict()} if auto is not None else {}), "stages": stages,
           "method": "multiple shooting, segments merged x4, continuity weight x10 per stage, then single "
                     "shooting over whole records (the result, unless it costs more than 1.44x per sample than "
                     "the last accepted stage while that stage is within 2x the noise: then that stage; a "
                     "stage refused so is passed over)"}
    kept = kept_stage(stages)
    if kept is not None:
        out["final_length"] = kept["length"]
        out["predictable"] = kept is stages[-1]
        if not out["predictable"]:
            out["note"] = (f"multiple shooting: a free run of the fitted chart does not follow the whole records "
                           f"(merging segments of {kept['length']} samples raised the cost per sample "
                           f"{_rise(stages[-1], kept)}); the parameters come "
                           f"from the stage with segments of {kept['length']} samples, and the fit is "
                           f"validated on horizons of up to {kept['length']} samples only (the training and "
                           f"validation RMS of whole-record free runs are not its measure)")
    return out


def _rise(stage: dict, kept: dict) -> str:
    """How much costlier per sample the whole-record stage was than the kept one (for the note)."""
    a, b = stage.get("cost_per_sample"), kept.get("cost_per_sample")
    return f"{a / b:.3g}x" if a is not None and b else "beyond floating point: it diverged"


def _resolved(chart, network):
    """The identified chart naming the network it was fitted with: `substeps: auto` (given or by default)
    replaced by the N used (auto depends on the parameter values) and the delay rule written out (a default may
    change; the identified values belong to this network)."""
    if chart.substeps in (None, "auto"):
        chart = replace(chart, substeps=network.substeps)
    return chart if chart.delays is not None else replace(chart, delays=delay_rule(chart))


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


def _second_look(problem: Problem, x0, lower, upper, settings: IdentifySettings, starts: str, auto, out: _Outcome,
                 progress, stop, executor):
    """(outcome, settings, auto): single shooting's when auto's second look (identify.shooting.auto.second_look) does
    not apply or multiple shooting does no better per sample, else multiple shooting's."""
    length = second_look(problem, auto, out.lm.cost)
    if length is None:
        return out, settings, auto
    m = max(1, sum(s.targets.size for s in problem.segments))
    again_settings = replace(settings, shooting=length, shooting_starts="free" if starts == "auto" else starts)
    again = _offline(problem, x0, lower, upper, again_settings, progress, stop, executor)
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


def _recording(cutoff, reasons: list[str]):
    """`cutoff` that also keeps the reason it gave in `reasons` (how identify tells a cut-off from Ctrl-C)."""
    if cutoff is None:
        return None

    def check(it: int, cost: float) -> bool:
        why = cutoff(it, cost)
        if why:
            reasons.append(why)
        return bool(why)
    return check


def _offline(problem: Problem, x0, lower, upper, settings: IdentifySettings, progress, stop, executor,
             cutoff=None) -> _Outcome:
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
        return _Outcome(np.asarray(lm.x, dtype=float), lm.status, lm.message, True, lm=lm,
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
    return _Outcome(np.asarray(best.x, dtype=float), "interrupted" if interrupted else best.status, best.message,
                    interrupted, lm=best, multistart=summary,
                    multistart_warning=_minima(ms) if settings.starts > 1 and ms.local_minima else None,
                    curve_start=warm.to_dict() if warm is not None and warm.curves else None)


def _online(problem: Problem, x0, lower, upper, settings: IdentifySettings, progress, stop, executor) -> _Outcome:
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
        return _Outcome(np.asarray(best.theta_mean, dtype=float), best.status, best.message,
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
    return _Outcome(np.asarray(best.theta_mean, dtype=float), best.status, best.message,
                    best.status == "interrupted", online=best, multistart=_summary(ms, problem.names, _ONLINE_COST),
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


def _fit(problem: Problem, x, settings: IdentifySettings, train: Dataset, more: list[Dataset], full: Dataset,
         validation: Dataset | None):
    """(Fit, the validation record's fitted initial state or None). `x` holds each training record's own
    values of the per-record parameters; a validation record runs with their mean, or with its own values
    fitted on its initial-state window."""
    xs, x = x, problem.mean_x(x)
    train_m = metrics(problem.compiled, problem.record_x(xs, 0), train, settings.alignment)
    if more:
        per_record = [train_m] + [metrics(problem.compiled, problem.record_x(xs, k), d, settings.alignment)
                                  for k, d in enumerate(more, start=1)]
        train_m = combined_metrics(per_record, problem, xs, [train] + more, settings.alignment)
    val = None
    if settings.split is not None:
        val = metrics(problem.compiled, x, full, settings.alignment, score_from=train.n_rows)
        val["note"] = "free run over the whole record, scored after the split"
    elif validation is not None and settings.init_window:
        state = estimate_initial_state(problem.compiled, x, validation, settings.alignment, settings.init_window,
                                       data_init(problem.network, validation), params=problem.record_params)
        val = metrics(problem.compiled, state.theta, validation, settings.alignment, score_from=settings.init_window,
                      history=state.history)
        val["note"] = (f"free run from the initial state fitted on the first {settings.init_window} samples, "
                       f"scored from row {settings.init_window}")
        return Fit(_metrics(train_m), _metrics(val)), state
    elif validation is not None:
        val = metrics(problem.compiled, x, validation, settings.alignment)
    return Fit(_metrics(train_m), None if val is None else _metrics(val)), None


def _metrics(d: dict) -> Metrics:
    records = d.get("records")
    return Metrics(d["rows"], d["cost"], d["rms"], d["fit_percent"],
                   None if records is None else tuple(_metrics(r) for r in records), d.get("note"))


def _curves(problem: Problem, x: np.ndarray) -> dict[str, dict]:
    """Learned curve weights per block, as the chart writer takes them: {"a": [...], "v": [...], "b"?: [...]}."""
    _, free = problem.compiled.values(x)
    out: dict[str, dict] = {}
    for fw in problem.network.free_weights:
        if fw.block is None or fw.role is None:
            continue
        entry = out.setdefault(fw.block, {"a": [], "v": [], "b": [], "fixed": True})
        entry["fixed"] = entry["fixed"] and fw.fixed  # a basis's fixed slopes leave the curve learned
        if fw.role == "c":
            entry["c"] = float(free[fw.name])
        else:
            entry[fw.role].append(float(free[fw.name]))
    for entry in out.values():
        if not entry["b"]:
            del entry["b"]
    return out


def _trace(lm: LMResult) -> OptimizerTrace:
    return OptimizerTrace(lm.iterations, tuple(lm.cost_history), lm.nfev, lm.njev, lm.rejected_cost,
                          lm.rejected_diverged, lm.rejected_guard)


def _online_trace(run, names, settings: IdentifySettings) -> OnlineTrace:
    return OnlineTrace(
        window=settings.window, average=settings.average, every=settings.every, steps=int(run.steps),
        mean_cost=float(run.mean_cost), final={n: float(v) for n, v in zip(names, run.theta_final, strict=True)},
        trajectory_time=tuple(float(t) for t in run.trajectory_time),
        trajectories={n: tuple(float(v) for v in run.trajectory[:, i]) for i, n in enumerate(names)},
        cost_time=tuple(float(t) for t in run.cost_time), cost=tuple(float(c) for c in run.cost))


def _online_tick(progress, stop, fraction: float, label: str = "quasi-online") -> bool:
    if progress:
        progress(label, fraction)
    return bool(stop and stop())


def _detail(message: str) -> str:
    """The parenthesised details of a trainer message ("... (iteration 3, cost 1.2, mu 0.1)")."""
    at = message.find(" (")
    return message[at:] if at >= 0 else ""


def _record(ds: Dataset) -> RecordInfo:
    return RecordInfo(ds.path, ds.sha256, ds.n_rows, ds.max_step_deviation)


def _versions() -> dict:
    import networkx
    import numba
    import scipy

    return {"sdnn": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__, "networkx": networkx.__version__}

"""identify(): fit a chart's physical parameters and learned curves to measured data.

Offline: Levenberg-Marquardt (eq. 11) on the cost of eq. (4) with the exact RTRL Jacobian, from one or several
seeded starts. Quasi-online (paper section 3.1): LM iterations on a sliding window as the record streams by,
the estimate the mean over the last K steps; with several starts, the run with the lowest final window cost.
Either way the answer is a typed :class:`~flowchart2sdnn.identify.result.Identification` with uncertainty, fit
metrics and everything needed to reproduce the run. Never prints: progress goes through
`progress(text, fraction)`.

The optimizer runs (offline multi-start, quasi-online, auto's second look, the LM options) are
:mod:`.optimize`'s; the pieces of the answer made from their raw results (metrics, traces, RESULT.json's
`discretization` and `shooting`) :mod:`.assemble`'s. This module decides: the sub-steps, the shooting, the
floor and its bias, the warnings, and puts the answer together.

Layer: identify (below it: simulate's oracle, fit, network, compiler, data, diagram, executors).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from ...compiler.substeps import AUTO_CAP, requested_substeps
from ...data.csvdata import Dataset
from ...diagram.dump import with_values
from ...diagram.model import Diagram
from ...errors import SdnnError
from ...fit.lm import CONVERGED_STATUSES, CRAWL_DETAIL
from ...notices import Notice, messages
from ...threads import one_blas_thread
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
    Identification,
)
from ..settings import (
    FAR_ABOVE_NOISE,
    HELD_CHATTER,
    IdentifySettings,
)
from ..shooting.auto import choose_shooting
from .assemble import (
    curves_of,
    detail,
    discretization,
    fit_of,
    online_trace,
    optimizer_trace,
    record_info,
    resolved_chart,
    shooting_extra,
    versions,
)
from .optimize import Outcome, fit_offline, fit_online, lm_options, recording, with_second_look
from .perrecord import per_record_estimates
from .problem import Problem, build_problem

__all__ = ["IdentifySettings", "Identification", "identify", "with_floor_bias"]

ONLINE_COST = "mean window cost over the last K steps of each quasi-online run"


@one_blas_thread
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
        out = Outcome(x0, "nothing_to_fit", "every parameter and curve is fixed; only the fit was evaluated", False)
    elif settings.online:
        out = fit_online(problem, x0, lower, upper, settings, progress, stop, executor)
    else:
        cut: list[str] = []
        out = fit_offline(problem, x0, lower, upper, settings, progress, stop, executor, recording(cutoff, cut))
        if cut:
            out = replace(out, status="cut_off", message=f"cut off: {cut[0]}", interrupted=False)
        if auto is not None and out.lm is not None and not out.interrupted:
            out, settings, auto = with_second_look(problem, x0, lower, upper, settings, starts, auto, out, progress,
                                               stop, executor)
    if out.multistart_warning:
        warnings.append(out.multistart_warning)
    shooting = shooting_extra(settings, out.lm, auto) if settings.shooting != "off" or auto is not None else None
    if shooting and shooting.get("predictable") is False:
        warnings.append(Notice("SHOOT001", shooting["note"], {"final_length": shooting["final_length"]},
                               f"validate the fit on horizons of up to {shooting['final_length']} samples "
                               f"(`sdnn compare --horizon {shooting['final_length']}`)"))
    x, status, message, interrupted = out.x, out.status, out.message, out.interrupted
    if status == "callback_stop" or message.startswith("stopped by the callback"):  # `stop`: the CLI's Ctrl-C
        status, interrupted = "interrupted", True
        message = "interrupted (Ctrl-C); the best point so far is returned" + detail(message)

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
    curves = curves_of(problem, x)
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

    chart = resolved_chart(with_values(diagram, params, curves), problem.network)
    fit, state = fit_of(problem, xs, settings, train, more, full, validation)
    if out.lm is not None and not interrupted and status not in ("no_excitation", "diverged_at_start") and not (
            shooting and shooting.get("predictable") is False):  # an unpredictable chart already says so
        warnings.extend(_far_above_noise(problem, fit.train.cost))
    disc = discretization(diagram, problem.network)
    if status == "diverged_at_start":
        disc["floor"] = {"rms": None, "skipped": "the fit diverged at its start"}
    elif not settings.floor:
        disc["floor"] = {"rms": None, "skipped": "not measured (floor off: a fit that only compares costs)"}
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
        data=DataInfo(record_info(full if settings.split is not None else train),
                      tuple(record_info(d) for d in ([full] if settings.split is not None else [train] + more)),
                      record_info(validation) if validation is not None else None),
        versions=versions(),
        optimizer=optimizer_trace(out.lm) if out.lm is not None else None,
        multistart=out.multistart, uncertainty=evidence.uncertainty,
        online=online_trace(out.online, problem.names, settings) if out.online is not None else None,
        problem=problem, x=x, lm=out.lm, online_run=out.online,
        extra={"discretization": disc,
               **({"shooting": shooting} if shooting else {}),
               **({"curve_start": out.curve_start} if out.curve_start else {}),
               **({"initial_states": {"validation": state.to_dict()}} if state is not None else {}),
               **({"parameters_per_record": per_record} if per_record else {})},
    )


def _finer_substeps(diagram: Diagram, problem: Problem, floor: dict, rms: dict, out: Outcome,
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

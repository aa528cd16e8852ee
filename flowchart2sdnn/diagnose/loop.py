"""The diagnose loop: fit, test the residual, score every candidate effect, refit the best, accept or stop.

One round:

1. the current chart is fitted (round 1: the chart as given);
2. every effect of the library at every place and option is scored by the score test (:mod:`.score`); when the
   current fit is unpredictable and loses the record part way (a chaotic drive), also on the part of each record
   it still follows (:mod:`.tracked`), whose best place joins the refits of step 3;
3. the best ``top`` places whose score is significant are refitted briefly (``refit_iter`` LM iterations),
   from the current fit with the effect added at neutral values, and from the chart as given with every
   accepted effect and this one added at neutral values (a refit only from the previous fit gets stuck where
   the previous fit bent its parameters to imitate the missing effect); a candidate that is not neutral (a
   scanned gap, clip or delay), and a neutral one whose plain refit is unpredictable (fitting.unpredictable:
   the effect made the drive chaotic, e.g. motor cogging), from the chart as given twice, on the whole records
   at once and with a growing
   horizon (``horizon`` samples of each record first, then 4x longer leading parts, then the whole records:
   on a chaotic drive a fit over whole records from far away stops in a local minimum) - keeping the lowest
   training cost;
4. the refitted candidates are ranked by validation RMS (those within ``min_gain / 2`` of the best by the
   information criterion, so that the simpler of two equally good effects wins); the first whose validation
   RMS falls (by at least ``min_gain``, over all validation records and on the median record) and whose
   criterion falls is accepted and polished (``max_iter`` iterations);
5. repeat until nothing is significant, nothing is accepted, or ``rounds`` rounds are done.

AIC = N ln(SSE/N) + 2k and BIC = N ln(SSE/N) + k ln N on the training record, N the number of residuals, k
the free quantities plus one per scanned discrete choice (a dead time's n, a cogging harmonic).
Never prints: progress goes through ``progress(text, fraction)``. The brief refits of a round are independent
work units (:func:`refit_unit`): an executor (:mod:`flowchart2sdnn.executors`) runs them in worker processes or on
a Dask cluster with the same results as in this process.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

from .. import rules
from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..identify import with_floor_bias
from ..strictjson import finite_or_none
from .document import REPORT_FORMAT, REPORT_VERSION, fit_summary, read_accepted, read_candidate, read_round
from .effects import BUILTIN_EFFECTS, Effect, Scales
from .entries import round_entry as _round_entry
from .entries import summary as _summary
from .fitting import (
    DEFAULT_SPLIT,
    DiagnoseSettings,
    Fitted,
    Progress,
    current_problem,
    effect_scales,
    far_above_noise,
    fit_chart,
    fit_growing,
    gain_spread,
    horizons,
    residual_analysis,
    still_moving,
    unpredictable,
    with_floor,
)
from .result import Diagnosis, FirstFit, ResidualCheck
from .score import Candidate, Score, Screen, screen
from .tracked import prefix_problem, score_rows

__all__ = ["DiagnoseSettings", "Fitted", "Diagnosis", "diagnose", "refit_unit", "refusal", "fit_chart", "horizons",
           "candidates", "done_key", "gain_spread", "whole_run_stop", "REPORT_FORMAT", "REPORT_VERSION"]

# ------------------------------------------------------------------------------------------------ helpers
def candidates(effects: Sequence[Effect], current: Diagram, scales: Scales, done: set) -> list[Candidate]:
    out = []
    for effect in effects:
        for place in effect.places(current):
            for option in effect.options(current, place, scales):
                if (effect.name, place.at) not in done and (effect.name, place.at, effect.label(option)) not in done:
                    out.append(Candidate(effect, place, option, current))
    return out


def _significant(s: Score, settings: DiagnoseSettings) -> bool:
    return s.scored and s.score > 0 and s.p_value < settings.alpha


def _refit_set(scr: Screen, settings: DiagnoseSettings) -> list[Score]:
    """The best option of each of the `top` best places with a significant score, plus the runners-up of the
    best place's scan (a dead time's n or a cogging harmonic is decided by refitting, not by the score)."""
    best = [s for s in scr.best_per_place() if _significant(s, settings)][: settings.top]
    if best and settings.runners_up > 0:
        key = best[0].candidate.key
        more = [s for s in scr.scores if _significant(s, settings) and s.candidate.key == key and s is not best[0]]
        best[1:1] = more[: settings.runners_up]
    return best


def _prefix_screen(cands: list[Candidate], current: Fitted, problem, train: list[Dataset],
                   settings: DiagnoseSettings, say) -> tuple[list[int] | None, tuple[float, list[Score]] | None]:
    """The score test on the part of each training record the current fit still follows (:mod:`.tracked`), when
    it does not follow the whole record: (rows per record or None, (seconds, the best place's picks) or None).

    The picks are the best significant place of that screen with its runners-up (:func:`_refit_set`'s first
    place): on a chaotic record the whole-record ranking is about the diverged part (cogging bench, seeds 2-3),
    the tracked part's ranking about the missing effect; both are refitted and judged on the whole records."""
    rows = score_rows(current, problem, train, settings)
    if rows is None:
        return None, None
    built = prefix_problem(current, train, settings, rows)
    if built is None:
        return rows, None
    say(f"score test on the tracked part of the records ({', '.join(map(str, rows))} rows)", None)
    part = screen(cands, built[0], built[1], settings.alignment, settings.seed, settings.top_options)
    picks = _refit_set(part, settings)
    picks = [s for s in picks if s.candidate.key == picks[0].candidate.key]  # the best place's options
    return rows, (part.seconds, picks)


#: the second look (DiagnoseSettings.second_look): no refit of the round within this many times the noise RMS.
#: Above what the discretization floor leaves on the benches' complete charts (at most 4x the noise: three-mass
#: drive at `substeps: 1`, noise 0.003), far below a chart that misses an effect outright (tanks bench, seed 2:
#: the best of the 5 places, an input clip, refitted to 19x; the spill, the 6th place, to 2.3x).
SECOND_LOOK = rules.value("far_above_noise")


def _second_look(scr: Screen, best: list[Score], refits: list[tuple[Score, Fitted]], train: list[Dataset],
                 settings: DiagnoseSettings) -> list[Score]:
    """The next `top` significant places (the best option of each) when no refit of the round came within
    SECOND_LOOK x the noise: the score test ranks by the residual's first-order fall at a fit that misses an
    effect, and from a fit far off the record the missing effect's place can rank just below the cut."""
    if not settings.second_look or any(not far_above_noise(f, train, settings, SECOND_LOOK) for _, f in refits):
        return []
    have = {s.candidate.key for s in best}
    rest = [s for s in scr.best_per_place() if _significant(s, settings) and s.candidate.key not in have]
    return rest[: settings.top]


def _union(best: list[Score], picks: list[Score], scr: Screen) -> list[Score]:
    """`best` plus the `picks` (scored on the tracked part) it lacks, each as its whole-record Score where that is
    scored (so that REPORT.json's ranking marks it refitted)."""
    have = {(s.candidate.key, s.candidate.label) for s in best}
    whole = {(s.candidate.key, s.candidate.label): s for s in scr.scores if s.scored}
    out = list(best)
    for s in picks:
        k = (s.candidate.key, s.candidate.label)
        if k not in have:
            have.add(k)
            out.append(whole.get(k, s))
    return out


def _order(refits: list[tuple[Score, Fitted]], settings: DiagnoseSettings) -> list[tuple[Score, Fitted]]:
    """Refitted candidates best first: by validation RMS, where those within half of `min_gain` of the best
    count as tied and go by the information criterion (the simpler of two equally good effects first)."""
    if not refits:
        return refits
    by_val = sorted(refits, key=lambda sf: sf[1].validation_rms)
    tol = by_val[0][1].validation_rms * (1 + settings.min_gain / 2)
    tied = [sf for sf in by_val if sf[1].validation_rms <= tol]
    rest = [sf for sf in by_val if sf[1].validation_rms > tol]
    return sorted(tied, key=lambda sf: sf[1].criterion(settings.criterion)) + rest


def refusal(after: Fitted, before: Fitted, settings: DiagnoseSettings) -> str | None:
    """Why the refit `after` must not replace `before`, or None when it may: the validation RMS must fall by at
    least ``min_gain`` over all validation records and on the median record, by more than the discretization
    floor of `before` explains, and the criterion must fall.

    The floor (``before.validation_floor``, :func:`~.fitting.with_floor`): the network of the fitted chart
    against the same chart simulated continuously, on the validation records. A complete chart's validation
    error is noise and that floor (independent, so their squares add); an effect that only imitates the
    network's step error can at best remove the floor's share, so the validation MSE must fall by more than
    floor² (two-mass Coulomb bench at N = 1: see docs/diagnose.md).

    The median record: on a chaotic drive one short record whose trajectory diverges (or locks back) moves the
    pooled RMS by several % (backlash bench, round 2: a cogging term the plant lacks lowered one record's RMS
    0.083 -> 0.074 and left the other four as they were); an effect must help the typical record.
    """
    keep = 1 - settings.min_gain
    if not after.validation_rms < before.validation_rms * keep:
        return "validation RMS did not fall enough"
    if not after.validation_median < before.validation_median * keep:
        return "validation RMS of the median record did not fall enough"
    floor = before.validation_floor
    if floor and not after.validation_rms ** 2 < before.validation_rms ** 2 - floor ** 2:
        room = before.validation_rms ** 2 - floor ** 2
        need = f"below {math.sqrt(room):.4g}" if room > 0 else "the whole validation RMS is within the floor"
        return (f"validation RMS {before.validation_rms:.4g} -> {after.validation_rms:.4g} is what the "
                f"discretization floor {floor:.3g} can explain ({need}); use `substeps: auto`, `delays: torques`")
    spread = gain_spread(after, before)
    if settings.spread_z and spread is not None:
        gain = before.validation_rms ** 2 - after.validation_rms ** 2
        need = (floor or 0.0) ** 2 + settings.spread_z * spread
        if not gain > need:
            return (f"validation MSE fell by {gain:.3g} ({before.validation_rms:.4g} -> {after.validation_rms:.4g} "
                    f"RMS), not more than the floor\u00b2 {(floor or 0.0) ** 2:.3g} plus {settings.spread_z:g} x "
                    f"its spread over the validation parts {spread:.3g}")
    if not after.criterion(settings.criterion) < before.criterion(settings.criterion):
        return f"{settings.criterion.upper()} did not fall"
    return None


def whole_run_stop(last_round: str, n_accepted: int) -> str:
    """The report's ``stop``: how the whole run ended. After accepting effects the loop ends when the next round
    finds nothing more ("done_after_accepting"; which way is in ``last_round``): a bare "nothing_accepted"
    there read as if the run had found nothing."""
    if n_accepted and last_round in ("nothing_significant", "nothing_accepted", "no_candidates"):
        return "done_after_accepting"
    return last_round


def _repeatable(effect: Effect) -> bool:
    return bool(getattr(effect, "repeatable", False))


def done_key(c: Candidate) -> tuple:
    """What an accepted candidate takes off the list: the effect at that place, or only that option of it for
    a repeatable effect (cogging harmonics) and for an option the effect says leaves room for its others
    (``leaves_room(option)``: friction's physical terms)."""
    leaves_room = getattr(c.effect, "leaves_room", None)
    partial = _repeatable(c.effect) or (leaves_room is not None and leaves_room(c.option))
    return (c.name, c.at) + ((c.label,) if partial else ())


# ------------------------------------------------------------------------------------------------ loop
def _split(train: list[Dataset], validation: Sequence[Dataset], split: float | None):
    if validation and split is not None:
        raise ValueError("give either validation records or a split, not both")
    if validation:
        return train, [(v, 0) for v in validation], None
    if len(train) > 1:
        raise SdnnError.at("DIAG002", "several training records need validation records (--validate)",
                           train[1].path, hint="a split applies to a single record")
    train = train[0]
    split = DEFAULT_SPLIT if split is None else split
    n = max(3, int(round(split * train.n_rows)))
    if train.n_rows - n < 3:
        raise SdnnError.at("DIAG002", f"only {train.n_rows} rows: too few to split off a validation part",
                           train.path, hint="give a validation record with --validate")
    return [train.slice(0, n)], [(train, n)], split


def _was_interrupted(fitted) -> bool:
    """The trainer turns Ctrl-C into an 'interrupted' result; diagnose must stop there too."""
    return fitted is not None and fitted.identification.status == "interrupted"


def diagnose(diagram: Diagram, train: Dataset | Sequence[Dataset], validation: Sequence[Dataset] = (),
             settings: DiagnoseSettings | None = None, effects: Sequence[Effect] | None = None,
             progress: Progress | None = None, executor=None) -> Diagnosis:
    """Find what `diagram` lacks from measured data, add it, refit, and report before and after.

    Parameters
    ----------
    diagram : Diagram
        The chart as the user wrote it (never modified).
    train : Dataset or sequence of Dataset
        The training record(s), each simulated from its own initial state (with ``settings.split``, or
        without validation records, the leading part of a single record).
    validation : sequence of Dataset
        Validation records (each simulated from its own first sample); empty: a split of `train`
        (``settings.split``, default 0.7), the model free-running over the whole record.
    settings : DiagnoseSettings, optional
    effects : sequence of Effect, optional
        The library to try (default: every built-in effect).
    progress : callable(text, fraction), optional
    executor : a :mod:`flowchart2sdnn.executors` executor, optional
        Runs the brief refits of each round (two work units per refitted candidate); in this process when None.

    Returns
    -------
    Diagnosis
    """
    t_start = time.perf_counter()
    settings = settings or DiagnoseSettings()
    effects = tuple(BUILTIN_EFFECTS.values()) if effects is None else tuple(effects)
    train = [train] if isinstance(train, Dataset) else list(train)
    if settings.init_window and not validation:
        raise ValueError("init_window sets the initial state of validation records: give some")
    train, records, split = _split(train, list(validation), settings.split)
    # scored from the initial-state window on (the window's rows set the state): the floor too
    records = [(ds, max(start, settings.init_window)) for ds, start in records]

    def say(text: str, fraction: float | None = None) -> None:
        if progress:
            progress(text, fraction)

    say("fitting the chart as given", 0.0)
    nominal = with_floor(fit_chart(diagram, train, records, settings, settings.max_iter, 0, "chart", say), records,
                         settings)
    current, nominal_chart, extra_dof = nominal, diagram, 0
    rounds, candidates_out, accepted, screens = [], [], [], []
    done: set = set()
    stop_reason = "rounds"
    interrupted = _was_interrupted(nominal)
    timing = {"nominal_fit": time.perf_counter() - t_start, "screen": [], "refit": []}
    # an unconverged first fit is no baseline: the effect that lets a refit escape its unfinished descent (or
    # its local minimum) "explains" the residual whether the plant has it or not (issue 16: train RMS 1.28 on
    # a chart whose best fit is 0.06, then false alarms)
    # a fit stopped by the iteration limit is still a baseline when nothing would move by more than its standard
    # error (a chart that lacks an effect ends far above the noise, at its own minimum): refuse only otherwise
    moving = still_moving(nominal) if (not interrupted and nominal.identification.converged is False) else []
    unconverged = not interrupted and settings.require_converged and bool(moving)
    try:
        if interrupted:
            raise KeyboardInterrupt
        for r in range(1, settings.rounds + 1 if not unconverged else 1):
            problem = current_problem(current, train, settings)
            cands = candidates(effects, current.diagram, effect_scales(problem), done)
            if not cands:
                stop_reason = "no_candidates"
                break
            say(f"round {r}: score test of {len(cands)} candidates", None)
            scr = screen(cands, problem, train, settings.alignment, settings.seed, settings.top_options, say)
            screens.append(scr)
            timing["screen"].append(scr.seconds)
            best = _refit_set(scr, settings)
            rows, prefix_best = _prefix_screen(cands, current, problem, train, settings, say)
            if prefix_best:
                timing["screen"][-1] += prefix_best[0]
                best = _union(best, prefix_best[1], scr)
            # REPORT.json: the rows of each training record the tracked-part score used (None: not used) and the
            # candidates it added to the refits
            round_extra = {"score_rows": rows,
                           "score_rows_added": [s.candidate.title() for s in prefix_best[1]] if prefix_best else []}
            refits: list[tuple[Score, Fitted]] = []
            for s, fitted, seconds in _refits(best, nominal_chart, train, records, settings, extra_dof, accepted,
                                              executor, lambda text, r=r: say(f"round {r}: {text}", None),
                                              current.cost):
                timing["refit"].append(seconds)
                if _was_interrupted(fitted):
                    raise KeyboardInterrupt
                if fitted is not None:
                    refits.append((s, fitted))
            more = _second_look(scr, best, refits, train, settings) if refits else []
            if more:
                say(f"round {r}: no refit near the noise; refitting {len(more)} more places", None)
                for s, fitted, seconds in _refits(more, nominal_chart, train, records, settings, extra_dof,
                                                  accepted, executor, lambda text, r=r: say(f"round {r}: {text}", None),
                                                  current.cost):
                    timing["refit"].append(seconds)
                    if _was_interrupted(fitted):
                        raise KeyboardInterrupt
                    if fitted is not None:
                        refits.append((s, fitted))
                best = best + more
            round_extra["second_look"] = [s.candidate.title() for s in more]
            achieved = {id(s): f for s, f in refits}
            for rank, s in enumerate(scr.scores):
                entry = {"round": r, "rank": rank + 1, **s.as_dict()}
                f = achieved.get(id(s))
                if f is not None:
                    entry.update({"refitted": True, "achieved_cost": finite_or_none(f.cost),
                                  "achieved_decrease": finite_or_none(current.cost - f.cost), "start": f.start,
                                  "validation_rms_after": finite_or_none(f.validation_rms),
                                  settings.criterion + "_after": finite_or_none(f.criterion(settings.criterion))})
                candidates_out.append(entry)
            if not best:
                stop_reason = "nothing_significant"
                break
            refits = _order(refits, settings)
            control = (_control(current, nominal_chart, train, records, settings, extra_dof, accepted, executor,
                                horizon=any(not s.candidate.neutral for s in best))
                       if settings.control_refit else None)
            if _was_interrupted(control):
                raise KeyboardInterrupt
            baseline = current
            if control is not None and control.validation_rms < current.validation_rms:
                # the current fit had not finished: finish the control as an accepted chart is polished, and judge
                # the candidates against that (an effect's extra freedom can speed a descent the chart as it is
                # would also complete, and a brief control may stop short of where that descent ends)
                say(f"round {r}: the current fit was not at its minimum; finishing it", None)
                finished = fit_chart(control.diagram, train, records, settings, settings.max_iter, extra_dof,
                                     control.start, None, control.accepted)
                if _was_interrupted(finished):
                    raise KeyboardInterrupt
                if finished.cost <= control.cost and finished.validation_rms <= control.validation_rms:
                    control = finished
                baseline = with_floor(control, records, settings)
            choice, reason = None, "no refit succeeded"
            for s, f in refits:
                why = refusal(f, baseline, settings)
                if why is not None and baseline is not current:
                    why += (f" (against the chart refitted as briefly without any effect: validation RMS "
                            f"{baseline.validation_rms:.4g}, the current fit's {current.validation_rms:.4g})")
                if why is None:
                    choice = (s, f)
                    break
                if choice is None and reason == "no refit succeeded":
                    reason = f"{s.candidate.title()}: {why}"
            control_entry = _control_entry(control, baseline is not current)
            if choice is None:
                s, f = refits[0] if refits else (best[0], None)
                rounds.append({**_round_entry(r, s, current, f, False, reason, settings), "control": control_entry,
                               **round_extra})
                stop_reason = "nothing_accepted"
                if baseline is not current:
                    # the same chart, refitted to a better point: the final chart is that fit, not the one the
                    # round found stuck (a first fit in a local minimum would otherwise be the report's `after`)
                    control_entry["final"] = True
                    current = baseline
                break
            s, f = choice
            c = s.candidate
            say(f"round {r}: accepted {c.title()}; polishing", None)
            extra_dof += c.effect.extra_dof
            polished = fit_chart(f.diagram, train, records, settings, settings.max_iter, extra_dof, f.start, None,
                            f.accepted)
            stop_now = _was_interrupted(polished)
            if stop_now or not (polished.cost <= f.cost and polished.validation_rms <= f.validation_rms):
                polished = f  # the brief refit validates better: stop early there
            polished = with_floor(polished, records, settings)  # the next round's candidates must beat its floor
            rounds.append({**_round_entry(r, s, current, polished, True, "validation RMS and "
                                          f"{settings.criterion.upper()} fell", settings), "control": control_entry,
                           **round_extra})
            accepted.append({"effect": c.name, "at": c.at, "option": s.as_dict()["option"], "label": c.label})
            done.add(done_key(c))
            nominal_chart = c.effect.patch(nominal_chart, c.place, c.option)
            current = polished
            if stop_now:
                raise KeyboardInterrupt
        else:
            stop_reason = "first_fit_not_converged" if unconverged else "rounds"
    except (KeyboardInterrupt, SystemError) as exc:
        # Ctrl-C (inside a numba kernel it surfaces as a SystemError caused by it): keep the last accepted chart
        # and report what was done; the CLI writes it marked interrupted
        if isinstance(exc, SystemError) and not isinstance(exc.__cause__ or exc.__context__, KeyboardInterrupt):
            raise
        stop_reason, interrupted = "interrupted", True

    if settings.final_bias and not interrupted and math.isfinite(current.cost):
        say("the final fit's discretization bias", None)
        t_bias = time.perf_counter()
        try:
            current = replace(current, identification=with_floor_bias(current.identification, train))
        except (KeyboardInterrupt, SystemError) as exc:  # Ctrl-C: the traced result stands without the analysis
            if isinstance(exc, SystemError) and not isinstance(exc.__cause__ or exc.__context__, KeyboardInterrupt):
                raise
            stop_reason, interrupted = "interrupted", True
        timing["final_bias"] = time.perf_counter() - t_bias
    say("residual analysis", None)
    whiteness = (ResidualCheck(residual_analysis(nominal, train, settings)),
                 ResidualCheck(residual_analysis(current, train, settings)))
    ident = nominal.identification
    # the rounds' pieces are built as REPORT.json mappings (entries.py) and read as the typed parts here
    return Diagnosis(
        stop=whole_run_stop(stop_reason, len(accepted)), last_round=stop_reason,
        first_fit=FirstFit(ident.converged, ident.status, ident.message, tuple(moving)), interrupted=interrupted,
        candidates=tuple(map(read_candidate, candidates_out)), rounds=tuple(map(read_round, rounds)),
        accepted=tuple(map(read_accepted, accepted)),
        before=fit_summary(_summary(nominal)), after=fit_summary(_summary(current)), whiteness=whiteness,
        identification=current.identification, settings=settings, split=split,
        effects=tuple(e.name for e in effects), timing={**timing, "total": time.perf_counter() - t_start},
        diagram=current.diagram, final=current, nominal=nominal, screens=tuple(screens))


# the starts from the chart as given, which a growing horizon may also refit, and the start the grown fit reads
_HORIZON_STARTS = {"nominal": "horizon", "control_nominal": "control_horizon"}


#: when a refit from the chart as given also grows its horizon: always (a candidate that changes the model at
#: once, or the control of a round that has one), or only when the plain refit is unpredictable (a neutral
#: candidate: fitting.unpredictable)
GROW_ALWAYS, GROW_IF_UNPREDICTABLE = "always", "if_unpredictable"


def refit_unit(unit: tuple) -> tuple[Fitted | None, float]:
    """One brief refit: (chart, train, records, settings, max_iter, dof, start, accepted[, grow[, target]]) ->
    (Fitted or None, seconds). From the chart as given (start "nominal", or the control's "control_nominal")
    also with a growing horizon (``settings.horizon``) - always, or with `grow` GROW_IF_UNPREDICTABLE only when
    the plain refit is unpredictable (:func:`~.fitting.unpredictable`) - keeping the lower training cost (its
    start then reads "horizon", "control_horizon"). A finite `target` (the lowest training cost a refit of the
    round reached) cuts a fit off once it cannot reach it (:func:`~.fitting.behind`). Module level, so that any
    executor's worker can run it."""
    chart, train, records, settings, max_iter, dof, start, acc, *rest = unit
    grow = rest[0] if rest else GROW_ALWAYS
    target = rest[1] if len(rest) > 1 else math.inf
    t0 = time.perf_counter()
    try:
        fitted = fit_chart(chart, train, records, settings, max_iter, dof, start, None, acc, target)
        if (start in _HORIZON_STARTS and settings.horizon > 0 and not _was_interrupted(fitted)
                and (grow == GROW_ALWAYS or unpredictable(fitted, train, settings))):
            grown = fit_growing(chart, train, records, settings, max_iter, dof, _HORIZON_STARTS[start], acc,
                                min(target, fitted.cost))
            if _was_interrupted(grown) or grown.cost < fitted.cost:
                fitted = grown
    except (SdnnError, ValueError, KeyError):
        fitted = None
    return fitted, time.perf_counter() - t0


def _control(current: Fitted, nominal_chart: Diagram, train: list[Dataset], records, settings: DiagnoseSettings,
             extra_dof: int, accepted: list, executor, horizon: bool = False) -> Fitted | None:
    """The current chart refitted as briefly as the candidates, without any new effect, from the current fit and
    from the chart as given (plus the accepted effects), and with `horizon` (some candidate was refitted so)
    also with the growing horizon from the chart as given: the lower training cost, or None.

    A candidate must beat this, not only the current fit: when the current fit has not finished its descent (or
    sits in a local minimum) any effect's refit goes further down, and without this control the effect takes the
    credit (one-mass chart traced from its init: damping accepted, validation RMS 0.076 -> 0.020, the noise;
    tests/test_diagnose_false_alarms.py). The control gets every start a candidate got: a first fit in a local
    minimum (converged, train RMS 0.52 at noise 0.003) was left by the growing-horizon refit of a scanned
    overflow limit the chart did not need (validation RMS 0.382 -> 0.0030, accepted), while the control without
    that start stayed at 0.382 (false-alarm bench, physical two-mass chart, seed 2; docs/diagnose.md)."""
    acc = tuple(a["effect"] + "@" + a["at"] for a in accepted)
    grow = GROW_ALWAYS if horizon else GROW_IF_UNPREDICTABLE
    # the control matters only where it goes below the current fit's cost: cut off where it cannot
    units = [(current.diagram, train, records, settings, settings.refit_iter, extra_dof, "control", acc, grow,
              current.cost),
             (nominal_chart, train, records, settings, settings.refit_iter, extra_dof, "control_nominal", acc, grow,
              current.cost)]
    results = map(refit_unit, units) if executor is None else executor.map(refit_unit, units)
    best = None
    for fitted, _sec in results:
        if _was_interrupted(fitted):
            return fitted
        if fitted is not None and math.isfinite(fitted.cost) and (best is None or fitted.cost < best.cost):
            best = fitted
    return best


def _control_entry(control: Fitted | None, used: bool) -> dict | None:
    """REPORT.json's round `control`: the brief refit without any effect, whether candidates were judged
    against it (it validated better than the current fit), and whether it became the final fit (`final`: set by
    the loop when nothing was accepted against it)."""
    if control is None:
        return None
    return {"start": control.start, "rms": finite_or_none(control.rms),
            "validation_rms": finite_or_none(control.validation_rms), "used_as_baseline": used, "final": False}


def _refits(best: Sequence[Score], nominal_chart: Diagram, train: list[Dataset], records,
            settings: DiagnoseSettings, extra_dof: int, accepted: list, executor, say: Callable[[str], None],
            current_cost: float = math.inf):
    """(score, the better of its brief refits or None, seconds) for each candidate in `best`, in order.

    Each candidate is refitted from the current fit and from the chart as given (plus the accepted effects),
    every one with its new effect at neutral values (or at its scanned option); a candidate that is not
    neutral is refitted from the chart as given twice, on the whole records at once and with a growing
    horizon (``settings.horizon``), in one work unit. The lowest training cost wins, ties go to the refit from
    the current fit.

    A refit is cut off (:func:`~.fitting.behind`) once it cannot reach the lowest training cost of a refit before
    it, nor the relevance bar: the current fit's cost `current_cost` lowered by ``min_gain`` of its RMS (an effect
    that cannot lower the training RMS by that much will not lower the validation RMS by it, which acceptance
    asks; see :func:`refusal`).
    """
    acc = tuple(a["effect"] + "@" + a["at"] for a in accepted)
    units, owner = [], []
    for i, s in enumerate(best):
        c = s.candidate
        dof = extra_dof + c.effect.extra_dof
        # the growing horizon always for a candidate that changes the model at once (a scanned gap, clip or
        # delay); for a neutral one, which starts on the chart as given's own trajectory, only where its plain
        # refit is unpredictable (fitting.unpredictable: motor cogging makes the two-mass drive chaotic). Not
        # always: a learned curve bent on the first 500 samples first ends elsewhere (EMPS: the learned curve
        # then wins over the physical friction terms)
        grow = GROW_IF_UNPREDICTABLE if c.neutral else GROW_ALWAYS
        for start, chart in (("previous", lambda c=c: c.diagram),
                             ("nominal", lambda c=c: c.effect.patch(nominal_chart, c.place, c.option))):
            try:
                units.append((chart(), train, records, settings, settings.refit_iter, dof, start, acc, grow))
            except (SdnnError, ValueError, KeyError):
                continue
            owner.append(i)
    chosen: list[Fitted | None] = [None] * len(best)
    seconds = [0.0] * len(best)
    # candidate by candidate, best score first, both starts of one candidate together (the executor's work), each
    # cut off at the lowest cost a refit before it reached (fitting.behind): a refit that cannot reach the round's
    # best stops after a few iterations. The waves do not depend on the executor, so neither do the results.
    leader, done = current_cost * (1 - settings.min_gain) ** 2, 0
    for i in dict.fromkeys(owner):
        batch = [(*u, leader) for u, o in zip(units, owner, strict=True) if o == i]
        results = map(refit_unit, batch) if executor is None else executor.map(refit_unit, batch)
        for fitted, sec in results:
            done += 1
            say(f"refit {best[i].candidate.title()} ({done}/{len(units)})")
            seconds[i] += sec
            if _was_interrupted(fitted):
                yield best[i], fitted, seconds[i]
                return
            if fitted is not None and (chosen[i] is None or fitted.cost < chosen[i].cost):
                chosen[i] = fitted
            if fitted is not None and math.isfinite(fitted.cost):
                leader = min(leader, fitted.cost)
    for i, s in enumerate(best):
        yield s, chosen[i], seconds[i]

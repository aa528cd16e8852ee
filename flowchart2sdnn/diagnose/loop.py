"""The diagnose loop: fit, test the residual, score every candidate effect, refit the best, accept or stop.

One round:

1. the current chart is fitted (round 1: the chart as given);
2. every effect of the library at every place and option is scored by the score test (:mod:`.score`); when the
   current fit is unpredictable and loses the record part way (a chaotic drive), also on the part of each record
   it still follows (:mod:`.tracked`), whose best place joins the refits of step 3;
3. a significant neutral candidate whose one Gauss-Newton step, simulated, is well predicted and does not lower
   the validation RMS (near the noise: by ``min_gain``) is dropped (choice.one_step_relevant); the best
   ``top`` places whose score is significant are refitted briefly (``refit_iter`` LM iterations),
   from the current fit with the effect added at neutral values, and - far above the noise, or for a candidate
   that is not neutral - from the chart as given with every accepted effect and this one added at neutral
   values (a refit only from the previous fit gets stuck where the previous fit bent its parameters to imitate
   the missing effect); a candidate that is not neutral (a
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
from collections.abc import Sequence
from dataclasses import replace

from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..identify import with_floor_bias
from ..strictjson import finite_or_none
from ..threads import one_blas_thread
from .choice import (
    SECOND_LOOK,
    candidates,
    done_key,
    one_step_relevant,
    order_refits,
    passes_gain,
    prefix_screen,
    refit_set,
    refusal,
    second_look_places,
    union_picks,
    whole_run_stop,
)
from .document import REPORT_FORMAT, REPORT_VERSION, fit_summary, read_accepted, read_candidate, read_round
from .effects import BUILTIN_EFFECTS, Effect
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
    gain_spread,
    horizons,
    residual_analysis,
    still_moving,
    with_floor,
)
from .refits import (
    GROW_ALWAYS,
    GROW_IF_UNPREDICTABLE,
    brief_refits,
    control_fit,
    control_report,
    refit_unit,
    was_interrupted,
)
from .result import Diagnosis, FirstFit, ResidualCheck
from .score import Score, screen

__all__ = ["DiagnoseSettings", "Fitted", "Diagnosis", "diagnose", "refit_unit", "refusal", "fit_chart", "horizons",
           "candidates", "done_key", "gain_spread", "whole_run_stop", "REPORT_FORMAT", "REPORT_VERSION",
           "SECOND_LOOK", "GROW_ALWAYS", "GROW_IF_UNPREDICTABLE"]


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


@one_blas_thread
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
    interrupted = was_interrupted(nominal)
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
            scr = screen(cands, problem, train, settings.alignment, settings.seed, settings.top_options, say, executor)
            screens.append(scr)
            timing["screen"].append(scr.seconds)
            best = refit_set(scr, settings)
            rows, prefix_best = prefix_screen(cands, current, problem, train, settings, say)
            if prefix_best:
                timing["screen"][-1] += prefix_best[0]
                best = union_picks(best, prefix_best[1], scr)
            # REPORT.json: the rows of each training record the tracked-part score used (None: not used) and the
            # candidates it added to the refits
            round_extra = {"score_rows": rows,
                           "score_rows_added": [s.candidate.title() for s in prefix_best[1]] if prefix_best else []}
            significant = best
            near = not far_above_noise(current, train, settings, SECOND_LOOK)
            best, round_extra["one_step"] = one_step_relevant(best, current, train, records, settings, near)
            refits: list[tuple[Score, Fitted]] = []
            for s, fitted, seconds in brief_refits(best, nominal_chart, train, records, settings, extra_dof, accepted,
                                              executor, lambda text, r=r: say(f"round {r}: {text}", None),
                                              current.cost, near):
                timing["refit"].append(seconds)
                if was_interrupted(fitted):
                    raise KeyboardInterrupt
                if fitted is not None:
                    refits.append((s, fitted))
            more = second_look_places(scr, significant, refits, train, settings) if refits else []
            if more:
                say(f"round {r}: no refit near the noise; refitting {len(more)} more places", None)
                for s, fitted, seconds in brief_refits(more, nominal_chart, train, records, settings, extra_dof,
                                                  accepted, executor, lambda text, r=r: say(f"round {r}: {text}", None),
                                                  current.cost, near):
                    timing["refit"].append(seconds)
                    if was_interrupted(fitted):
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
            if not significant:
                stop_reason = "nothing_significant"
                break
            refits = order_refits(refits, settings)
            # the control only ever refuses more: a refit whose validation RMS does not fall by min_gain against
            # the current fit falls by less against a control that validates better (and a control that validates
            # worse is not used). With no refit past that bar the round accepts nothing with or without it: skip it
            control = (control_fit(current, nominal_chart, train, records, settings, extra_dof, accepted, executor,
                                horizon=any(not s.candidate.neutral for s in best),
                                from_current_only=near and all(s.candidate.neutral for s in best))
                       if settings.control_refit and any(passes_gain(f, current, settings) for _, f in refits)
                       else None)
            if was_interrupted(control):
                raise KeyboardInterrupt
            baseline = current
            if control is not None and control.validation_rms < current.validation_rms:
                # the current fit had not finished: finish the control as an accepted chart is polished, and judge
                # the candidates against that (an effect's extra freedom can speed a descent the chart as it is
                # would also complete, and a brief control may stop short of where that descent ends)
                say(f"round {r}: the current fit was not at its minimum; finishing it", None)
                finished = fit_chart(control.diagram, train, records, settings, settings.max_iter, extra_dof,
                                     control.start, None, control.accepted)
                if was_interrupted(finished):
                    raise KeyboardInterrupt
                if finished.cost <= control.cost and finished.validation_rms <= control.validation_rms:
                    control = finished
                baseline = with_floor(control, records, settings)
            choice, reason = None, ("no refit succeeded" if best else "no significant place's Gauss-Newton step "
                                    f"lowers the validation RMS by {settings.min_gain:g} (one_step)")
            for s, f in refits:
                why = refusal(f, baseline, settings)
                if why is not None and baseline is not current:
                    why += (f" (against the chart refitted as briefly without any effect: validation RMS "
                            f"{baseline.validation_rms:.4g}, the current fit's {current.validation_rms:.4g})")
                if why is None:
                    choice = (s, f)
                    break
                if choice is None and reason == "no refit succeeded":  # the first refused refit says why
                    reason = f"{s.candidate.title()}: {why}"
            control_entry = control_report(control, baseline is not current)
            if choice is None:
                s, f = refits[0] if refits else (significant[0], None)
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
            stop_now = was_interrupted(polished)
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

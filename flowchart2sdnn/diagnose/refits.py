"""The brief refits of a diagnose round (:mod:`.loop`): one work unit (:func:`refit_unit`, module level so that
any executor's worker runs it), the candidates' refits cut off behind the round's best, and the control refit
without any new effect that a candidate must beat."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..strictjson import finite_or_none
from .fitting import DiagnoseSettings, Fitted, fit_chart, fit_growing, unpredictable
from .score import Score

__all__ = ["GROW_ALWAYS", "GROW_IF_UNPREDICTABLE", "refit_unit", "was_interrupted", "control_fit",
           "control_report", "brief_refits"]


def was_interrupted(fitted) -> bool:
    """The trainer turns Ctrl-C into an 'interrupted' result; diagnose must stop there too."""
    return fitted is not None and fitted.identification.status == "interrupted"


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
        if (start in _HORIZON_STARTS and settings.horizon > 0 and not was_interrupted(fitted)
                and (grow == GROW_ALWAYS or unpredictable(fitted, train, settings))):
            grown = fit_growing(chart, train, records, settings, max_iter, dof, _HORIZON_STARTS[start], acc,
                                min(target, fitted.cost))
            if was_interrupted(grown) or grown.cost < fitted.cost:
                fitted = grown
    except (SdnnError, ValueError, KeyError):
        fitted = None
    return fitted, time.perf_counter() - t0


def control_fit(current: Fitted, nominal_chart: Diagram, train: list[Dataset], records, settings: DiagnoseSettings,
             extra_dof: int, accepted: list, executor, horizon: bool = False,
             from_current_only: bool = False) -> Fitted | None:
    """The current chart refitted as briefly as the candidates, without any new effect, from the current fit and
    from the chart as given (plus the accepted effects), and with `horizon` (some candidate was refitted so)
    also with the growing horizon from the chart as given: the lower training cost, or None.

    A candidate must beat this, not only the current fit: when the current fit has not finished its descent (or
    sits in a local minimum) any effect's refit goes further down, and without this control the effect takes the
    credit (one-mass chart traced from its init: damping accepted, validation RMS 0.076 -> 0.020, the noise;
    tests/test_diagnose_false_alarms.py). The control gets every start a candidate got: a first fit in a local
    minimum (converged, train RMS 0.52 at noise 0.003) was left by the growing-horizon refit of a scanned
    overflow limit the chart did not need (validation RMS 0.382 -> 0.0030, accepted), while the control without
    that start stayed at 0.382 (false-alarm bench, physical two-mass chart, seed 2; docs/diagnose.md). With
    `from_current_only` (every candidate was refitted from the current fit only: :func:`brief_refits`' `near`)
    the control is too."""
    acc = tuple(a["effect"] + "@" + a["at"] for a in accepted)
    grow = GROW_ALWAYS if horizon else GROW_IF_UNPREDICTABLE
    # the control matters only where it goes below the current fit's cost: cut off where it cannot
    units = [(current.diagram, train, records, settings, settings.refit_iter, extra_dof, "control", acc, grow,
              current.cost),
             (nominal_chart, train, records, settings, settings.refit_iter, extra_dof, "control_nominal", acc, grow,
              current.cost)][: 1 if from_current_only else 2]
    results = map(refit_unit, units) if executor is None else executor.map(refit_unit, units)
    best = None
    for fitted, _sec in results:
        if was_interrupted(fitted):
            return fitted
        if fitted is not None and math.isfinite(fitted.cost) and (best is None or fitted.cost < best.cost):
            best = fitted
    return best


def control_report(control: Fitted | None, used: bool) -> dict | None:
    """REPORT.json's round `control`: the brief refit without any effect, whether candidates were judged
    against it (it validated better than the current fit), and whether it became the final fit (`final`: set by
    the loop when nothing was accepted against it)."""
    if control is None:
        return None
    return {"start": control.start, "rms": finite_or_none(control.rms),
            "validation_rms": finite_or_none(control.validation_rms), "used_as_baseline": used, "final": False}


def brief_refits(best: Sequence[Score], nominal_chart: Diagram, train: list[Dataset], records,
            settings: DiagnoseSettings, extra_dof: int, accepted: list, executor, say: Callable[[str], None],
            current_cost: float = math.inf, near: bool = False):
    """(score, the better of its brief refits or None, seconds) for each candidate in `best`, in order.

    Each candidate is refitted from the current fit and from the chart as given (plus the accepted effects),
    every one with its new effect at neutral values (or at its scanned option); a candidate that is not
    neutral is refitted from the chart as given twice, on the whole records at once and with a growing
    horizon (``settings.horizon``), in one work unit. The lowest training cost wins, ties go to the refit from
    the current fit.

    `near`: the current fit is near the noise; a neutral candidate is then refitted from the current fit only.
    The start from the chart as given is for a fit that bent its parameters to imitate a missing effect; a fit
    within ``far_above_noise`` x the noise has little left to imitate, and near it the refit's landscape is nearly
    quadratic (one Gauss-Newton step's training fall predicted within a few % on the benches' second rounds).

    A refit is cut off (:func:`~.fitting.behind`) once it cannot reach the lowest training cost of a refit before
    it, and the first one once it cannot reach `current_cost` (the current fit's: a refit ending above it is no
    better than the chart without the effect, as the control refit is cut). Not also below a relevance bar (the current fit's cost lowered by ``min_gain`` of its RMS): measured, that
    cut the EMPS friction refit while its learned curve was still slow to start, and a saturation took its place
    (tests/test_real_emps.py).
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
        starts = (("previous", lambda c=c: c.diagram),
                  ("nominal", lambda c=c: c.effect.patch(nominal_chart, c.place, c.option)))
        for start, chart in starts[:1] if (near and c.neutral) else starts:
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
    leader, done = current_cost, 0
    for i in dict.fromkeys(owner):
        batch = [(*u, leader) for u, o in zip(units, owner, strict=True) if o == i]
        results = map(refit_unit, batch) if executor is None else executor.map(refit_unit, batch)
        for fitted, sec in results:
            done += 1
            say(f"refit {best[i].candidate.title()} ({done}/{len(units)})")
            seconds[i] += sec
            if was_interrupted(fitted):
                yield best[i], fitted, seconds[i]
                return
            if fitted is not None and (chosen[i] is None or fitted.cost < chosen[i].cost):
                chosen[i] = fitted
            if fitted is not None and math.isfinite(fitted.cost):
                leader = min(leader, fitted.cost)
    for i, s in enumerate(best):
        yield s, chosen[i], seconds[i]

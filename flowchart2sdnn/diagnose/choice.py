"""The choices of a diagnose round (:mod:`.loop`): the candidates on offer, which scored ones are refitted (the
best places, a second look, the best place of the tracked part), the refits' order, and whether a refit may
replace the current fit (:func:`refusal`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from .. import rules
from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..strictjson import finite_or_none
from .effects import Effect, Scales
from .fitting import DiagnoseSettings, Fitted, far_above_noise, gain_spread, one_step_line
from .score import Candidate, Score, Screen, screen
from .tracked import prefix_problem, score_rows

__all__ = ["candidates", "refit_set", "prefix_screen", "SECOND_LOOK", "second_look_places", "union_picks",
           "one_step_relevant", "order_refits", "passes_gain", "refusal", "whole_run_stop", "done_key"]


def candidates(effects: Sequence[Effect], current: Diagram, scales: Scales, done: set) -> list[Candidate]:
    out = []
    for effect in effects:
        for place in effect.places(current):
            for option in effect.options(current, place, scales):
                if (effect.name, place.at) not in done and (effect.name, place.at, effect.label(option)) not in done:
                    out.append(Candidate(effect, place, option, current))
    return out


def _significant(s: Score, settings: DiagnoseSettings, tests: int = 1) -> bool:
    """Significant at the round's level `alpha` shared by the `tests` candidates scored (Bonferroni): the chance
    that a round refits some place where nothing is missing stays below alpha however many places a chart has."""
    return s.scored and s.score > 0 and s.p_value < settings.alpha / max(1, tests)


def _tests(scr: Screen) -> int:
    return sum(1 for s in scr.scores if s.scored)


def refit_set(scr: Screen, settings: DiagnoseSettings) -> list[Score]:
    """The best option of each of the `top` best places with a significant score, plus the runners-up of the
    best place's scan (a dead time's n or a cogging harmonic is decided by refitting, not by the score)."""
    n = _tests(scr)
    best = [s for s in scr.best_per_place() if _significant(s, settings, n)][: settings.top]
    if best and settings.runners_up > 0:
        key = best[0].candidate.key
        more = [s for s in scr.scores if _significant(s, settings, n) and s.candidate.key == key and s is not best[0]]
        best[1:1] = more[: settings.runners_up]
    return best


def prefix_screen(cands: list[Candidate], current: Fitted, problem, train: list[Dataset],
                   settings: DiagnoseSettings, say) -> tuple[list[int] | None, tuple[float, list[Score]] | None]:
    """The score test on the part of each training record the current fit still follows (:mod:`.tracked`), when
    it does not follow the whole record: (rows per record or None, (seconds, the best place's picks) or None).

    The picks are the best significant place of that screen with its runners-up (:func:`refit_set`'s first
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
    picks = refit_set(part, settings)
    picks = [s for s in picks if s.candidate.key == picks[0].candidate.key]  # the best place's options
    return rows, (part.seconds, picks)


#: the second look (DiagnoseSettings.second_look): no refit of the round within this many times the noise RMS.
#: Above what the discretization floor leaves on the benches' complete charts (at most 4x the noise: three-mass
#: drive at `substeps: 1`, noise 0.003), far below a chart that misses an effect outright (tanks bench, seed 2:
#: the best of the 5 places, an input clip, refitted to 19x; the spill, the 6th place, to 2.3x).
SECOND_LOOK = rules.value("far_above_noise")


def second_look_places(scr: Screen, best: list[Score], refits: list[tuple[Score, Fitted]], train: list[Dataset],
                 settings: DiagnoseSettings) -> list[Score]:
    """The next `top` significant places (the best option of each) when no refit of the round came within
    SECOND_LOOK x the noise: the score test ranks by the residual's first-order fall at a fit that misses an
    effect, and from a fit far off the record the missing effect's place can rank just below the cut."""
    if not settings.second_look or any(not far_above_noise(f, train, settings, SECOND_LOOK) for _, f in refits):
        return []
    have = {s.candidate.key for s in best}
    rest = [s for s in scr.best_per_place() if _significant(s, settings, _tests(scr)) and s.candidate.key not in have]
    return rest[: settings.top]


def union_picks(best: list[Score], picks: list[Score], scr: Screen) -> list[Score]:
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


#: one Gauss-Newton step is trusted to say where a refit goes when the training cost it reaches, simulated, falls
#: by at least this share of the fall its linearisation predicts: the trust-region rule that calls a step below it
#: poorly predicted (the trainer's own, fit.steps.TRUST_POOR); a poorly predicted step is shortened as the
#: trainer's trust radius is (fit.steps.TRUST_SHRINK)
ONE_STEP_TRUST = rules.value("trust_poor_gain")
ONE_STEP_SHRINK = rules.value("trust_shrink")


def _trusted_step(cost_at, current: Fitted, predicted: float) -> tuple[float | None, float]:
    """(t, rho): the longest t x the step, from 1 down by ONE_STEP_SHRINK, whose simulated training fall is at
    least ONE_STEP_TRUST of the linearised fall (2t - t^2) x `predicted`; t None when the step is shortened to a
    predicted fall below one unit of -2 log-likelihood at the residual's variance without being trusted (no guide
    at any length that matters)."""
    sigma2 = 2 * current.cost / max(current.n, 1)
    t, rho = 1.0, math.nan
    while predicted > 0 and sigma2 > 0:
        fall = (2 * t - t * t) * predicted
        rho = (current.cost - cost_at(t)) / fall
        if rho >= ONE_STEP_TRUST:
            return t, rho
        if 2 * fall / sigma2 < 1:
            break
        t *= ONE_STEP_SHRINK
    return None, rho


def one_step_relevant(best: list[Score], current: Fitted, train: list[Dataset], records,
                      settings: DiagnoseSettings, near: bool) -> tuple[list[Score], list[dict]]:
    """The places worth a refit, and REPORT.json's `one_step` rows ({candidate, step, rho, validation_rms,
    refitted}) for those judged; `near`: the current fit is near the noise (not :func:`far_above_noise` by
    ``SECOND_LOOK``).

    Each significant neutral candidate is moved along the Gauss-Newton step its score stands for and simulated.
    The step is trusted where its training cost falls by at least ONE_STEP_TRUST of the linearised fall (the
    trust-region ratio rho); a poorly predicted step is shortened, as a trust region is, to the longest trusted
    part (:func:`_trusted_step`). A trusted step says where a refit goes:
    * near the noise a fit is nearly linear and the whole step lands about where a brief refit ends (seed 11 of
      bench_diagnose_time.py, round 2: training cost falls predicted 0.24, 0.24, 0.12, refits reached 0.24, 0.24,
      0.12): a whole step that does not lower the validation RMS by ``min_gain`` (:func:`passes_gain`) is not
      refitted;
    * far above the noise one step falls short of a refit (the same seed, round 1: 701 predicted, 1729
      reached), and so does a shortened step: one that does not lower the validation RMS at all is not refitted
      (three-mass drive, seed 11, round 1: three such places, each refused when refitted; the complete two-mass
      chart, seed 11: two Coulomb terms whose whole steps were poorly predicted, each refitted in 75 s at N = 24
      and refused).
    A step not trusted at any length that matters is no guide: refitted."""
    if not (best and settings.one_step):
        return best, []
    keep, rows = [], []
    for s in best:
        line = one_step_line(s.candidate.diagram, s.step, train, records, settings) if (
            s.candidate.neutral and s.step and s.predicted_cost is not None) else None
        if line is None:
            keep.append(s)
            continue
        t, rho = _trusted_step(line[0], current, s.cost - s.predicted_cost)
        rms = line[1](t) if t is not None else math.nan
        bar = current.validation_rms * ((1 - settings.min_gain) if (near and t == 1.0) else 1.0)
        rows.append({"candidate": s.candidate.title(), "step": t, "rho": finite_or_none(rho),
                     "validation_rms": finite_or_none(rms), "refitted": t is None or rms < bar})
        if rows[-1]["refitted"]:
            keep.append(s)
    return keep, rows


def order_refits(refits: list[tuple[Score, Fitted]], settings: DiagnoseSettings) -> list[tuple[Score, Fitted]]:
    """Refitted candidates best first: by validation RMS, where those within half of `min_gain` of the best
    count as tied and go by the information criterion (the simpler of two equally good effects first)."""
    if not refits:
        return refits
    by_val = sorted(refits, key=lambda sf: sf[1].validation_rms)
    tol = by_val[0][1].validation_rms * (1 + settings.min_gain / 2)
    tied = [sf for sf in by_val if sf[1].validation_rms <= tol]
    rest = [sf for sf in by_val if sf[1].validation_rms > tol]
    return sorted(tied, key=lambda sf: sf[1].criterion(settings.criterion)) + rest


def passes_gain(after: Fitted, before: Fitted, settings: DiagnoseSettings) -> bool:
    """The first test of :func:`refusal`: the validation RMS falls by at least ``min_gain``. A refit that fails it
    against `before` fails it against any baseline that validates better."""
    return after.validation_rms < before.validation_rms * (1 - settings.min_gain)


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
    if not passes_gain(after, before, settings):
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

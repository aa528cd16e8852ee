"""Judging one diagnose run against its scenario's truth, and rates with Wilson 95 % intervals.

Per run (:func:`judge`), from REPORT.json's ``accepted`` list (``effect``, ``at``) in order:

* ``right_first`` (one or two missing): the first accepted (effect, at) is an answer one of the missing effects
  accepts (missing.py's table); None when no missing effect is expressible by the library;
* ``both`` (two missing): each missing effect is named by some accepted (effect, at), each by a different one;
* ``clean`` (complete chart): nothing accepted, apart from the scenario's tolerated completions (a damping
  beside a learned curve the user wrote without a viscous gain);
* ``refused``: diagnose declined the scenario: raised an SdnnError or ValueError (its messages to a user), or
  did not trace because its first fit did not converge; ``crashed``: any other exception (a bug to look at);
* ``true_refused`` (missing effects): a candidate that names a missing effect was refitted but not accepted
  (diagnose's own refusal of the truth: the round's reason says why); ``true_rank``: the best rank of such a
  candidate in round 1's score test (1 = ranked first; None: not scored).

A refused or crashed run counts as a miss in every rate (the rates are over all draws) and is also counted on
its own.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping

__all__ = ["wilson", "judge", "summarise", "Z95"]

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of k successes in n trials: ``(centre -+ half) / (1 + z^2/n)`` with
    ``centre = p + z^2/(2n)``, ``half = z sqrt(p (1 - p) / n + z^2 / (4 n^2))``; (0, 1) for n = 0."""
    if n == 0:
        return 0.0, 1.0
    if not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    p = k / n
    denominator = 1 + z * z / n
    centre = p + z * z / (2 * n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, (centre - half) / denominator), min(1.0, (centre + half) / denominator)


def judge(truth: Mapping, report: Mapping | None, error: str | None = None, crashed: bool = False) -> dict:
    """The verdict of one run: see the module docstring. `truth` is Scenario.truth (or truth.json); `error` the
    exception's text when diagnose raised, `crashed` when that was not one of its user-facing errors."""
    missing = truth["missing"]
    accepted = [(a["effect"], a["at"]) for a in (report or {}).get("accepted", [])]
    refused = not crashed and (error is not None or report is None
                               or report.get("stop") == "first_fit_not_converged")
    answers = [{tuple(a) for a in m["accept"]} for m in missing]
    names_truth = [c for c in (report or {}).get("candidates", []) if any((c["effect"], c["at"]) in a for a in answers)]
    first_round = [c["rank"] for c in names_truth if c.get("round") == 1 and c.get("score") is not None]
    verdict = {"accepted": [f"{e}@{p}" for e, p in accepted], "refused": refused, "crashed": crashed,
               "missing": [f"{m['kind']}@{m['place']}" for m in missing], "error": error,
               "right_first": None, "both": None, "clean": None,
               "true_refused": bool(missing) and any(c.get("refitted") and (c["effect"], c["at"]) not in accepted
                                                     for c in names_truth),
               "true_rank": min(first_round) if first_round else None}
    refused = refused or crashed
    if not missing:
        tolerated = {tuple(t) for t in truth.get("tolerated", ())}
        verdict["clean"] = not refused and all(a in tolerated for a in accepted)
        return verdict
    if any(answers):
        verdict["right_first"] = bool(accepted) and not refused and any(accepted[0] in a for a in answers)
    if len(missing) == 2:
        verdict["both"] = not refused and all(answers) and _matched(answers, accepted)
    return verdict


def _matched(answers: list[set], accepted: list[tuple[str, str]]) -> bool:
    """Each missing effect named by a different accepted entry (two effects: try both assignments)."""
    hits = [[i for i, a in enumerate(accepted) if a in ans] for ans in answers]
    return any(i != j for i in hits[0] for j in hits[1])


def _rate(name: str, values: list[bool]) -> str:
    k, n = sum(values), len(values)
    lo, hi = wilson(k, n)
    return f"{name} {k}/{n} = {k / n:.2f} [{lo:.3f}, {hi:.3f}]" if n else f"{name} -"


def summarise(rows: Iterable[Mapping]) -> list[str]:
    """One line per category (and per number of missing effects over every excitation): the rates with
    their 95 % Wilson intervals, refusals and the median wall time."""
    rows = list(rows)
    groups: dict[str, list[Mapping]] = {}
    for r in rows:
        groups.setdefault(r["category"], []).append(r)
        head = next(c for c in ("complete", "one-missing", "two-missing") if r["category"].startswith(c))
        groups.setdefault(head + " (all excitations)", []).append(r)
    lines = []
    for name in sorted(groups):
        g = groups[name]
        parts = []
        for key, label in (("right_first", "right effect at the right place first"), ("both", "both of two"),
                           ("clean", "nothing accepted")):
            values = [bool(r[key]) for r in g if r.get(key) is not None]
            if values:
                parts.append(_rate(label, values))
        unrated = sum(1 for r in g if r.get("missing") and r.get("right_first") is None)
        if unrated:
            parts.append(f"{unrated} not rated (no library effect states what is missing)")
        unexposed = sum(1 for r in g if r.get("unexposed"))
        if unexposed:
            parts.append(f"{unexposed} with a clip the training record never reaches (rated all the same)")
        parts.append(_rate("refused", [bool(r["refused"]) for r in g]))
        if any(r.get("crashed") for r in g):
            parts.append(_rate("crashed", [bool(r.get("crashed")) for r in g]))
        with_truth = [bool(r.get("true_refused")) for r in g if r.get("missing")]
        if with_truth:
            parts.append(_rate("the true effect refitted and refused", with_truth))
        seconds = [r["seconds"] for r in g if r.get("seconds") is not None]
        if seconds:
            parts.append(f"median time {statistics.median(seconds):.0f} s")
        lines.append(f"{name} (n={len(g)}): " + "; ".join(parts))
    return lines

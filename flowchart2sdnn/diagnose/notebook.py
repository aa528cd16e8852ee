"""A diagnosis as a notebook shows it: one line (``repr``), a short text (``summary()``), an HTML fragment
(``_repr_html_``: the page's verdict, rounds, best candidates, final parameters and warnings) and its tables as
rows. The whole report stays in REPORT.json (``to_json()``) and ``sdnn diagnose``'s text and page.

Layer: diagnose.
"""

from __future__ import annotations

from html import escape

from ..identify.notebook import (
    MAX_WARNINGS,
    STYLE,
    count,
    g,
    html_list,
    html_table,
    short,
)
from ..identify.notebook import summary_html as identification_html
from ..identify.notebook import summary_text as identification_text
from ..tables import table
from .result import Diagnosis, FitSummary

__all__ = ["one_line", "summary_text", "summary_html", "candidate_rows", "round_rows", "CANDIDATE_COLUMNS",
           "ROUND_COLUMNS"]

CANDIDATE_COLUMNS = ("round", "rank", "effect", "at", "label", "score", "p_value", "refitted", "achieved_decrease",
                     "validation_rms_after", "start", "error")
ROUND_COLUMNS = ("round", "effect", "at", "label", "accepted", "reason", "rms_before", "rms_after",
                 "validation_rms_before", "validation_rms_after", "bic_before", "bic_after")
#: the best candidates shown per round, and at most this many in all (every one: candidates_table())
BEST, BEST_ALL = 3, 9


def candidate_rows(d: Diagnosis) -> list[dict]:
    """Every scored candidate of every round, ranked per round, with its refit where it had one."""
    return [{"round": c.round, "rank": c.rank, "effect": c.effect, "at": c.at, "label": c.label, "score": c.score,
             "p_value": c.p_value, "refitted": c.refit is not None,
             "achieved_decrease": c.refit.achieved_decrease if c.refit else None,
             "validation_rms_after": c.refit.validation_rms_after if c.refit else None,
             "start": c.refit.start if c.refit else None, "error": c.error} for c in d.candidates]


def round_rows(d: Diagnosis) -> list[dict]:
    """Each round's decision: the effect, accepted or why not, train and validation RMS and BIC before/after."""
    return [{k: getattr(r, k) for k in ROUND_COLUMNS} for r in d.rounds]


def _stop(d: Diagnosis) -> str:
    from .summary import STOP_MESSAGES

    text = STOP_MESSAGES.get(d.stop, d.stop)
    if d.stop == "done_after_accepting" and d.last_round:
        text += f" ({STOP_MESSAGES.get(d.last_round, d.last_round)})"
    return text


def _name(d: Diagnosis) -> str:
    return d.identification.source.name


def _accepted(d: Diagnosis) -> str:
    return ", ".join(a.title for a in d.accepted) or "nothing"


def _arrow(a, b) -> str:
    return f"{g(a)} -> {g(b)}"


def one_line(d: Diagnosis) -> str:
    """``<Diagnosis 'one_mass': accepted friction at v, validation RMS 0.147 -> 0.0213, stop done_after_...>``."""
    warn = f", {count(len(d.warnings), 'warning')}" if d.warnings else ""
    return (f"<Diagnosis '{_name(d)}': accepted {_accepted(d)}, validation RMS "
            f"{_arrow(d.before.validation_rms, d.after.validation_rms)}, stop {d.stop}{warn}>")


def _fits(before: FitSummary, after: FitSummary, criterion: str) -> list[list[str]]:
    return [["train RMS", g(before.rms), g(after.rms)],
            ["validation RMS", g(before.validation_rms), g(after.validation_rms)],
            [criterion.upper(), g(getattr(before, criterion), 8), g(getattr(after, criterion), 8)]]


def _round_cells(d: Diagnosis) -> list[list[str]]:
    return [[r.title, "yes" if r.accepted else "no", _arrow(r.validation_rms_before, r.validation_rms_after),
             "" if r.accepted else short(r.reason, 120)] for r in d.rounds]


def _best(d: Diagnosis) -> list[list[str]]:
    """The `BEST` best scored candidates of each round."""
    return [[c.round, c.rank, c.title, g(c.score), g(c.p_value, 2),
             g(c.refit.validation_rms_after) if c.refit else ""]
            for c in d.candidates if c.rank <= BEST and c.score is not None][:BEST_ALL]


FIT_HEAD = ["", "chart as given", "final chart"]
ROUND_HEAD = ["effect", "accepted", "validation RMS", "why not"]
BEST_HEAD = ["round", "rank", "candidate", "score", "p", "val RMS refitted"]


def _warnings(d: Diagnosis) -> tuple[str, ...]:
    # the final fit's own warnings are listed with its parameters
    return tuple(w for w in d.warnings if w not in d.identification.warnings)


def summary_text(d: Diagnosis) -> str:
    """The verdict, the error before and after, each round's decision, the best candidates, the final chart's
    parameters (with units, ± standard error and %) and the warnings: a short text."""
    crit = d.settings.criterion
    out = [f"diagnosis of chart '{_name(d)}': accepted {_accepted(d)}", f"stopped: {short(_stop(d))}", "",
           table(FIT_HEAD, _fits(d.before, d.after, crit)).rstrip()]
    if d.rounds:
        out += ["", table(ROUND_HEAD, _round_cells(d)).rstrip()]
    best = _best(d)
    if best:
        out += ["", f"best candidates ({len(d.candidates)} scored; all: .candidates_table()):",
                table(BEST_HEAD, best).rstrip()]
    own = _warnings(d)
    if own:
        out += ["", "warnings:"] + [f"- {short(w)}" for w in own[:MAX_WARNINGS]]
    out += ["", identification_text(d.identification, f"final chart: {d.identification.status}").rstrip()]
    return "\n".join(out) + "\n"


def summary_html(d: Diagnosis) -> str:
    """The page's sections as one HTML fragment (a few kB, no figures): verdict, before and after, rounds, best
    candidates, warnings, the final chart's identification."""
    parts = [f"<div class=\"sdnn\">{STYLE}<h4>Diagnosis of chart '{escape(_name(d))}'</h4>",
             f"<p><b>accepted</b>: {escape(_accepted(d))}<br><b>stopped</b>: {escape(short(_stop(d)))}</p>",
             "<h4>Before and after</h4>" + html_table(FIT_HEAD, _fits(d.before, d.after, d.settings.criterion))]
    if d.rounds:
        parts.append("<h4>Rounds</h4>" + html_table(ROUND_HEAD, _round_cells(d), left=2))
    best = _best(d)
    if best:
        parts.append(f"<h4>Candidates, best first</h4><p>{len(d.candidates)} scored; all: "
                     "<code>.candidates_table()</code></p>" + html_table(BEST_HEAD, best, left=3))
    own = _warnings(d)
    if own:
        parts.append("<h4>Warnings</h4>" + html_list(own, more=".warnings"))
    parts.append(identification_html(d.identification, "Final chart, identified", heading="h5", style=False))
    return "".join(parts) + "</div>"

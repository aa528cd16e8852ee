"""Results as a notebook shows them: one line (``repr``), a short text (``summary()``) and an HTML fragment
(``_repr_html_``: the page's sections without figures) for an identification and a diagnosis.

Short on purpose: a result holds traces of thousands of numbers (cost history, multi-start starts, quasi-online
trajectories, every candidate's score) that belong in RESULT.json / REPORT.json and the pages, not in a cell's
output. Long warnings and long tables are cut, saying how many were left out and where to find them. The
results ask for these views by name (:mod:`flowchart2sdnn.views`, registered by :mod:`flowchart2sdnn.report`).

Layer: report.
"""

from __future__ import annotations

from html import escape

from ..diagnose.result import Diagnosis, FitSummary
from ..identify import Identification, fit_rows, parameter_rows
from ..tables import table
from .diagnose_text import STOP_MESSAGES

__all__ = ["identification_line", "identification_text", "identification_html", "diagnosis_line",
           "diagnosis_text", "diagnosis_html"]

#: at most this many parameter rows, warnings, and characters of one warning or message are shown
MAX_ROWS, MAX_WARNINGS, MAX_CHARS = 30, 6, 240


def g(x, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def short(text: str, limit: int = MAX_CHARS) -> str:
    """`text` on one line, cut at `limit` characters (with an ellipsis)."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1].rstrip() + "\u2026"


def _status(ident: Identification) -> str:
    how = {True: "converged", False: "not converged", None: ""}[ident.converged]
    return ident.status + (f" ({how})" if how else "") + (", interrupted" if ident.interrupted else "")


def identification_line(ident: Identification) -> str:
    """``<Identification 'engine': 3 parameters (2 free), small_cost_change (converged), fit w1 97.2 %, ...>``."""
    free = sum(1 for e in ident.parameters.values() if not e.fixed)
    fit = ", ".join(f"{o} {g(p, 3)} %" if p is not None else f"{o} diverged"
                    for o, p in ident.fit.train.fit_percent.items())
    curves = f", {count(len(ident.curves), 'curve')}" if ident.curves else ""
    warn = f", {count(len(ident.warnings), 'warning')}" if ident.warnings else ""
    return (f"<Identification '{ident.source.name}': {count(len(ident.parameters), 'parameter')} ({free} free)"
            f"{curves}, {_status(ident)}, train fit {fit or 'none'}{warn}>")


def count(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _parameter_cells(ident: Identification) -> list[list[str]]:
    rows = []
    for r in parameter_rows(ident)[:MAX_ROWS]:
        if r["fixed"]:
            err = "fixed"
        elif r["stderr"] is None:
            err = ""
        else:
            err = f"± {g(r['stderr'], 2)}" + (f" ({g(r['stderr_percent'], 2)} %)" if r["stderr_percent"] is not None
                                             else "")
        ci = f"[{g(r['ci95_low'])}, {g(r['ci95_high'])}]" if r["ci95_low"] is not None else ""
        rows.append([r["parameter"], g(r["value"], 5), r["unit"] or "", err, ci])
    return rows


def _fit_cells(ident: Identification) -> list[list[str]]:
    return [[r["record"], r["output"], g(r["rms"]), g(r["fit_percent"], 4), r["rows"]] for r in fit_rows(ident)]


PARAMETER_HEAD = ["parameter", "value", "unit", "± stderr (%)", "95 % interval"]
FIT_HEAD = ["record", "output", "RMS", "fit %", "rows"]


def _more(n: int, what: str, where: str) -> str:
    return f"(+{n} more {what}: {where})" if n > 0 else ""


def identification_text(ident: Identification, title: str | None = None) -> str:
    """Status, parameters with units, ± standard error and %, fit per output, curves, warnings: a few lines."""
    out = [title or f"identification of chart '{ident.source.name}': {_status(ident)}"]
    if ident.message:
        out.append("  " + short(ident.message))
    if ident.parameters:
        out += ["", table(PARAMETER_HEAD, _parameter_cells(ident)).rstrip()]
        if len(ident.parameters) > MAX_ROWS:
            out.append(_more(len(ident.parameters) - MAX_ROWS, "parameters", ".parameters_table()"))
    if ident.curves:
        out.append("learned curves: " + ", ".join(f"{b} ({len(c.a)} tanh terms, slope at 0 {g(c.slope_at_zero)})"
                                                    for b, c in ident.curves.items()))
    out += ["", table(FIT_HEAD, _fit_cells(ident)).rstrip()]
    if ident.warnings:
        out += ["", "warnings:"] + [f"- {short(coded(n))}" for n in ident.notices[:MAX_WARNINGS]]
        if len(ident.warnings) > MAX_WARNINGS:
            out.append(_more(len(ident.warnings) - MAX_WARNINGS, "warnings", ".warnings"))
    return "\n".join(out).rstrip() + "\n"


#: the fragment's one style rule: numbers right-aligned, the first n columns of a table of class ln (names) left
STYLE = ("<style>.sdnn td,.sdnn th{text-align:right;padding:1px 6px}.sdnn table{border-collapse:collapse}"
         + ",".join(f".sdnn .l{n} {c}:nth-child(-n+{n})" for n in (1, 2, 3) for c in ("td", "th"))
         + "{text-align:left}</style>")


def html_table(head: list[str], rows: list[list], left: int = 1) -> str:
    """A plain HTML table (the first `left` columns, 1 to 3, left-aligned, the rest numbers; see STYLE)."""
    def cells(tag: str, row) -> str:
        return "".join(f"<{tag}>{escape(str(c))}</{tag}>" for c in row)
    return (f"<table class=l{left}><tr>" + cells("th", head) + "</tr>"
            + "".join(f"<tr>{cells('td', r)}</tr>" for r in rows) + "</table>")


def coded(notice) -> str:
    """A warning with its code in front (``[FLOOR001] the discretization floor ...``), bare when it has none."""
    return f"[{notice.code}] {notice.message}" if notice.code else notice.message


def html_list(items, limit: int = MAX_WARNINGS, more: str = "") -> str:
    items = list(items)
    lis = "".join(f"<li>{escape(short(w))}</li>" for w in items[:limit])
    tail = f"<p>{escape(_more(len(items) - limit, 'items', more))}</p>" if len(items) > limit else ""
    return f"<ul>{lis}</ul>{tail}"


def identification_html(ident: Identification, title: str | None = None, heading: str = "h4",
                        style: bool = True) -> str:
    """The page's status, parameter, fit and warning sections as one HTML fragment (a few kB, no figures);
    `title` heads it (an h4), `heading` is the sections' heading tag, `style` False leaves out the style rule
    (a fragment inside another that has it)."""
    h = heading
    title = title or f"Identification of chart '{ident.source.name}'"
    parts = [f"<div class=\"sdnn\">{STYLE if style else ''}<h4>{escape(title)}</h4>",
             f"<p><b>status</b>: {escape(_status(ident))}"
             + (f" &mdash; {escape(short(ident.message))}" if ident.message else "") + "</p>"]
    if ident.parameters:
        parts.append(f"<{h}>Parameters</{h}>" + html_table(PARAMETER_HEAD, _parameter_cells(ident), left=1))
        if len(ident.parameters) > MAX_ROWS:
            parts.append(f"<p>{escape(_more(len(ident.parameters) - MAX_ROWS, 'parameters', '.parameters_table()'))}"
                         "</p>")
    if ident.curves:
        parts.append("<p>learned curves: " + escape(", ".join(f"{b} ({len(c.a)} tanh terms)"
                                                              for b, c in ident.curves.items())) + "</p>")
    parts.append(f"<{h}>Fit</{h}>" + html_table(FIT_HEAD, _fit_cells(ident), left=2))
    if ident.warnings:
        parts.append(f"<{h}>Warnings</{h}>" + html_list(map(coded, ident.notices), more=".warnings"))
    return "".join(parts) + "</div>"


# ------------------------------------------------------------------------------------------------ diagnosis
#: the best candidates shown per round, and at most this many in all (every one: candidates_table())
BEST, BEST_ALL = 3, 9


def _stop(d: Diagnosis) -> str:
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


def diagnosis_line(d: Diagnosis) -> str:
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


BEFORE_AFTER_HEAD = ["", "chart as given", "final chart"]
ROUND_HEAD = ["effect", "accepted", "validation RMS", "why not"]
BEST_HEAD = ["round", "rank", "candidate", "score", "p", "val RMS refitted"]


def _warnings(d: Diagnosis) -> tuple[str, ...]:
    # the final fit's own warnings are listed with its parameters
    return tuple(coded(n) for n in d.notices if n.message not in d.identification.warnings)


def diagnosis_text(d: Diagnosis) -> str:
    """The verdict, the error before and after, each round's decision, the best candidates, the final chart's
    parameters (with units, ± standard error and %) and the warnings: a short text."""
    crit = d.settings.criterion
    out = [f"diagnosis of chart '{_name(d)}': accepted {_accepted(d)}", f"stopped: {short(_stop(d))}", "",
           table(BEFORE_AFTER_HEAD, _fits(d.before, d.after, crit)).rstrip()]
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


def diagnosis_html(d: Diagnosis) -> str:
    """The page's sections as one HTML fragment (a few kB, no figures): verdict, before and after, rounds, best
    candidates, warnings, the final chart's identification."""
    parts = [f"<div class=\"sdnn\">{STYLE}<h4>Diagnosis of chart '{escape(_name(d))}'</h4>",
             f"<p><b>accepted</b>: {escape(_accepted(d))}<br><b>stopped</b>: {escape(short(_stop(d)))}</p>",
             "<h4>Before and after</h4>"
             + html_table(BEFORE_AFTER_HEAD, _fits(d.before, d.after, d.settings.criterion))]
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

"""An identification as a notebook shows it: one line (``repr``), a short text (``summary()``), an HTML fragment
(``_repr_html_``: the status, parameter, fit and warning sections of the page) and its tables as rows.

Short on purpose: a result holds traces of thousands of numbers (cost history, multi-start starts, quasi-online
trajectories) that belong in RESULT.json and the page, not in a cell's output. Long warnings and long tables
are cut, saying how many were left out and where to find them.

Layer: identify.
"""

from __future__ import annotations

from html import escape

from ..tables import table
from .result import Identification, Metrics

__all__ = ["one_line", "summary_text", "summary_html", "parameter_rows", "fit_rows", "short", "count", "html_table", "STYLE",
           "html_list", "PARAMETER_COLUMNS", "FIT_COLUMNS", "MAX_ROWS", "MAX_WARNINGS", "MAX_CHARS"]

#: at most this many parameter rows, warnings, and characters of one warning or message are shown
MAX_ROWS, MAX_WARNINGS, MAX_CHARS = 30, 6, 240
PARAMETER_COLUMNS = ("parameter", "value", "unit", "stderr", "stderr_percent", "ci95_low", "ci95_high", "init",
                     "fixed")
FIT_COLUMNS = ("record", "output", "rms", "fit_percent", "cost", "rows")


def g(x, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def short(text: str, limit: int = MAX_CHARS) -> str:
    """`text` on one line, cut at `limit` characters (with an ellipsis)."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1].rstrip() + "\u2026"


def _percent(value: float, stderr: float | None) -> float | None:
    return None if stderr is None or not value else 100.0 * stderr / abs(value)


def parameter_rows(ident: Identification) -> list[dict]:
    """One row per chart parameter: value, unit, standard error (also in % of the value), 95 % interval, init."""
    return [{"parameter": n, "value": e.value, "unit": e.unit, "stderr": e.stderr,
             "stderr_percent": _percent(e.value, e.stderr), "ci95_low": e.ci95[0] if e.ci95 else None,
             "ci95_high": e.ci95[1] if e.ci95 else None, "init": e.init, "fixed": e.fixed}
            for n, e in ident.parameters.items()]


def fit_rows(ident: Identification) -> list[dict]:
    """One row per record (train, validation) and output: RMS, fit %, cost E, rows scored."""
    out = []
    for which, m in (("train", ident.fit.train), ("validation", ident.fit.validation)):
        if isinstance(m, Metrics):
            out += [{"record": which, "output": o, "rms": m.rms[o], "fit_percent": m.fit_percent.get(o),
                     "cost": m.cost, "rows": m.rows} for o in m.rms]
    return out


def _status(ident: Identification) -> str:
    how = {True: "converged", False: "not converged", None: ""}[ident.converged]
    return ident.status + (f" ({how})" if how else "") + (", interrupted" if ident.interrupted else "")


def one_line(ident: Identification) -> str:
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


def summary_text(ident: Identification, title: str | None = None) -> str:
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
        out += ["", "warnings:"] + [f"- {short(w)}" for w in ident.warnings[:MAX_WARNINGS]]
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


def html_list(items, limit: int = MAX_WARNINGS, more: str = "") -> str:
    items = list(items)
    lis = "".join(f"<li>{escape(short(w))}</li>" for w in items[:limit])
    tail = f"<p>{escape(_more(len(items) - limit, 'items', more))}</p>" if len(items) > limit else ""
    return f"<ul>{lis}</ul>{tail}"


def summary_html(ident: Identification, title: str | None = None, heading: str = "h4", style: bool = True) -> str:
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
        parts.append(f"<{h}>Warnings</{h}>" + html_list(ident.warnings, more=".warnings"))
    return "".join(parts) + "</div>"

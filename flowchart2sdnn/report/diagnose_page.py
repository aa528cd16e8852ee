"""`sdnn diagnose --html REPORT.html`: the diagnosis as one self-contained page.

The page holds the chart's name, the command line that reproduces the run, how it ended (the stopping rule,
the first fit's convergence, the final fit's status) with every warning and note the command line printed, the
error of the chart as given, the ranked candidates of every round (the score test's predicted decrease of the
cost, its p-value, and for the refitted ones the achieved decrease and validation RMS; which one was accepted,
and why when it is not rank 1), the before/after of every round (train and validation RMS, AIC, validation fit %; accepted or
why not), for every accepted effect the residual against the signal it attaches to before and after
(:func:`.diagnose_plots.figures`), the residual autocorrelation before and after, and the final chart as an
identification report (parameters with intervals and units, fit, compare, residual and Bode figures; see
:mod:`.identify_page`). Figures are embedded PNGs; nothing is loaded from elsewhere.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..data.csvdata import Dataset
from ..diagnose.loop import Diagnosis
from ..identify import Metrics
from ..notices import Notice
from .diagnose_plots import figures
from .diagnose_text import STOP_MESSAGES, fit_percent_change, shown_candidate_rows
from .html import chart_section, esc, figure, page, paragraph, section, table
from .identify_page import identification_sections, status_paragraphs

__all__ = ["diagnosis_html"]


def _g(x, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _arrow(a, b, digits: int = 4) -> str:
    return f"{_g(a, digits)} → {_g(b, digits)}" if b is not None else _g(a, digits)


def _effect(a: dict) -> str:
    return f"{a['effect']} at {a['at']}" + (f" ({a['label']})" if a.get("label") else "")


def _candidates(report: dict, limit: int) -> list[str]:
    criterion = report["settings"].get("criterion", "aic").upper()
    parts = [paragraph("rank = order of the score: the decrease of the cost E predicted by one Gauss-Newton step "
                       "from the current fit (a score test). The best few are refitted (achieved decrease, "
                       "validation RMS), and the refits, not the ranks, decide: they are ordered by validation RMS "
                       f"(near-ties by {criterion}), and the first whose validation error and {criterion} both fall "
                       "is accepted. So the accepted effect need not be rank 1.")]
    for r in sorted({c["round"] for c in report["candidates"]}):
        cands = [c for c in report["candidates"] if c["round"] == r]
        rows, hidden = shown_candidate_rows(cands, limit)
        entry = next((e for e in report["rounds"] if e["round"] == r), None)
        won = (entry["effect"], entry["at"], entry.get("label") or "") if entry and entry["accepted"] else None
        for row in rows:
            row.append("accepted" if won == (row[1], row[2], row[3]) else "")
        parts.append(f"<h3>round {r}: {len(cands)} candidates scored</h3>")
        if rows:
            parts.append(table(["rank", "effect", "at", "option", "score", "p", "achieved", "from", "val RMS", ""],
                               rows, left=4))
        if won and rows and (rows[0][1], rows[0][2], rows[0][3]) != won:
            rank = next((row[0] for row in rows if (row[1], row[2], row[3]) == won), "?")
            parts.append(paragraph(f"round {r}: accepted {_effect(entry)} (rank {rank}), not rank 1 "
                                   f"{rows[0][1]} at {rows[0][2]}: its refit gave the lower validation RMS "
                                   f"{_g(entry['validation_rms_after'])} (rank 1's refit: "
                                   f"{rows[0][8] or 'not refitted'})."))
        if hidden:
            parts.append(paragraph(f"({hidden} more: other options of these places, lower scores, or failures)"))
    return parts


def _rounds(report: dict) -> list[str]:
    rows = [[r["round"], _effect(r), "yes" if r["accepted"] else "no", _arrow(r["rms_before"], r["rms_after"]),
             _arrow(r["validation_rms_before"], r["validation_rms_after"]),
             _arrow(r["aic_before"], r["aic_after"], 8),
             fit_percent_change(r.get("before") or {}, r.get("after") or {})]
            for r in report["rounds"]]
    parts = [table(["round", "effect", "accepted", "train RMS", "validation RMS", "AIC", "val fit %"], rows,
                   left=3)] if rows else []
    parts += [paragraph(f"round {r['round']}: not accepted - {r['reason']}") for r in report["rounds"]
              if not r["accepted"]]
    return parts


def _status(diagnosis: Diagnosis, notes: Sequence[Notice | str]) -> list[str]:
    """How the run ended and every warning the command line printed: its notes on the data, the first fit's
    convergence, the stopping rule, the final fit's status and warnings (as the text report prints them)."""
    report = diagnosis.report
    stop = STOP_MESSAGES.get(report["stop"], report["stop"])
    last = report.get("last_round")
    if report["stop"] == "done_after_accepting" and last:
        stop += f" ({STOP_MESSAGES.get(last, last)})"
    parts = [paragraph(f"stopped: {stop}", "warn" if report["stop"] == "first_fit_not_converged" else "")]
    if report.get("interrupted"):
        parts.append(paragraph("interrupted: the chart and report hold what was accepted before Ctrl-C", "warn"))
    first = report.get("first_fit") or {}
    if first.get("converged") is False:
        moving = ", ".join(first.get("still_moving") or [])
        parts.append(paragraph(f"the first fit of the chart as given did not converge: {first.get('status')} - "
                               f"{first.get('message')}" + (f" (still moving: {moving})" if moving else ""), "warn"))
    parts += [paragraph(n.one_line("note") if isinstance(n, Notice) else f"note: {n}", "warn") for n in notes]
    parts.append(paragraph("final chart's fit:"))
    parts += status_paragraphs(diagnosis.final.identification)
    return parts


def diagnosis_html(diagnosis: Diagnosis, train: Dataset, validation: Sequence[Dataset] = (),
                   command: str = "", notes: Sequence[Notice | str] = (), limit: int = 10, lags: int | None = None) -> str:
    """The whole page (see the module docstring); `train` the first training record, `validation` the
    validation records as given to :func:`flowchart2sdnn.diagnose.loop.diagnose`, `command` the command line
    that reproduces the run, `notes` what the command line printed about the data, `lags` those of the final
    chart's residual analysis (default: from its dynamics)."""
    report = diagnosis.report
    before = report["before"]
    name = diagnosis.nominal.diagram.name
    accepted = report.get("accepted") or []
    head = []
    if diagnosis.nominal.diagram.description:
        head.append(paragraph(diagnosis.nominal.diagram.description))
    if command:
        head.append(f"<p>command: <code>{esc(command)}</code></p>")
    status = _status(diagnosis, notes)
    # green only when something was accepted and nothing on the page warns
    clean = accepted and not any('class="warn"' in part for part in status)
    head.append(paragraph("accepted: " + (", ".join(_effect(a) for a in accepted) or "nothing"),
                          "ok" if clean else ""))
    head += status
    head.append(paragraph(f"chart as given: train RMS {_g(before['rms'])}, validation RMS "
                          f"{_g(before['validation_rms'])}, AIC {_g(before['aic'], 8)}, BIC {_g(before['bic'], 8)}"))
    parts = [*head, section("Candidates, ranked", _candidates(report, limit), "candidates")]
    figs = figures(diagnosis, train, resid=False, lags=lags)
    effect_figs = [figure(fig, f"Residual against {file[9:-4]}: the chart as given (left) and the final chart "
                          "(right).", file[:-4]) for file, fig in figs if file.startswith("residual_")]
    white = [figure(fig, "Residual autocorrelation of the chart as given and of the final chart, with the 99 % band "
                    "(the text report's whiteness test uses 25 lags).", "whiteness")
             for file, fig in figs if file == "whiteness.png"]
    parts.append(section("Before and after", [*_rounds(report), *effect_figs, *white], "rounds"))
    final = diagnosis.final.identification
    records = [(f"training: {Path(train.path).name}", train, 0)]
    split = report["settings"].get("split")
    window = report["settings"].get("init_window") or 0
    checks = [(f"validation: {Path(v.path).name}", v, 0) for v in validation]
    if split is not None:
        n = max(3, int(round(split * train.n_rows)))
        records = [(records[0][0], train.slice(0, n), 0)]
        checks = [(f"validation: {Path(train.path).name} after the split", train, n)]
    # the final chart's validation as diagnose scored it (its own init window, no per-record values fitted)
    note = ("free run over the whole record, scored after the split" if split is not None else
            f"free run from the initial state fitted on the first {window} samples" if window else None)
    scored = [Metrics(m["rows"], m["cost"], dict(m["rms"]), dict(m["fit_percent"]), note=note)
              for m in diagnosis.final.validation.get("records", [])]
    final_parts = identification_sections(final, records, checks, lags=lags, scored=(scored, window, ()))
    parts.append(section("Final chart", [paragraph(f"'{diagnosis.diagram.name}' with the accepted effects, "
                                                   "identified:")], "final"))
    parts += final_parts
    added = {b.name for b in diagnosis.diagram.blocks} - {b.name for b in diagnosis.nominal.diagram.blocks}
    parts.append(chart_section(diagnosis.diagram, added, "The final chart (added blocks in orange)"))
    return page(f"{name}: diagnosis", parts, f"diagnosis of chart '{name}' on {Path(train.path).name}")

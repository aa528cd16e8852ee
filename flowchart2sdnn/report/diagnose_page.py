"""`sdnn diagnose --html REPORT.html`: the diagnosis as one self-contained page.

The page holds the chart's name, the error of the chart as given, the ranked candidates of every round (the
score test's predicted decrease of the cost, its p-value, and for the refitted ones the achieved decrease and
validation RMS), the before/after of every round (train and validation RMS, AIC, validation fit %; accepted or
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
from .diagnose_plots import figures
from .diagnose_text import STOP_MESSAGES, _candidate_rows, _fit_pct
from .html import chart_section, esc, figure, page, paragraph, section, table
from .identify_page import identification_sections

__all__ = ["diagnosis_html"]


def _g(x, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _arrow(a, b, digits: int = 4) -> str:
    return f"{_g(a, digits)} → {_g(b, digits)}" if b is not None else _g(a, digits)


def _effect(a: dict) -> str:
    return f"{a['effect']} at {a['at']}" + (f" ({a['label']})" if a.get("label") else "")


def _candidates(report: dict, limit: int) -> list[str]:
    parts = [paragraph("score = the decrease of the cost E predicted by one Gauss-Newton step from the current "
                       "fit (a score test); the best few are refitted: achieved decrease and validation RMS.")]
    for r in sorted({c["round"] for c in report["candidates"]}):
        cands = [c for c in report["candidates"] if c["round"] == r]
        rows, hidden = _candidate_rows(cands, limit)
        parts.append(f"<h3>round {r}: {len(cands)} candidates scored</h3>")
        if rows:
            parts.append(table(["rank", "effect", "at", "option", "score", "p", "achieved", "from", "val RMS"],
                               rows, left=4))
        if hidden:
            parts.append(paragraph(f"({hidden} more: other options of these places, lower scores, or failures)"))
    return parts


def _rounds(report: dict) -> list[str]:
    rows = [[r["round"], _effect(r), "yes" if r["accepted"] else "no", _arrow(r["rms_before"], r["rms_after"]),
             _arrow(r["validation_rms_before"], r["validation_rms_after"]),
             _arrow(r["aic_before"], r["aic_after"], 8), _fit_pct(r.get("before") or {}, r.get("after") or {})]
            for r in report["rounds"]]
    parts = [table(["round", "effect", "accepted", "train RMS", "validation RMS", "AIC", "val fit %"], rows,
                   left=3)] if rows else []
    parts += [paragraph(f"round {r['round']}: not accepted - {r['reason']}") for r in report["rounds"]
              if not r["accepted"]]
    return parts


def diagnosis_html(diagnosis: Diagnosis, train: Dataset, validation: Sequence[Dataset] = (),
                   command: str = "", limit: int = 10) -> str:
    """The whole page (see the module docstring); `train` the first training record, `validation` the
    validation records as given to :func:`flowchart2sdnn.diagnose.loop.diagnose`."""
    report = diagnosis.report
    before = report["before"]
    name = diagnosis.nominal.diagram.name
    accepted = report.get("accepted") or []
    head = []
    if diagnosis.nominal.diagram.description:
        head.append(paragraph(diagnosis.nominal.diagram.description))
    if command:
        head.append(f"<p>command: <code>{esc(command)}</code></p>")
    head.append(paragraph("accepted: " + (", ".join(_effect(a) for a in accepted) or "nothing"),
                          "ok" if accepted else ""))
    head.append(paragraph(f"stopped: {STOP_MESSAGES.get(report['stop'], report['stop'])}"))
    if report.get("interrupted"):
        head.append(paragraph("interrupted: the chart and report hold what was accepted before Ctrl-C", "warn"))
    head.append(paragraph(f"chart as given: train RMS {_g(before['rms'])}, validation RMS "
                          f"{_g(before['validation_rms'])}, AIC {_g(before['aic'], 8)}, BIC {_g(before['bic'], 8)}"))
    parts = [*head, section("Candidates, ranked", _candidates(report, limit), "candidates")]
    figs = figures(diagnosis, train, resid=False)
    effect_figs = [figure(fig, f"Residual against {file[9:-4]}: the chart as given (left) and the final chart "
                          "(right).", file[:-4]) for file, fig in figs if file.startswith("residual_")]
    white = [figure(fig, "Residual autocorrelation before and after, with the 99 % band.", "whiteness")
             for file, fig in figs if file == "whiteness.png"]
    parts.append(section("Before and after", [*_rounds(report), *effect_figs, *white], "rounds"))
    final = diagnosis.final.identification
    records = [(f"training: {Path(train.path).name}", train, 0)]
    split = report["settings"].get("split")
    checks = [(f"validation: {Path(v.path).name}", v, 0) for v in validation]
    if split is not None:
        n = max(3, int(round(split * train.n_rows)))
        records = [(records[0][0], train.slice(0, n), 0)]
        checks = [(f"validation: {Path(train.path).name} after the split", train, n)]
    final_parts = identification_sections(final, records, checks)
    parts.append(section("Final chart", [paragraph(f"'{diagnosis.diagram.name}' with the accepted effects, "
                                                   "identified:")], "final"))
    parts += final_parts
    added = {b.name for b in diagnosis.diagram.blocks} - {b.name for b in diagnosis.nominal.diagram.blocks}
    parts.append(chart_section(diagnosis.diagram, added, "The final chart (added blocks in orange)"))
    return page(f"{name}: diagnosis", parts, f"diagnosis of chart '{name}' on {Path(train.path).name}")

"""The text report of a diagnosis (a pure function of the REPORT.json document)."""

from __future__ import annotations

from ..identify import from_document
from ..tables import table
from .identify_text import format_result

__all__ = ["format_report", "STOP_MESSAGES", "shown_candidate_rows", "fit_percent_change"]

STOP_MESSAGES = {
    "rounds": "the round limit (--rounds) was reached",
    "nothing_significant": "no candidate's score test was significant",
    "nothing_accepted": "no refitted candidate lowered both the validation error and the information criterion",
    "no_candidates": "no effect of the library attaches anywhere in the chart",
    "done_after_accepting": "effects were accepted, then the next round found nothing more to accept",
    "first_fit_not_converged": "the first fit of the chart as given stopped while parameters still moved by more "
                               "than their standard error: nothing was traced (raise --max-iter, improve the "
                               "chart's init, or --allow-unconverged)",
    "interrupted": "interrupted (Ctrl-C)",
}


def _g(x, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _arrow(a, b, digits: int = 4) -> str:
    return f"{_g(a, digits)} -> {_g(b, digits)}" if b is not None else _g(a, digits)


def shown_candidate_rows(cands: list[dict], limit: int) -> tuple[list[list], int]:
    """The best option of each (effect, place) and every refitted candidate, at most `limit` others."""
    rows, hidden, seen = [], 0, set()
    for c in cands:
        key = (c["effect"], c["at"])
        shown = c.get("refitted") or (c.get("score") is not None and key not in seen and len(rows) < limit)
        seen.add(key)
        if not shown:
            hidden += 1
            continue
        rows.append([c["rank"], c["effect"], c["at"], c.get("label") or "", _g(c.get("score")),
                     _g(c.get("p_value"), 2), _g(c.get("achieved_decrease")) if c.get("refitted") else "",
                     c.get("start") or "", _g(c.get("validation_rms_after")) if c.get("refitted") else ""])
    return rows, hidden


def _whiteness(w: dict) -> str:
    if not w or "error" in w:
        return (w or {}).get("error", "not available")
    parts = []
    n_auto = w["max_lag"]
    for out, s in w["autocorrelation"].items():
        cross = w["cross_correlation"][out]
        cx = ", ".join(f"{u} {c['outside']}/{len(c['lags'])}" for u, c in cross.items())
        parts.append(f"{out}: autocorrelation outside the 99 % band at {s['outside']}/{n_auto} lags "
                     f"(max |r| {s['max_abs']:.3f}); cross-correlation with {cx}")
    verdict = ("white" if w["white"] else "not white") + ", " + ("independent of the inputs" if w["independent"]
                                                                  else "correlated with the inputs")
    traced = "; ".join(f"{s['signal']} ({s['output']}, lag {s['lag']}, r = {s['r']:+.3f})"
                       for s in w.get("signals", [])[:3])
    return f"{verdict} (band +-{w['bound']:.4f}, N = {w['n']})\n    " + "\n    ".join(parts) + \
        (f"\n    most correlated signals: {traced}" if traced else "")


def format_report(report: dict, limit: int = 10) -> str:
    """The whole diagnosis as text: candidates per round, accepted effects before/after, whiteness, final fit."""
    out = []
    before = report["before"]
    out.append(f"chart as given: train RMS {_g(before['rms'])}, validation RMS {_g(before['validation_rms'])}, "
               f"AIC {_g(before['aic'], 8)}, BIC {_g(before['bic'], 8)}")
    rounds = sorted({c["round"] for c in report["candidates"]})
    for r in rounds:
        cands = [c for c in report["candidates"] if c["round"] == r]
        rows, hidden = shown_candidate_rows(cands, limit)
        out.append("")
        out.append(f"round {r}: {len(cands)} candidates scored (score = predicted decrease of the cost E by one "
                   "Gauss-Newton step)")
        if rows:
            out.append(table(["rank", "effect", "at", "option", "score", "p", "achieved", "from", "val RMS"],
                             rows).rstrip())
        if hidden:
            out.append(f"({hidden} more: other options of these places, lower scores, or failures)")
    if report["rounds"]:
        out.append("")
        rows = []
        for r in report["rounds"]:
            a, b = r.get("before") or {}, r.get("after") or {}
            rows.append([r["round"], f"{r['effect']} at {r['at']}" + (f" ({r['label']})" if r.get("label") else ""),
                         "yes" if r["accepted"] else "no", _arrow(r["rms_before"], r["rms_after"]),
                         _arrow(r["validation_rms_before"], r["validation_rms_after"]),
                         _arrow(r["aic_before"], r["aic_after"], 8),
                         fit_percent_change(a, b)])
        out.append(table(["round", "effect", "accepted", "train RMS", "validation RMS", "AIC", "val fit %"],
                         rows).rstrip())
        for r in report["rounds"]:
            if r.get("score_rows"):
                added = ", ".join(r.get("score_rows_added") or []) or "nothing new"
                out.append(f"round {r['round']}: the fit loses the record; also scored on the part it follows "
                           f"({', '.join(map(str, r['score_rows']))} rows), which added to the refits: {added}")
            if r.get("second_look"):
                out.append(f"round {r['round']}: no refit came near the noise; also refitted: "
                           + ", ".join(r["second_look"]))
            if not r["accepted"]:
                out.append(f"round {r['round']}: not accepted - {r['reason']}")
    accepted = report.get("accepted") or []
    out.append("")
    out.append("accepted: " + (", ".join(f"{a['effect']} at {a['at']}" + (f" ({a['label']})" if a.get("label")
                                                                          else "") for a in accepted) or "nothing"))
    stop = STOP_MESSAGES.get(report["stop"], report["stop"])
    last = report.get("last_round")
    if report["stop"] == "done_after_accepting" and last:
        stop += f" ({STOP_MESSAGES.get(last, last)})"
    out.append(f"stopped: {stop}")
    w = report.get("whiteness", {})
    out.append("")
    out.append("residual before: " + _whiteness(w.get("before")))
    out.append("residual after:  " + _whiteness(w.get("after")))
    out.append("")
    out.append("final chart:")
    out.append(format_result(from_document(report["final"])).rstrip())
    return "\n".join(out) + "\n"


def fit_percent_change(a: dict, b: dict) -> str:
    va, vb = a.get("validation_fit_percent") or [], b.get("validation_fit_percent") or []
    if not va:
        return ""
    parts = []
    for name in va[0]:
        x = va[0].get(name)
        y = vb[0].get(name) if vb else None
        parts.append(f"{name} {_arrow(x, y, 4)}")
    return "; ".join(parts)

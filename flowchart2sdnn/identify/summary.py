"""The text report of an identification (a pure function of the result document)."""

from __future__ import annotations

from collections.abc import Sequence

from ..tables import table

__all__ = ["format_result"]


def _g(x) -> str:
    return "" if x is None else f"{x:.6g}"


def format_result(result: dict, fixed_from: Sequence[str] = ()) -> str:
    out = [f"status: {result['status']}" + (f" - {result['message']}" if result.get("message") else "")]
    rows = []
    for name, p in result["parameters"].items():
        ci = f"[{_g(p['ci95'][0])}, {_g(p['ci95'][1])}]" if p.get("ci95") else ""
        how = "fixed" + (" (from result)" if name in fixed_from else "") if p["fixed"] else "identified"
        rows.append([name, _g(p["init"]), _g(p["value"]), ci, p.get("unit") or "", how])
    if rows:
        out.append("")
        out.append(table(["parameter", "initial", "identified", "95 % interval", "unit", ""], rows).rstrip())
    if result.get("nonlinear"):
        out.append("")
        for block, w in result["nonlinear"].items():
            n = len(w["a"])
            slope = sum(a * v for a, v in zip(w["a"], w["v"], strict=True))
            state = "fixed" if w.get("fixed") else "learned"
            out.append(f"nonlinear {block}: {n} tanh neurons ({state}), slope at 0 = {slope:.4g}, "
                       f"y = sum v_i tanh(a_i x{' + b_i' if 'b' in w else ''})")
    out.append("")
    fit_rows = []
    for which in ("train", "validation"):
        m = result["fit"].get(which)
        if not m:
            continue
        for name in m["rms"]:
            fit_rows.append([which, name, _g(m["cost"]), _g(m["rms"][name]), _g(m["fit_percent"][name]), m["rows"]])
    out.append(table(["record", "output", "cost E", "RMS", "fit %", "rows"], fit_rows).rstrip())
    ms = result.get("multistart")
    if ms and ms.get("n", 1) > 1:
        out.append("")
        out.append(f"multi-start: {ms['n']} starts, best #{ms['best_index']}; {ms['message']}")
    shown = {ms.get("message")} if ms else set()
    for w in result.get("warnings", []):
        if w not in shown:
            out.append(f"warning: {w}")
    return "\n".join(out) + "\n"

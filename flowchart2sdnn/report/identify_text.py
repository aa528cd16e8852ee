"""The text summary of an identification (a pure function of the typed result)."""

from __future__ import annotations

from collections.abc import Sequence

from ..fit.stoprule import status_line as rule_line
from ..identify import Identification
from ..notices import Notice
from ..tables import table

__all__ = ["format_result", "status_line", "warning_lines", "notice_lines"]


def _g(x) -> str:
    return "" if x is None else f"{x:.6g}"


def status_line(result: Identification) -> str:
    """The status as the summary's first line says it: the optimizer's status word and the one rule that fired,
    by name, with its numbers."""
    return rule_line(result.status, result.message, result.converged)


def notice_lines(result: Identification) -> list[Notice]:
    """The warnings the summary prints, as records, in its order (the multi-start message is its own line, not
    repeated); the HTML page shows the same list."""
    shown = {result.multistart.message} if result.multistart else set()
    return [n for n in result.notices if n.message not in shown]


def warning_lines(result: Identification) -> list[str]:
    """The sentences of :func:`notice_lines`."""
    return [n.message for n in notice_lines(result)]


def format_result(result: Identification, fixed_from: Sequence[str] = ()) -> str:
    """The parameter table, learned curves, fit table, multi-start line and warnings, as text."""
    out = [status_line(result)]
    rows = []
    for name, p in result.parameters.items():
        ci = f"[{_g(p.ci95[0])}, {_g(p.ci95[1])}]" if p.ci95 else ""
        how = "fixed" + (" (from result)" if name in fixed_from else "") if p.fixed else "identified"
        rows.append([name, _g(p.init), _g(p.value), ci, p.unit or "", how])
    if rows:
        out.append("")
        out.append(table(["parameter", "initial", "identified", "95 % interval", "unit", ""], rows).rstrip())
    per = result.extra.get("parameters_per_record") or {}
    if per:  # one value per training record; the table above shows their mean
        rows = [[name, i + 1, r["record"], _g(r["value"]),
                 f"[{_g(r['ci95'][0])}, {_g(r['ci95'][1])}]" if r.get("ci95") else "", result.parameters[name].unit or ""]
                for name, records in per.items() for i, r in enumerate(records)]
        out.append("")
        out.append("per-record parameters (the table above gives their mean):")
        out.append(table(["parameter", "record", "file", "identified", "95 % interval", "unit"], rows).rstrip())
        state = (result.extra.get("initial_states") or {}).get("validation") or {}
        for name, v in (state.get("parameters") or {}).items():
            out.append(f"validation record: {name} = {_g(v)} (fitted on its first {state.get('window')} samples)")
    if result.curves:
        out.append("")
        for block, w in result.curves.items():
            state = "fixed" if w.fixed else "learned"
            linear = "" if w.c is None else f" + c x (c = {w.c:.4g})"
            out.append(f"nonlinear {block}: {len(w.a)} tanh terms ({state}), slope at 0 = {w.slope_at_zero:.4g}, "
                       f"y = sum v_i tanh(a_i x{' + b_i' if w.b is not None else ''}){linear}")
    out.append("")
    fit_rows = []
    for which, m in (("train", result.fit.train), ("validation", result.fit.validation)):
        if not m:
            continue
        for name in m.rms:
            fit_rows.append([which, name, _g(m.cost), _g(m.rms[name]), _g(m.fit_percent[name]), m.rows])
    out.append(table(["record", "output", "cost E", "RMS", "fit %", "rows"], fit_rows).rstrip())
    floor_line = _floor(result)
    if floor_line:
        out.append(floor_line)
    shooting_line = _shooting(result)
    if shooting_line:
        out.append(shooting_line)
    out.extend(_bias(result))
    ms = result.multistart
    if ms and ms.n > 1:
        out.append("")
        out.append(f"multi-start: {ms.n} starts, best #{ms.best_index}; {ms.message}")
    out += [n.one_line() for n in notice_lines(result)]
    return "\n".join(out) + "\n"


def _floor(result: Identification) -> str | None:
    """The discretization floor beside the training RMS (identify.assess.floor), or why it was not measured."""
    floor = (result.extra.get("discretization") or {}).get("floor")
    if not isinstance(floor, dict):
        return None
    if not floor.get("rms"):
        return f"discretization floor: not measured ({floor.get('skipped', 'no oracle run')})"
    parts = []
    for name, f in floor["rms"].items():
        r = result.fit.train.rms.get(name)
        share = f" ({100 * f / r:.0f} % of RMS)" if r else ""
        parts.append(f"{name} {f:.3g}{share}")
    return ("discretization floor (network vs continuous chart, training input, RMS): " + ", ".join(parts))


def _shooting(result: Identification) -> str | None:
    """What multiple shooting did: auto's choice and the stage whose fit is the result (identify.shooting.multiple)."""
    s = result.extra.get("shooting")
    if not isinstance(s, dict):
        return None
    text = "shooting: "
    if "auto" in s:
        text += f"auto -> {s['auto']['chose']} ({s['auto']['reason']})"
        look = s["auto"].get("second_look")
        if look:
            text += f"; then {look['reason']}, kept {look['kept']}"
    else:
        text += f"segments of {s['length']} samples"
    if s.get("final_length") is not None:
        text += ("; the result is single shooting over whole records" if s.get("predictable")
                 else f"; the result is the stage with segments of {s['final_length']} samples (see the warning)")
    return text


def _bias(result: Identification) -> list[str]:
    """The discretization's bias per parameter and the corrected estimates (identify --floor-bias)."""
    bias = (result.extra.get("discretization") or {}).get("bias")
    if not isinstance(bias, dict):
        return []
    if not bias.get("beta"):
        return ["", f"discretization bias: not estimated ({bias.get('skipped', 'no refit')})"]
    rows = []
    for name, b in bias["beta"].items():
        c = bias["corrected"][name]
        ratio = bias["ratio"].get(name)
        ci = f"[{_g(c['ci95'][0])}, {_g(c['ci95'][1])}]" if c.get("ci95") else ""
        rows.append([name, f"{b:+.3g}", "" if ratio is None else f"{ratio:.2f}", _g(c["value"]), ci])
    refit = bias.get("refit") or {}
    return ["", f"discretization bias (the network refitted to the continuous chart's noise-free run, "
                f"{refit.get('iterations')} LM iterations): corrected = identified - beta",
            table(["parameter", "beta", "|beta|/stderr", "corrected", "corrected 95 % interval"], rows).rstrip()]

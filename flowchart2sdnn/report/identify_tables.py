"""The tables of an identification page: parameters (value ± stderr, its %, interval), per-record values, the
correlation matrix, the learned curves, and the fit per record, labelled as the figures beside them are.

Each table reads the typed result only. The fit table takes its numbers from the result (what identify scored),
the figures theirs from :func:`flowchart2sdnn.identify.compare.compare_fit`; both print a fit % with
:func:`.figures.fit_number`, so a reader (and a test) can hold one against the other.
"""

from __future__ import annotations

from collections.abc import Sequence

from .figures import fit_number
from .html import paragraph, section, table

__all__ = ["parameter_sections", "fit_section", "fit_rows"]

#: a correlation matrix of more parameters than this is listed as its strongest pairs instead
_MATRIX_MAX = 14
#: |r| from which a pair of parameters is listed as strongly correlated
_STRONG = 0.9


def _g(x, digits: int = 6) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _ci(ci) -> str:
    return "" if not ci else f"[{ci[0]:.6g}, {ci[1]:.6g}]"


def _percent(stderr, value) -> str:
    return "" if stderr is None or not value else f"{100 * stderr / abs(value):.3g}"


def parameter_sections(outcome, fixed_from: Sequence[str] = ()) -> list[str]:
    """Parameters, per-record values, correlations and learned curves, as page sections."""
    rows = [[name, p.init, p.value, _g(p.stderr, 3), _percent(p.stderr, p.value), _ci(p.ci95), p.unit or "",
             ("fixed" + (" (from result)" if name in fixed_from else "")) if p.fixed else "identified"]
            for name, p in outcome.parameters.items()]
    parts = [paragraph("± stderr: the standard error; stderr %: it relative to the value; the interval is 95 %.")]
    parts.append(table(["parameter", "initial", "identified", "± stderr", "stderr %", "95 % interval", "unit", ""],
                       rows, left=1))
    per = outcome.extra.get("parameters_per_record") or {}
    if per:
        rows = [[name, k + 1, r["record"], r["value"], _g(r.get("stderr"), 3), _percent(r.get("stderr"), r["value"]),
                 _ci(r.get("ci95")), outcome.parameters[name].unit or ""]
                for name, records in per.items() for k, r in enumerate(records)]
        parts.append(paragraph("Per-record parameters: one value per training record (the table above gives "
                               "their mean, which a record without a fit of its own runs with)."))
        parts.append(table(["parameter", "record", "file", "identified", "± stderr", "stderr %", "95 % interval",
                            "unit"], rows, left=3))
        state = (outcome.extra.get("initial_states") or {}).get("validation") or {}
        for name, v in (state.get("parameters") or {}).items():
            parts.append(paragraph(f"validation record: {name} = {v:.6g} (fitted on its first {state.get('window')} "
                                   "samples with the states)"))
    parts.append(_correlation(outcome.uncertainty))
    out = [section("Parameters", [p for p in parts if p], "parameters")]
    if outcome.curves:
        curve_rows = [[block, len(w.a), "fixed" if w.fixed else "learned", w.slope_at_zero]
                      for block, w in outcome.curves.items()]
        out.append(section("Learned curves", [
            paragraph("y = Σ vᵢ tanh(aᵢ x [+ bᵢ]) per block; the slope at 0 is Σ vᵢ aᵢ. Each curve is drawn over "
                      "the range its input covered in the training record (shaded): outside it the curve is a guess."),
            table(["block", "tanh neurons", "", "slope at 0"], curve_rows, left=1, digits=4)], "curves"))
    return out


def _correlation(u) -> str:
    if u is None or not u.names:
        return ""
    names, r = list(u.names), u.correlation
    head = (f"Correlation of the estimates (condition number {_g(u.condition_number, 3)})"
            + ("; not identifiable apart: " + "; ".join(", ".join(g) for g in u.unidentifiable)
               if u.unidentifiable else "") + ".")
    parts = [paragraph(head)]
    if u.note:
        parts.append(paragraph(u.note))
    if len(names) <= _MATRIX_MAX:
        rows = [[a, *(("" if v is None else f"{v:+.2f}") for v in r[i])] for i, a in enumerate(names)]
        parts.append(table(["", *names], rows, left=1))
    else:
        pairs = sorted(((abs(r[i][j]), names[i], names[j], r[i][j]) for i in range(len(names))
                        for j in range(i + 1, len(names)) if r[i][j] is not None and abs(r[i][j]) >= _STRONG),
                       reverse=True)
        parts.append(table(["parameter", "parameter", "r"], [[a, b, f"{v:+.3f}"] for _, a, b, v in pairs], left=2)
                     if pairs else paragraph(f"no pair correlated by |r| ≥ {_STRONG:g}"))
    return "\n".join(parts)


def fit_rows(outcome, labels: Sequence[str] = (), validation_labels: Sequence[str] = (),
             validation_metrics: Sequence | None = None) -> list[list]:
    """[record, output, cost E, RMS, fit %, rows, how] per scored record and output: each training record under
    its label (and all of them pooled when several), then each validation record: the result's own, or
    `validation_metrics` (Metrics, one per validation label) where the caller scored them (diagnose)."""
    train = outcome.fit.train
    vals = ([outcome.fit.validation] if outcome.fit.validation is not None else []) if validation_metrics is None \
        else list(validation_metrics)
    rows = []
    per = list(train.records) if train.records else [train]
    for k, m in enumerate(per):
        label = labels[k] if k < len(labels) else f"training record {k + 1}"
        rows += [[label, name, m.cost, m.rms[name], fit_number(m.fit_percent[name]), m.rows, m.note or ""]
                 for name in m.rms]
    if train.records:
        rows += [[f"training, all {len(per)} records", name, train.cost, train.rms[name],
                  fit_number(train.fit_percent[name]), train.rows, "pooled"] for name in train.rms]
    for k, val in enumerate(vals):
        label = validation_labels[k] if k < len(validation_labels) else f"validation record {k + 1}"
        rows += [[label, name, val.cost, val.rms[name], fit_number(val.fit_percent[name]), val.rows, val.note or ""]
                 for name in val.rms]
    return rows


def fit_section(outcome, labels: Sequence[str] = (), validation_labels: Sequence[str] = (),
                validation_metrics: Sequence | None = None) -> str:
    rows = fit_rows(outcome, labels, validation_labels, validation_metrics)
    return section("Fit", [paragraph("fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖), free run of the identified network "
                                     "(each training record with its own per-record values); cost E of eq. (4)."),
                           table(["record", "output", "cost E", "RMS", "fit %", "rows", "how"], rows, left=2,
                                 digits=5)], "fit")

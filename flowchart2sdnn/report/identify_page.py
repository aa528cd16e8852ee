"""One self-contained HTML page per run (`identify --html REPORT.html`): what an engineer attaches to a ticket.

The page holds the chart's name and description, the status and warnings, the parameter table (identified
value, 95 % interval, unit), the learned curves, the fit table, and the figures: measured against model for
every record (:func:`.figures.compare_figure`), the residual analysis per output (:func:`.figures.resid_figure`),
and the Bode plot of the chart linearised at the record's operating point over Welch's H1 from the training
record (:mod:`.bode`). The page is built of the pieces in :mod:`.html` (one file, nothing loaded from
elsewhere); the diagnose page (:mod:`.diagnose_page`) reuses its sections for the final chart.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..analysis.linearize import linearize
from ..analysis.response import empirical_response
from ..errors import SdnnError
from ..identify.compare import compare_records, signal_units
from .bode import bode_figure
from .figures import compare_figure, resid_figure
from .html import chart_section, esc, figure, page, paragraph, section, table
from .identify_plots import resid_inputs

__all__ = ["identification_sections", "bode_section", "identification_html"]

def _ci(p) -> str:
    return "" if not p.ci95 else f"[{p.ci95[0]:.6g}, {p.ci95[1]:.6g}]"


def _warnings(outcome) -> list[str]:
    notes = []
    if outcome.converged is False:
        notes.append(f"not converged: {outcome.message} (raise --max-iter, or start closer)")
    shown = {outcome.multistart.message} if outcome.multistart else set()
    notes += [w for w in outcome.warnings if w not in shown]
    return notes


def _result_tables(outcome, fixed_from: Sequence[str]) -> list[str]:
    rows = [[name, p.init, p.value, _ci(p), p.unit or "",
             ("fixed" + (" (from result)" if name in fixed_from else "")) if p.fixed else "identified"]
            for name, p in outcome.parameters.items()]
    parts = [section("Parameters", [table(["parameter", "initial", "identified", "95 % interval", "unit", ""],
                                          rows, left=1)], "parameters")]
    if outcome.curves:
        curve_rows = [[block, len(w.a), "fixed" if w.fixed else "learned", w.slope_at_zero]
                      for block, w in outcome.curves.items()]
        parts.append(section("Learned curves", [
            paragraph("y = Σ vᵢ tanh(aᵢ x [+ bᵢ]) per block; the slope at 0 is Σ vᵢ aᵢ."),
            table(["block", "tanh neurons", "", "slope at 0"], curve_rows, left=1, digits=4)], "curves"))
    fit_rows = []
    for which, m in (("training", outcome.fit.train), ("validation", outcome.fit.validation)):
        if m:
            fit_rows += [[which, name, m.cost, m.rms[name], m.fit_percent[name], m.rows] for name in m.rms]
    parts.append(section("Fit", [paragraph("fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖), free run of the identified "
                                           "network; cost E of eq. (4)."),
                                 table(["record", "output", "cost E", "RMS", "fit %", "rows"], fit_rows, left=2,
                                       digits=5)], "fit"))
    return parts


def bode_section(diagram, problem, x, record=None) -> str | None:
    """The Bode figure of `diagram` linearised at the RMS of its states over the free run of the record, over
    Welch's H1 from `record` (a Dataset; default the fitted inputs and targets); None when the chart has no
    input or output, or cannot be linearised (the reason is then a paragraph)."""
    if not diagram.input_names or not diagram.output_names:
        return None
    states = {b.name for b in diagram.blocks if b.kind == "integrator"}
    with np.errstate(all="ignore"):
        signals = dict(problem.compiled.signals(x, problem.inputs, problem.init))
    at = {name: float(f"{np.sqrt(np.mean(np.square(v))):.3g}") for name, v in signals.items()
          if name in states and np.all(np.isfinite(v))}
    try:
        model = linearize(diagram, at)
    except (SdnnError, ValueError) as exc:
        return section("Frequency response", [paragraph(f"not drawn: {exc}", "warn")], "bode")
    if model.A.size == 0:
        return None
    estimates = []
    for o in model.outputs:
        for i in model.inputs:
            if record is not None:
                u, y = record.columns[i], record.columns[o]
            else:
                u = problem.inputs[:, list(problem.compiled.input_names).index(i)]
                y = problem.targets[:, list(problem.compiled.output_names).index(o)]
            if len(u) >= 64:
                estimates.append(empirical_response(u, y, diagram.sample_time, i, o))
    modes = [d for d in model.damp() if d["f_hz"] > 0 and d["zeta"] is not None and d["zeta"] < 1]
    text = ", ".join(f"{d['f_hz']:.4g} Hz (ζ = {d['zeta']:.3g})" for d in modes) or "no oscillating mode"
    point = ", ".join(f"{k} = {v:.3g}" for k, v in model.at.items())
    notes = [paragraph(f"Linearised at the RMS of each state over the free run of the training record ({point}); "
                       f"modes: {text}. Measured: Welch's H1 from the training record, faint where the coherence "
                       "is below 0.5.")]
    notes += [paragraph(n) for n in model.notes]
    return section("Frequency response", [*notes, figure(bode_figure(model, estimates), "Bode plot")], "bode")


def identification_sections(outcome, records=(), validation=(), fixed_from: Sequence[str] = ()) -> list[str]:
    """The report's sections for one identification: tables, then compare, residual and Bode figures.

    `records` and `validation` are (label, Dataset, score_from) as for
    :func:`.identify_plots.write_plots`.
    """
    parts = _result_tables(outcome, fixed_from)
    problem, x = outcome.problem, outcome.x
    if problem is None or x is None:
        return parts
    names, inputs = list(problem.compiled.output_names), list(problem.compiled.input_names)
    units = signal_units(outcome.diagram)
    every = [*records, *validation]
    if every:
        comparison = compare_records(problem.compiled, x, every, problem.alignment, None, outcome.diagram)
        parts.append(section("Measured and model output", [figure(
            compare_figure(comparison, f"{outcome.diagram.name}: measured and model output (free run)"),
            "Every training and validation record: fit % and RMS in the legend, a zoom on the largest error.",
            "compare")], "compare"))
    with np.errstate(all="ignore"):
        yhat = problem.compiled.simulate(x, problem.inputs, problem.init)
    residuals = [("training", problem.targets - yhat, problem.inputs)]
    if validation and every:
        rec, (label, data, _) = comparison.records[len(records)], validation[0]
        e = np.column_stack([rec.measured[n] - rec.model[n] for n in names])
        residuals.append((label, e, resid_inputs(data, inputs, rec.rows, problem.alignment)))
    figs = []
    for label, e, u in residuals:
        for j, name in enumerate(names):
            if e.shape[0] >= 3 and np.all(np.isfinite(e[:, j])):
                figs.append(figure(resid_figure(e[:, j], u, name, inputs, label, units.get(name)),
                                   f"Residual analysis of {name} ({label}): autocorrelation and cross-correlation "
                                   "with each input, 99 % band of a white residual independent of the input.",
                                   f"resid {name} {label}"))
    if figs:
        parts.append(section("Residual analysis", figs, "resid"))
    if outcome.online is None:
        bode = bode_section(outcome.diagram, problem, x, records[0][1] if records else None)
        if bode:
            parts.append(bode)
    return parts


def identification_html(outcome, records=(), validation=(), fixed_from: Sequence[str] = (),
                        command: str = "") -> str:
    """The whole page of one identification (see the module docstring)."""
    d = outcome.diagram
    head = [paragraph(d.description)] if d.description else []
    if command:
        head.append(f"<p>command: <code>{esc(command)}</code></p>")
    state = f"status: {outcome.status}" + (f" - {outcome.message}" if outcome.message else "")
    notes = _warnings(outcome)
    head.append(paragraph(state, "warn" if notes else "ok"))
    head += [paragraph(f"warning: {w}", "warn") for w in notes]
    ms = outcome.multistart
    if ms and ms.n > 1:
        head.append(paragraph(f"multi-start: {ms.n} starts, best #{ms.best_index}; {ms.message}"))
    files = ", ".join(Path(r.file).name for r in outcome.data.train_records if r.file)
    subtitle = f"identification of chart '{d.name}'" + (f" on {files}" if files else "")
    return page(f"{d.name}: identification", [*head, *identification_sections(outcome, records, validation,
                                                                               fixed_from), chart_section(d)],
                subtitle)



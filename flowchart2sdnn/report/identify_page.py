"""One self-contained HTML page per run (`identify --html REPORT.html`): what an engineer attaches to a ticket.

The page holds the chart's name and description, the command line that reproduces the run, the status (the
rule that stopped the fit) and every warning the command line printed, the tables (:mod:`.identify_tables`:
parameters ± stderr, per-record values, correlations, learned curves, the fit per record) and the figures:
each learned curve over its data range, measured against model for every record
(:func:`.figures.compare_figure`), the residual over time, the residual analysis per output with its verdict
in words (:func:`.figures.resid_figure`; lags spanning the slowest mode), and the Bode plot of the chart
linearised at the record's operating point over Welch's H1 from the training record (:mod:`.bode`).

Every figure of a record is computed with the parameters its table row was scored with
(:func:`flowchart2sdnn.identify.compare.compare_fit`: per-record values, the validation record's fitted
initial state); the captions repeat the figure's fit % as the table prints it. The page is built of the pieces in :mod:`.html` (one file, nothing loaded from
elsewhere); the diagnose page (:mod:`.diagnose_page`) reuses its sections for the final chart.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..analysis.response import empirical_response
from ..identify import compare_fit, record_theta, signal_units
from .bode import bode_figure
from .figures import compare_figure, fit_number, resid_figure, residual_time_figure, verdict
from .html import chart_section, esc, figure, page, paragraph, section
from .identify_plots import curve_figure, resid_inputs
from .identify_tables import fit_section, parameter_sections
from .identify_text import notice_lines, status_line
from .linear import linear_model, residual_lags

__all__ = ["identification_sections", "bode_section", "identification_html", "status_paragraphs"]


def bode_section(outcome, model, reason: str = "", record=None) -> str | None:
    """The Bode figure of the linearised chart `model` over Welch's H1 from `record` (a Dataset; default the
    fitted inputs and targets); without a model the reason is a paragraph, or nothing when the chart has
    neither input nor output."""
    diagram, problem = outcome.diagram, outcome.problem
    if model is None:
        if not diagram.input_names or not diagram.output_names or reason == "the chart has no state":
            return None
        return section("Frequency response", [paragraph(f"not drawn: {reason}", "warn")], "bode")
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


def _fallback_residual(outcome):
    """Without records: the first training record as the problem holds it, with its own values."""
    problem = outcome.problem
    with np.errstate(all="ignore"):
        yhat = problem.compiled.simulate(record_theta(outcome, 0), problem.inputs, problem.init)
    return [("training", problem.targets - yhat, problem.inputs)]


def identification_sections(outcome, records=(), validation=(), fixed_from: Sequence[str] = (),
                            lags: int | None = None, scored: tuple | None = None) -> list[str]:
    """The report's sections for one identification: tables, then curve, compare, residual and Bode figures.

    `records` (the training records in the order they were fitted) and `validation` are
    (label, Dataset, score_from) as for :func:`.identify_plots.write_plots`. `lags` of the residual analysis:
    default from the dynamics (:func:`flowchart2sdnn.analysis.response.lags_for`). `scored`, for a caller that
    scored the validation records itself (diagnose): (Metrics per validation record, init_window,
    per-record parameters fitted on the window), so that table and figures show its numbers.
    """
    parts = parameter_sections(outcome, fixed_from)
    labels, checks = [r[0] for r in records], [v[0] for v in validation]
    metrics, window, params = scored if scored is not None else (None, None, None)
    parts.append(fit_section(outcome, labels, checks, metrics))
    problem, x = outcome.problem, outcome.x
    if problem is None or x is None:
        return parts
    names, inputs = list(problem.compiled.output_names), list(problem.compiled.input_names)
    if outcome.curves:
        parts.append(section("Learned curves over their data", [
            figure(curve_figure(outcome, block, w), f"Learned curve {block} over the range its input covered "
                   "in the training record (shaded).", f"curve {block}") for block, w in outcome.curves.items()],
            "curve-figures"))
    comparison = compare_fit(outcome, records, validation, window, params) if records or validation else None
    if comparison is not None:
        fits = "; ".join(f"{r.label}, {n}: fit {fit_number(r.fit_percent[n])} %" for r in comparison.records
                         for n in names)
        parts.append(section("Measured and model output", [
            figure(compare_figure(comparison, f"{outcome.diagram.name}: measured and model output (free run)"),
                   f"Every training and validation record, each run with the parameters of its fit table row "
                   f"({fits}); a zoom on the largest error.", "compare"),
            figure(residual_time_figure(comparison), "The residual, measured minus model, over time.",
                   "residual over time")], "compare"))
        given = [*records, *validation]
        shown = [0] + list(range(len(records), len(given)))  # the first training record, every validation one
        residuals = []
        for i in shown:
            if i < len(comparison.records):
                rec, data = comparison.records[i], given[i][1]
                e = np.column_stack([rec.measured[n] - rec.model[n] for n in names])
                residuals.append((rec.label, e, resid_inputs(data, inputs, rec.rows, problem.alignment)))
    else:
        residuals = _fallback_residual(outcome)
    model, reason = linear_model(outcome) if outcome.online is None else (None, "")
    lags, why = residual_lags(outcome, min(e.shape[0] for _, e, _ in residuals), lags, model)
    figs, units = [], signal_units(outcome.diagram)
    for label, e, u in residuals:
        for j, name in enumerate(names):
            if e.shape[0] >= 3 and np.all(np.isfinite(e[:, j])):
                said = verdict(e[:, j], u, name, inputs, lags)
                figs.append(figure(resid_figure(e[:, j], u, name, inputs, label, units.get(name), lags,
                                                sample_time=outcome.diagram.sample_time),
                                   f"Residual analysis of {name} ({label}): {said}. Autocorrelation and "
                                   "cross-correlation with each input, 99 % band of a white residual independent "
                                   f"of the input; {lags} lags ({why}).", f"resid {name} {label}"))
    if figs:
        parts.append(section("Residual analysis", figs, "resid"))
    if outcome.online is None:
        bode = bode_section(outcome, model, reason, records[0][1] if records else None)
        if bode:
            parts.append(bode)
    return parts


def status_paragraphs(outcome, printed: Sequence[str] = ()) -> list[str]:
    """The status line (the rule that stopped the fit) and every warning the command line printed: the
    result's own (as the text summary lists them) and `printed`, the ones it printed beside them."""
    own = notice_lines(outcome)
    said = {n.message for n in own}
    notes = [n.one_line() for n in own] + [f"warning: {w}" for w in dict.fromkeys(printed) if w not in said]
    if outcome.converged is True:
        rule = "converged"
    elif outcome.converged is False:
        rule = "not converged"
    else:
        rule = "no convergence test applies"
    parts = [paragraph(f"{status_line(outcome)} ({rule})", "warn" if notes or outcome.converged is False else "ok")]
    parts += [paragraph(w, "warn") for w in notes]
    ms = outcome.multistart
    if ms and ms.n > 1:
        parts.append(paragraph(f"multi-start: {ms.n} starts, best #{ms.best_index}; {ms.message}"))
    return parts


def identification_html(outcome, records=(), validation=(), fixed_from: Sequence[str] = (),
                        command: str = "", printed: Sequence[str] = (), lags: int | None = None) -> str:
    """The whole page of one identification (see the module docstring). `command` is the command line that
    reproduces the run; `printed` the warnings the command line printed beside the result's own."""
    d = outcome.diagram
    head = [paragraph(d.description)] if d.description else []
    if command:
        head.append(f"<p>command: <code>{esc(command)}</code></p>")
    head += status_paragraphs(outcome, printed)
    files = ", ".join(Path(r.file).name for r in outcome.data.train_records if r.file)
    subtitle = f"identification of chart '{d.name}'" + (f" on {files}" if files else "")
    return page(f"{d.name}: identification", [*head, *identification_sections(outcome, records, validation,
                                                                               fixed_from, lags), chart_section(d)],
                subtitle)

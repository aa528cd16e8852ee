"""`sdnn identify`: the click layer over identify.offline.run (formatting lives in report.identify_text).

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .. import rules
from .help import SectionedCommand
from .options import (
    alignment_option,
    column_reading,
    command_line,
    data_options,
    executor_options,
    force_option,
    handle_errors,
    html_option,
    intersample_option,
    lags_given,
    lags_option,
    max_iter_option,
    read_records,
    require_figures,
    rows_option,
    seed_option,
    settings_usage,
    shooting_option,
    substeps_option,
    timebase_options,
    with_intersample,
    with_substeps,
)
from .order import chart_and_data
from .terminal import CtrlC, Progress

__all__ = ["identify"]


@click.command(name="identify", cls=SectionedCommand,
               short_help="Identify a chart's parameters and learned curves from records.")
@click.argument("paths", nargs=-1, required=True, type=click.Path(dir_okay=False), metavar="CHART DATA...")
@click.option("--diagram", "diagram", type=click.Path(dir_okay=False),
              help="The chart, in the old order DATA... --diagram CHART (still read, with a note).")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="RESULT.json; the identified chart is written beside it as RESULT.chart.yaml.")
@click.option("--fix-from", type=click.Path(dir_okay=False),
              help="Fix parameters and nonlinear blocks with matching names from an earlier RESULT.json.")
@click.option("--validate", "validation", type=click.Path(dir_okay=False), help="Validation record (CSV).")
@click.option("--init-window", type=click.IntRange(min=1), default=None,
              help="Set the validation record's initial state from its first N samples (parameters fixed), then "
                   "run free; scored from row N (EMPS: 20, CED: 4, Cascaded Tanks: 5).")
@shooting_option()
@click.option("--shooting-starts", type=click.Choice(["auto", "data", "free"]), default="auto", show_default=True,
              help="Multiple shooting: measured states start each segment at the data's sample ('data') or are "
                   "fitted from it ('free'); 'auto': free where --shooting auto found the records chaotic.")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="Multiple shooting: the segments of a fit on N threads (same result; pays from segments of "
                   "~500 samples).")
@click.option("--floor-bias/--no-floor-bias", default=True, show_default=True,
              help="Estimate the discretization's bias on each parameter (a refit to the continuous chart's "
                   "noise-free run), widen the 95 % intervals by it and report corrected values (RESULT.json "
                   "discretization.bias). Offline fits only.")
@click.option("--curve-start", type=click.Choice(["stick", "random"]), default="stick", show_default=True,
              help="Where learned curves without stored weights start: 'stick', a stick-slip step set by brief "
                   "fits; 'random', the chart's seeded init_range weights (docs/rough_init.md). Offline fits only.")
@click.option("--lm-steps", type=click.Choice(["geodesic", "plain"]), default="geodesic", show_default=True,
              help="LM steps where the transform keeps the bounds: 'geodesic', bent along the cost's valley (one "
                   "extra simulation per step); 'plain', unbent (docs/rough_init.md).")
@click.option("--lm-bounds", type=click.Choice(["auto", "transform", "box"]), default="auto", show_default=True,
              help="How offline fits keep the bounds: 'box', steps in the physical quantities with a trust radius "
                   "(as scipy's trf); 'transform', a change of variables; 'auto', box unless a learned curve is "
                   "fitted (docs/rough_init.md).")
@click.option("--split", type=click.FloatRange(0, 1, min_open=True, max_open=True),
              help="Train on this leading fraction of DATA, validate on the rest.")
@click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
              help="Multi-start: number of seeded starts (the first is the chart's init, its learned curves as "
                   "--curve-start sets them); with --online, that many "
                   "quasi-online runs, the one with the lowest final window cost reported.")
@seed_option("Seed for starts and initial curves.")
@click.option("--online", is_flag=True, help="Quasi-online LM over a sliding window (paper section 3.1).")
@click.option("--window", type=click.IntRange(min=2), default=rules.value("online_window"), show_default=True,
              help="Quasi-online window Q (samples).")
@click.option("--average", type=click.IntRange(min=1), default=rules.value("online_average"), show_default=True,
              help="Quasi-online: report the mean over the last K steps.")
@max_iter_option("Safety limit on LM iterations: a fit stops when it has converged; one that reaches the "
                 "limit is reported as not converged.")
@alignment_option()
@substeps_option()
@intersample_option()
@data_options
@timebase_options
@rows_option("each training record")
@click.option("--plots", type=click.Path(file_okay=False),
              help="Directory for the figures (PNG; created if needed, figures of the same name replaced). "
                   "Needs matplotlib: pip install flowchart2sdnn[plots].")
@html_option()
@lags_option()
@force_option()
@click.option("--quiet", is_flag=True,
              help="No progress, table or 'wrote' lines (errors and the not-converged warning still go to stderr).")
@executor_options("the multi-start fits")
@handle_errors
def identify(paths, diagram, output, fix_from, validation, init_window, shooting, shooting_starts, threads, floor_bias, curve_start, lm_steps, lm_bounds, split, starts, seed, online, window, average,
             max_iter, alignment, substeps, intersample, mapping, units, delimiter, decimal, resample, plots, html_path, force,
             quiet, workers=None, scheduler=None) -> None:
    """Identify the physical parameters of CHART (YAML) from measured DATA (CSV; several records are fitted
    together, each simulated from its own initial state)."""
    from ..api import with_data_notes
    from ..atomic import atomic_write_text, check_output_path
    from ..data.timebase import longest
    from ..diagram.dump import dump_diagram
    from ..diagram.validate import load_diagram
    from ..errors import SdnnError
    from ..identify import IDENTIFY_GEODESIC, IdentifySettings, dumps, fix_from_result
    from ..identify import identify as run_identify
    from ..report.identify_text import format_result

    chart, data = chart_and_data("identify", paths, diagram)
    if validation and split:
        raise click.UsageError("give either --validate or --split, not both")
    if init_window and not validation:
        raise click.UsageError("--init-window sets the initial state of the --validate record: give one")
    inputs = [*data, chart] + [p for p in (fix_from, validation) if p]
    require_figures(plots, html_path)  # before any work: a missing extra must not cost a whole run
    chart_out = None
    if output:
        chart_out = str(Path(output).with_suffix("")) + ".chart.yaml"
        check_output_path(output, inputs, force=force)
        check_output_path(chart_out, inputs, force=force)
    if html_path:
        check_output_path(html_path, inputs, force=force)
    diagram = with_intersample(with_substeps(load_diagram(chart), substeps), intersample)
    fixed = []
    if fix_from:
        diagram, fixed = fix_from_result(diagram, fix_from)
    maps, scales = column_reading(diagram, mapping, units)
    dialect = (delimiter, decimal, resample)
    train = read_records(data, diagram, maps, scales, *dialect)
    val = longest(read_records([validation], diagram, maps, scales, *dialect, window=False)) if validation else None
    with settings_usage():
        settings = IdentifySettings(starts=starts, seed=seed, max_iter=max_iter, alignment=alignment, split=split,
                                    online=online, window=window, average=average, fixed_from=tuple(fixed),
                                    init_window=init_window or 0, shooting=shooting,
                                    shooting_starts=shooting_starts, floor_bias=floor_bias,
                                    curve_start=curve_start, threads=threads,
                                    lm_geodesic=IDENTIFY_GEODESIC if lm_steps == "geodesic" else 0.0,
                                    lm_bounds=lm_bounds)
    progress = Progress(quiet)
    ctrl_c = CtrlC()  # until the files are written: restored when the click context closes
    click.get_current_context().call_on_close(ctrl_c.restore)
    try:
        if workers is None and scheduler is None:
            outcome = run_identify(diagram, train, val, settings, progress, stop=ctrl_c)
        else:
            from ..executors import make_executor

            with make_executor(workers, scheduler) as executor:
                outcome = run_identify(diagram, train, val, settings, progress, executor=executor,
                                       stop=ctrl_c)
    finally:
        progress.close()
    outcome = with_data_notes(outcome, [*train, *([val] if val is not None else [])])
    if outcome.status == "diverged_at_start":
        raise SdnnError.at("FIT001", outcome.message, chart,
                           hint="the start values make the model unstable on this data: change 'init'")
    if output:
        extra = {"command": {"data": data[0] if len(data) == 1 else list(data), "diagram": chart,
                             "fix_from": fix_from, "validate": validation, "map": dict(maps),
                             **({"unit": dict(u.split("=", 1) for u in units)} if units else {})},
                 "identified_chart": chart_out}
        # both texts first: a failure here must not leave one file without the other
        chart_text = dump_diagram(outcome.diagram, {"from": output, "status": outcome.status})
        result_text = dumps({**outcome.to_document(), **extra})
        atomic_write_text(chart_out, chart_text)
        atomic_write_text(output, result_text)
    # what is printed beside the result's own warnings, on stderr at the end: the page shows it too
    printed = [f"not converged: {_stop_reason(outcome)}; raise --max-iter, or start closer"] \
        if outcome.converged is False and outcome.status != "interrupted" else []
    if plots or html_path:
        records = [(f"training: {Path(d.path).name}", d, 0) for d in train]
        checks = [(f"validation: {Path(val.path).name}", val, 0)] if val is not None else []
        if split:  # as identify splits: the free run over the whole record, shown and scored after the split
            n = max(3, int(round(split * train[0].n_rows)))
            records = [(records[0][0], train[0].slice(0, n), 0)]
            checks = [(f"validation: {Path(train[0].path).name} after the split", train[0], n)]
    figures = []
    if plots:
        from ..report.identify_plots import write_plots

        figures = write_plots(outcome, plots, records, checks, lags_given())
    if html_path:
        from ..report.html import write_html
        from ..report.identify_page import identification_html

        write_html(html_path, identification_html(outcome, records, checks, fixed, command_line(), printed,
                                                  lags_given()))
    if not quiet:
        click.echo(format_result(outcome, fixed), nl=False)
        if output:
            click.echo(f"wrote {output} and {chart_out}")
        if html_path:
            click.echo(f"wrote {html_path}")
        if plots:
            click.echo(f"wrote {len(figures)} figure(s) to {plots}")
    for line in printed:
        click.echo(f"warning: {line}", err=True)
    if outcome.status == "interrupted":
        click.echo(f"interrupted: {'the best result so far is in ' + output if output else 'no -o, nothing written'}",
                   err=True)
        sys.exit(1)


def _stop_reason(outcome) -> str:
    """The one rule that ended an unconverged fit, with its iterations (the whole message where none is read)."""
    from ..fit.stoprule import stop_rule

    rule = stop_rule(outcome.status, outcome.message)
    if rule is None:
        return outcome.message
    its = rule.iterations
    return rule.sentence + (f" (after {its} iteration{'s' * (its != 1)})" if its is not None else "")

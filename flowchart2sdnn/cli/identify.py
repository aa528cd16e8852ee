"""`sdnn identify`: the click layer over identify.run (formatting lives in report.identify_text).

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

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
from .terminal import CtrlC, Progress

__all__ = ["identify"]


@click.command(name="identify")
@click.argument("data", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--diagram", "chart", required=True, type=click.Path(dir_okay=False), help="The chart (YAML).")
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
              help="Multiple shooting: measured states start each segment from the data's sample ('data') or are "
                   "fitted like the unmeasured ones from it ('free': a noisy sample is a poor start); 'auto': "
                   "free where --shooting auto found the records chaotic, data otherwise.")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="Multiple shooting: run the segments of a fit on N threads in this process (same result as 1; "
                   "pays from segments of ~500 samples on, benchmarks/bench_shooting_iteration.py).")
@click.option("--floor-bias/--no-floor-bias", default=True, show_default=True,
              help="Estimate the discretization's bias beta on each parameter (the network refitted to the "
                   "continuous oracle's noise-free run of the identified chart), widen each 95 % interval by "
                   "|beta| (the noise's alone: ci95_noise) and report the corrected values (RESULT.json "
                   "discretization.bias). Offline fits only (--online skips it).")
@click.option("--curve-start", type=click.Choice(["stick", "random"]), default="stick", show_default=True,
              help="Where learned curves without stored weights start: 'stick', for a curve in a feedback loop a "
                   "stick-slip step at 0.3 of the slope the network's step allows, set after brief fits (at most "
                   "150 iterations; docs/rough_init.md); 'random', the chart's seeded init_range weights. Offline fits only.")
@click.option("--lm-steps", type=click.Choice(["geodesic", "plain"]), default="geodesic", show_default=True,
              help="LM steps of offline fits: 'geodesic', bent along the cost's valley (geodesic acceleration, one "
                   "extra simulation per step); 'plain', the unbent steps (docs/rough_init.md). Used where the "
                   "bounds are kept by the transform (--lm-bounds).")
@click.option("--lm-bounds", type=click.Choice(["auto", "transform", "box"]), default="auto", show_default=True,
              help="How offline fits keep the parameters' bounds: 'box', plain steps in the physical quantities "
                   "held inside them, each step's length set by a trust radius (as scipy's trf); 'transform', a "
                   "change of variables with --lm-steps; 'auto', box where no learned curve is fitted, the "
                   "transform elsewhere (docs/rough_init.md).")
@click.option("--split", type=click.FloatRange(0, 1, min_open=True, max_open=True),
              help="Train on this leading fraction of DATA, validate on the rest.")
@click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
              help="Multi-start: number of seeded starts (the first is the chart's init, its learned curves as "
                   "--curve-start sets them); with --online, that many "
                   "quasi-online runs, the one with the lowest final window cost reported.")
@seed_option("Seed for starts and initial curves.")
@click.option("--online", is_flag=True, help="Quasi-online LM over a sliding window (paper section 3.1).")
@click.option("--window", type=click.IntRange(min=2), default=25000, show_default=True,
              help="Quasi-online window Q (samples).")
@click.option("--average", type=click.IntRange(min=1), default=25000, show_default=True,
              help="Quasi-online: report the mean over the last K steps.")
@max_iter_option("Safety limit on LM iterations: a fit stops when it has converged; one that reaches the "
                 "limit is reported as not converged.", default=1000)
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
@click.option("--quiet", is_flag=True, help="No progress and no table.")
@executor_options("the multi-start fits")
@handle_errors
def identify(data, chart, output, fix_from, validation, init_window, shooting, shooting_starts, threads, floor_bias, curve_start, lm_steps, lm_bounds, split, starts, seed, online, window, average,
             max_iter, alignment, substeps, intersample, mapping, units, delimiter, decimal, resample, plots, html_path, force,
             quiet, workers=None, scheduler=None) -> None:
    """Identify the physical parameters of the chart from measured DATA (CSV; several records are fitted
    together, each simulated from its own initial state)."""
    from ..api import with_data_notes
    from ..atomic import atomic_write_text, check_output_path
    from ..data.timebase import longest
    from ..diagram.dump import dump_diagram
    from ..diagram.validate import load_diagram
    from ..errors import SdnnError
    from ..identify.document import dumps, fix_from_result
    from ..identify.run import IdentifySettings
    from ..identify.run import identify as run_identify
    from ..identify.settings import IDENTIFY_GEODESIC
    from ..report.identify_text import format_result

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
    printed = ([f"not converged: {outcome.message} (raise --max-iter, or start closer)"]
               if outcome.converged is False and outcome.status != "interrupted" else [])
    if plots or html_path:
        records = [(f"training: {Path(d.path).name}", d, 0) for d in train]
        checks = [(f"validation: {Path(val.path).name}", val, 0)] if val is not None else []
        if split:  # as identify splits: the free run over the whole record, shown and scored after the split
            n = max(3, int(round(split * train[0].n_rows)))
            records = [(records[0][0], train[0].slice(0, n), 0)]
            checks = [(f"validation: {Path(train[0].path).name} after the split", train[0], n)]
    if plots:
        from ..report.identify_plots import write_plots

        write_plots(outcome, plots, records, checks, lags_given())
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
    for line in printed:
        click.echo(f"warning: {line}", err=True)
    if outcome.status == "interrupted":
        click.echo(f"interrupted: {'the best result so far is in ' + output if output else 'no -o, nothing written'}",
                   err=True)
        sys.exit(1)

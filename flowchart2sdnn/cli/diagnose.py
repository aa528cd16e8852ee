"""`sdnn diagnose`: the click layer over diagnose.loop (formatting lives in report.diagnose_text).

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import sys
from dataclasses import replace

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
from .terminal import Progress

__all__ = ["diagnose", "parse_effects"]


def parse_effects(text: str | None) -> list[str] | None:
    """``"friction, dead_time"`` -> ["friction", "dead_time"]; None stays None."""
    if text is None:
        return None
    return [t.strip() for t in text.split(",") if t.strip()]


def _int_list(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise click.BadParameter(f"expected whole numbers separated by commas, got {text!r}") from None
    if not values or any(v < 1 for v in values):
        raise click.BadParameter("expected at least one whole number >= 1")
    return values


#: diagnose's own --help section: how the effects are searched and accepted
EFFECTS = {"Effect search": ("rounds", "effect_names", "effects_file", "top", "second_look", "criterion", "min_gain",
                             "spread_z", "alpha", "dead_time_max", "harmonics", "refit_iter", "horizon",
                             "allow_unconverged")}


@click.command(name="diagnose", cls=SectionedCommand, sections=EFFECTS,
               short_help="Trace the residual to missing effects, add them, refit.")
@click.argument("paths", nargs=-1, required=True, type=click.Path(dir_okay=False), metavar="CHART DATA...")
@click.option("--diagram", "diagram", type=click.Path(dir_okay=False),
              help="The chart, in the old order DATA... --diagram CHART (still read, with a note).")
@click.option("--validate", "validation", multiple=True, type=click.Path(dir_okay=False),
              help="Validation record (CSV); repeatable (e.g. several short records of a chaotic drive).")
@click.option("--split", type=click.FloatRange(0, 1, min_open=True, max_open=True),
              help="Train on this leading fraction of DATA, validate on the rest (default without "
                   f"--validate: {rules.value('default_split'):g}).")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Write the augmented, identified chart (YAML).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write REPORT.json.")
@click.option("--rounds", type=click.IntRange(min=0), default=rules.value("rounds"), show_default=True,
              help="At most this many effects are added.")
@click.option("--effects", "effect_names", metavar="NAME,NAME",
              help="Effects to try (default: all built-in and all from --effects-file).")
@click.option("--effects-file", type=click.Path(dir_okay=False),
              help="User effects: chart fragments with placeholders (YAML, 'sdnn_effects: 1').")
@click.option("--plots", type=click.Path(file_okay=False),
              help="Directory for the figures (residual against the traced signal, before and after).")
@click.option("--refit-iter", type=click.IntRange(min=1), default=rules.value("refit_iter"), show_default=True,
              help="LM iterations of each brief refit of a candidate.")
@max_iter_option("Safety limit on LM iterations of the first fit, a finished control and each accepted chart: "
                 "a fit stops when it has converged; a first fit that reaches the limit is not traced.")
@click.option("--horizon", type=click.IntRange(min=0), default=rules.value("horizon"), show_default=True,
              help="Samples of the first stage of the growing-horizon refit of a non-neutral candidate (a gap, "
                   "clip or delay), or of a neutral one whose plain refit is unpredictable (chaotic), from the "
                   "chart as given; 0: off.")
@click.option("--top", type=click.IntRange(min=1), default=rules.value("top"), show_default=True,
              help="Places refitted per round (the best option of each).")
@click.option("--second-look/--no-second-look", default=True, show_default=True,
              help=f"When no refit of the --top places comes within {rules.value('far_above_noise'):g}x the noise, refit "
                   "the next --top places too.")
@click.option("--criterion", type=click.Choice(["aic", "bic"]), default="bic", show_default=True,
              help="Information criterion that must fall for an effect to be accepted.")
@click.option("--min-gain", type=click.FloatRange(0, 1, max_open=True), default=rules.value("min_gain"), show_default=True,
              help="The validation RMS must fall by at least this fraction.")
@click.option("--spread-z", type=click.FloatRange(min=0), default=rules.value("spread_z"), show_default=True,
              help="The validation MSE must fall by more than the floor squared plus this many standard errors of "
                   "its fall, read off the fall's spread over the parts of the validation records (0: off).")
@click.option("--alpha", type=click.FloatRange(0, 1, min_open=True, max_open=True), default=rules.value("alpha"),
              show_default=True, help="Significance level of the score test per round, shared by the candidates scored (Bonferroni).")
@click.option("--dead-time-max", type=click.IntRange(min=1, max=10000), default=20, show_default=True,
              help="dead_time scans n = 1..this many samples.")
@click.option("--harmonics", default="1,2,3,4,6,8,12", show_default=True,
              help="cogging harmonics p to try.")
@click.option("--init-window", type=click.IntRange(min=1), default=None,
              help="Fit each --validate record's initial state on its first N samples (parameters fixed) and score "
                   "it from sample N on (the public benchmarks' protocol).")
@shooting_option("the full fits (the chart as given; the brief refits stay single shooting)", default="off")
@click.option("--allow-unconverged", is_flag=True,
              help="Trace even when the first fit of the chart as given did not converge (default: refuse).")
@alignment_option()
@substeps_option()
@intersample_option()
@data_options
@timebase_options
@rows_option("each training record")
@seed_option("Seed for initial curves.")
@html_option()
@lags_option()
@force_option()
@click.option("--quiet", is_flag=True, help="No progress, report text or 'wrote' lines (errors still go to stderr).")
@executor_options("the scanned options and candidate refits")
@handle_errors
def diagnose(paths, diagram, validation, split, output, report_path, rounds, effect_names, effects_file, plots,
             refit_iter, max_iter, horizon, top, second_look, criterion, min_gain, spread_z, alpha, dead_time_max, harmonics, init_window,
             shooting, allow_unconverged, alignment, substeps, intersample, mapping, units, delimiter, decimal, resample, seed, html_path, force, quiet, workers=None, scheduler=None) -> None:
    """Trace the residual of CHART (YAML; never modified) on DATA (one or more CSV records) to missing effects,
    add them to the chart, refit, and report the error before and after."""
    from ..atomic import atomic_write_text, check_output_path
    from ..data.timebase import record_notices
    from ..diagnose.document import dumps
    from ..diagnose.effects import effect_library, select_effects
    from ..diagnose.loop import DiagnoseSettings
    from ..diagnose.loop import diagnose as run_diagnose
    from ..diagram.dump import dump_diagram
    from ..diagram.validate import load_diagram
    from ..notices import messages
    from ..report.diagnose_text import format_report

    chart, data = chart_and_data("diagnose", paths, diagram)
    if validation and split:
        raise click.UsageError("give either --validate or --split, not both")
    if init_window and not validation:
        raise click.UsageError("--init-window sets the initial state of the --validate records: give one")
    cogging_p = _int_list(harmonics)
    inputs = list(data) + [chart] + list(validation) + ([effects_file] if effects_file else [])
    for path in (output, report_path, html_path):
        if path:
            check_output_path(path, inputs, force=force)
    if output and report_path and output == report_path:
        raise click.UsageError("-o and --report name the same file")
    require_figures(plots, html_path)
    user = {}
    if effects_file:
        from ..diagnose.usereffects import load_effects_file

        user = load_effects_file(effects_file)
    try:
        library = effect_library(dead_time_max=dead_time_max, harmonics=cogging_p, user=user)
    except ValueError as exc:
        raise click.UsageError(f"{effects_file}: {exc}") from None
    effects = select_effects(parse_effects(effect_names), library)
    diagram = with_intersample(with_substeps(load_diagram(chart), substeps), intersample)
    for effect in effects:  # a user effect's `at:` the chart lacks is an error now, not after the first fit
        effect.places(diagram)
    maps, scales = column_reading(diagram, mapping, units)
    dialect = (delimiter, decimal, resample)
    train = read_records(data, diagram, maps, scales, *dialect)
    val = read_records(validation, diagram, maps, scales, *dialect, window=False)
    notes = record_notices([*train, *val])
    if not quiet:
        for note in notes:
            click.echo(note.one_line("note"), err=True)
    with settings_usage():
        settings = DiagnoseSettings(rounds=rounds, top=top, second_look=second_look, refit_iter=refit_iter, max_iter=max_iter,
                                    alpha=alpha, criterion=criterion, min_gain=min_gain, spread_z=spread_z,
                                    alignment=alignment,
                                    seed=seed, split=split, horizon=horizon,
                                    require_converged=not allow_unconverged, init_window=init_window or 0,
                                    shooting=shooting)
    progress = Progress(quiet)
    executor = None
    try:
        if workers is not None or scheduler is not None:
            from ..executors import make_executor

            executor = make_executor(workers, scheduler)
        outcome = run_diagnose(diagram, train if len(train) > 1 else train[0], val, settings, effects, progress,
                               executor=executor)
    except BaseException:
        if executor is not None:
            executor.close(cancel=True)
        raise
    finally:
        progress.close()
    if executor is not None:
        # after Ctrl-C the refits still running are dropped, not waited for
        executor.close(cancel=outcome.interrupted)
    outcome = replace(outcome, data_notes=messages(notes), data_notices=tuple(notes),
                      command={"data": list(data), "diagram": chart, "validate": list(validation),
                               "effects_file": effects_file, "output": output, "map": dict(maps)})
    report = outcome.report
    report_text = dumps(report)
    chart_text = dump_diagram(outcome.diagram, {"from": "sdnn diagnose", "chart": chart,
                                                "accepted": [a.title for a in outcome.accepted]})
    if output:
        atomic_write_text(output, chart_text)
    if report_path:
        atomic_write_text(report_path, report_text)
    written = []
    if plots:
        from ..report.diagnose_plots import write_plots

        written = write_plots(outcome, train[0], plots, lags_given())
    if html_path:
        from ..report.diagnose_page import diagnosis_html
        from ..report.html import write_html

        written.append(write_html(html_path, diagnosis_html(outcome, train[0], val, command_line(), notes,
                                                            lags=lags_given())))
    if not quiet:
        click.echo(format_report(report), nl=False)
        for path in [p for p in (output, report_path) if p] + [str(w) for w in written]:
            click.echo(f"wrote {path}")
    if report["stop"] == "first_fit_not_converged":
        # exit 1 (a failed run), after the report is written: REPORT.json holds the unconverged fit
        first = report["first_fit"]
        moving = ", ".join(first.get("still_moving") or []) or "?"
        click.echo(f"error: {chart}: the first fit stopped ({first['status']}) while {moving} still moved by more "
                   "than their standard error, nothing traced; raise --max-iter or improve the chart's init "
                   "(or --allow-unconverged)", err=True)
        sys.exit(1)
    if report.get("interrupted"):
        click.echo("interrupted: the chart and report hold what was accepted before Ctrl-C", err=True)
        sys.exit(1)

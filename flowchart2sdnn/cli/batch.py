"""`sdnn batch`: identify one chart on a fleet of data files, resumably (the click layer over batch.run).

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import glob
import os

import click

from ..errors import SdnnError
from .help import SectionedCommand
from .options import (
    alignment_option,
    column_reading,
    data_options,
    executor_options,
    force_option,
    handle_errors,
    max_iter_option,
    seed_option,
    settings_usage,
    shooting_option,
    substeps_option,
    with_substeps,
)
from .order import chart_first
from .terminal import BatchBar

__all__ = ["batch", "expand_files"]

_GLOB_CHARS = set("*?[")


def expand_files(patterns: tuple[str, ...], exclude: tuple[str, ...] = ()) -> list[str]:
    """Files named or matched (``**`` recursive) by the arguments, sorted and without repeats.

    A directory stands for the ``*.csv`` files in it. Quoted globs are expanded here, so fleets larger than the
    shell's argument limit work. Files in `exclude` (the results table itself) are left out.
    """
    skip = {os.path.realpath(e) for e in exclude}
    out: dict[str, None] = {}
    for pattern in patterns:
        if os.path.isdir(pattern):
            matches = sorted(glob.glob(os.path.join(glob.escape(pattern), "*.csv")))
        elif os.path.exists(pattern) or not (_GLOB_CHARS & set(pattern)):
            matches = [pattern]
        else:
            matches = sorted(glob.glob(pattern, recursive=True))
            if not matches:
                raise SdnnError.at("BATCH001", f"no file matches '{pattern}'")
        for m in matches:
            if os.path.realpath(m) not in skip and not os.path.basename(m).startswith(".sdnn-tmp."):
                out.setdefault(m, None)
    return list(out)


@click.command(name="batch", cls=SectionedCommand,
               short_help="Identify a chart on every log file of a fleet, resumably.",
               sections={"Output": ("retry_errors", "diagnose")})
@click.argument("chart", type=click.Path(dir_okay=False))
@click.argument("data", nargs=-1, required=True)
@click.option("-o", "--output", type=click.Path(dir_okay=False), default="results.csv", show_default=True,
              help="Results table: .csv (appended after each file) or .parquet (needs pyarrow).")
@click.option("--fix-from", type=click.Path(dir_okay=False),
              help="Fix parameters and nonlinear blocks with matching names from an earlier RESULT.json.")
@executor_options("the files' identifications")
@click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
              help="Multi-start per file (seeded starts, the first is the chart's init).")
@seed_option()
@max_iter_option("Safety limit on LM iterations: a fit stops when it has converged; one that reaches the "
                 "limit is reported as not converged.")
@alignment_option(None)
@substeps_option()
@shooting_option("every file's fit")
@data_options
@click.option("--retry-errors", is_flag=True, help="Redo files whose earlier row is an error.")
@force_option("Start the results table over (it holds other settings).")
@click.option("--diagnose", is_flag=True,
              help="Also diagnose each file; the effects it adds (e.g. friction) go to the 'effects' column.")
@click.option("--quiet", is_flag=True, help="No progress bar, summary or 'wrote' line (errors still go to stderr).")
@handle_errors
def batch(chart, data, output, fix_from, workers, scheduler, starts, seed, max_iter, alignment, substeps, shooting,
          mapping, units, retry_errors, force, diagnose, quiet) -> None:
    """Identify CHART on every DATA file (paths, directories or quoted globs): one row per file in OUTPUT.

    Rerunning the same command skips the files already done, so an interrupted run resumes.
    """
    from ..atomic import check_output_path
    from ..batch.run import BatchSettings, run_batch
    from ..diagram.validate import load_diagram
    from ..executors import make_executor
    from ..identify import IdentifySettings, fix_from_result

    chart, data = chart_first("sdnn batch CHART DATA...", chart, data)
    if workers and scheduler and scheduler != "local":
        raise click.UsageError("give either --workers or --scheduler ADDRESS (--workers sizes only 'local')")
    files = expand_files(data, exclude=(output, f"{output}.lock"))
    check_output_path(output, [chart] + ([fix_from] if fix_from else []) + files, force=True)
    diagram = with_substeps(load_diagram(chart), substeps)
    fixed: list[str] = []
    if fix_from:
        diagram, fixed = fix_from_result(diagram, fix_from)
    maps, scales = column_reading(diagram, mapping, units)
    with settings_usage():
        settings = BatchSettings(
            identify=IdentifySettings(starts=starts, seed=seed, max_iter=max_iter, alignment=alignment,
                                      fixed_from=tuple(fixed), shooting=shooting),
            mapping=tuple(sorted(maps.items())), scales=tuple(sorted(scales.items())), retry_errors=retry_errors, force=force,
            diagnose=diagnose)
    bar = BatchBar(len(files), quiet)
    with make_executor(workers, scheduler) as executor:
        if not quiet:
            click.echo(f"{len(files)} file(s), {executor.describe()}", err=True)
        summary = run_batch(diagram, files, output, settings, executor, bar)
    if not quiet:
        click.echo(f"wrote {output}: {summary.identified} identified, {summary.failed} failed, "
                   f"{summary.skipped} already done, {summary.copied} copied (same content) in "
                   f"{summary.seconds:.1f} s ({summary.files_per_second:.2f} files/s)")
        if summary.dropped_lines:
            click.echo(f"note: {summary.dropped_lines} torn line(s) of an interrupted run were dropped "
                       "and their files redone", err=True)
    if summary.failed:
        click.echo(f"{summary.failed} file(s) failed: see the 'error' column of {output}", err=True)

"""`sdnn batch` (identify a fleet of data files, resumably) and `sdnn report` (parameters over time per drive)."""

from __future__ import annotations

import glob
import os
import sys
import time

import click

__all__ = ["register", "expand_files", "BatchBar"]

_GLOB_CHARS = set("*?[")


def expand_files(patterns: tuple[str, ...], exclude: tuple[str, ...] = ()) -> list[str]:
    """Files named or matched (``**`` recursive) by the arguments, sorted and without repeats.

    A directory stands for the ``*.csv`` files in it. Quoted globs are expanded here, so fleets larger than the
    shell's argument limit work. Files in `exclude` (the results table itself) are left out.
    """
    from ..errors import SdnnError

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


class BatchBar:
    """A progress bar over files on stderr: redrawn on a terminal, a plain line every few seconds elsewhere."""

    def __init__(self, total: int, quiet: bool):
        self.total, self.quiet = total, quiet
        self.tty = sys.stderr.isatty()
        self.start = time.monotonic()
        self.last = 0.0
        self.failed = self.skipped = self.worked = 0

    def __call__(self, done: int, total: int, row: dict | None) -> None:
        if row is None:
            self.skipped += 1
        else:
            self.worked += 1
            self.failed += row.get("status") == "error"
        if self.quiet:
            return
        now = time.monotonic()
        if done < total and now - self.last < (0.2 if self.tty else 5.0):
            return
        self.last = now
        elapsed = now - self.start
        rate = self.worked / elapsed if elapsed > 0 else 0.0
        left = total - done
        eta = f", about {left / rate:.0f} s left" if rate > 0 and left else ""
        filled = int(round(24 * done / max(1, total)))
        line = (f"[{'#' * filled}{'.' * (24 - filled)}] {done}/{total} files ({self.skipped} already done, "
                f"{self.failed} failed) {rate:.2f} files/s{eta}")
        if self.tty:
            click.echo("\r" + line[:150].ljust(150), nl=done >= total, err=True)
        else:
            click.echo(line, err=True)


def register(main: click.Group) -> None:
    from ..cli import executor_options, handle_errors

    @main.command()
    @click.argument("chart", type=click.Path(dir_okay=False))
    @click.argument("data", nargs=-1, required=True)
    @click.option("-o", "--output", type=click.Path(dir_okay=False), default="results.csv", show_default=True,
                  help="Results table: .csv (appended after each file) or .parquet (needs pyarrow).")
    @click.option("--fix-from", type=click.Path(dir_okay=False),
                  help="Fix parameters and nonlinear blocks with matching names from an earlier RESULT.json.")
    @executor_options("the files' identifications")
    @click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
                  help="Multi-start per file (seeded starts, the first is the chart's init).")
    @click.option("--seed", type=int, default=0, show_default=True)
    @click.option("--max-iter", type=click.IntRange(min=0), default=100, show_default=True)
    @click.option("--alignment", type=click.Choice(["zoh", "direct"]), default="zoh", show_default=True)
    @click.option("--map", "mapping", multiple=True, metavar="NAME=COLUMN",
                  help="Take chart signal NAME from CSV column COLUMN (repeatable).")
    @click.option("--retry-errors", is_flag=True, help="Redo files whose earlier row is an error.")
    @click.option("--force", is_flag=True, help="Start the results table over (it holds other settings).")
    @click.option("--diagnose", is_flag=True,
                  help="Also diagnose each file; the effects it adds (e.g. friction) go to the 'effects' column.")
    @click.option("--quiet", is_flag=True, help="No progress bar and no summary.")
    @handle_errors
    def batch(chart, data, output, fix_from, workers, scheduler, starts, seed, max_iter, alignment, mapping,
              retry_errors, force, diagnose, quiet) -> None:
        """Identify CHART on every DATA file (paths, directories or quoted globs): one row per file in OUTPUT.

        Rerunning the same command skips the files already done, so an interrupted run resumes.
        """
        from ..atomic import check_output_path
        from ..data.csvdata import parse_mapping
        from ..diagram.validate import load_diagram
        from ..executors import make_executor
        from ..identify.document import fix_from_result
        from ..identify.run import IdentifySettings
        from .run import BatchSettings, run_batch

        if workers and scheduler and scheduler != "local":
            raise click.UsageError("give either --workers or --scheduler ADDRESS (--workers sizes only 'local')")
        files = expand_files(data, exclude=(output, f"{output}.lock"))
        check_output_path(output, [chart] + ([fix_from] if fix_from else []) + files, force=True)
        diagram = load_diagram(chart)
        fixed: list[str] = []
        if fix_from:
            diagram, fixed = fix_from_result(diagram, fix_from)
        settings = BatchSettings(
            identify=IdentifySettings(starts=starts, seed=seed, max_iter=max_iter, alignment=alignment,
                                      fixed_from=tuple(fixed)),
            mapping=tuple(sorted(parse_mapping(mapping).items())), retry_errors=retry_errors, force=force,
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

    @main.command()
    @click.argument("results", type=click.Path(dir_okay=False))
    @click.option("-o", "--output", "directory", type=click.Path(file_okay=False), required=True,
                  help="Directory for the plots, drift.csv and report.md (created if needed).")
    @click.option("--group", metavar="REGEX",
                  help="Read drive and day from each file path with (?P<drive>...) and (?P<day>...) groups.")
    @click.option("--threshold", type=click.FloatRange(min=0), default=0.10, show_default=True,
                  help="Smallest change over the days, as a fraction of the mean, that counts as drift.")
    @click.option("--t-min", type=click.FloatRange(min=0), default=3.0, show_default=True,
                  help="Smallest slope / robust standard error that counts as drift.")
    @click.option("--ci-factor", type=click.FloatRange(min=0), default=2.0, show_default=True,
                  help="The change must also exceed this many typical 95 % half-widths of one file's estimate.")
    @handle_errors
    def report(results, directory, group, threshold, t_min, ci_factor) -> None:
        """Plot each parameter of a batch RESULTS table over time per drive and list the drifting drives.

        Drive and day come from file names such as drive07_day012.csv, pump-3_2024-05-01.csv or
        drive07/2024-05-01.csv (see --group for others).
        """
        from .drift import drift_table, effects_table, load_fleet, plots_available, write_report

        fleet = load_fleet(results, group)
        drift = drift_table(fleet, threshold=threshold, t_min=t_min, ci_factor=ci_factor)
        plots = plots_available()
        if not plots:
            click.echo("warning: matplotlib is not installed, writing the tables only: "
                       "pip install flowchart2sdnn[plots]", err=True)
        written = write_report(fleet, drift, directory, plots=plots)
        n_files = sum(len(p) for p in fleet.drives.values())
        click.echo(f"{len(fleet.drives)} drive(s), {n_files} file(s), {len(fleet.errors)} error row(s); "
                   f"wrote {len(written)} file(s) to {directory}")
        if fleet.unmatched:
            click.echo(f"warning: {len(fleet.unmatched)} file name(s) give no drive and day, e.g. "
                       f"'{fleet.unmatched[0]}' (see --group)", err=True)
        for d in drift:
            if d["drift"]:
                click.echo(f"drift: drive {d['drive']}: {d['parameter']} {d['drift']} {d['change_percent']:+.1f} % "
                           f"({d['first']:.4g} -> {d['last']:.4g}, days {d['first_day']}..{d['last_day']})")
        for e in effects_table(fleet):
            click.echo(f"effect: drive {e['drive']}: {e['effect']} on {len(e['days'])} of {e['of']} days, "
                       f"first on day {e['first_day']}")

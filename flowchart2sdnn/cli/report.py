"""`sdnn report`: each parameter of a batch results table over time per drive, and the drifting drives (the
click layer over batch.drift).

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import click

from .help import SectionedCommand
from .options import handle_errors

__all__ = ["report"]


@click.command(name="report", cls=SectionedCommand,
               short_help="Each parameter of a batch table over time; the drifting drives.",
               sections={"Drift": ("group", "threshold", "t_min", "ci_factor")})
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
    from ..batch.drift import drift_table, effects_table, load_fleet
    from ..report.drift import plots_available, write_report

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
    if fleet.unconverged:
        click.echo(f"warning: {len(fleet.unconverged)} fit(s) did not converge and are left out of the trends"
                   f", e.g. '{fleet.unconverged[0]}'", err=True)
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

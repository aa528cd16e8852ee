"""`sdnn linearize`: the continuous state-space model of an identified chart, its poles, a python-control file
and a Bode figure over the frequency response measured in data.

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import json

import click

from ..strictjson import strict_json
from .help import SectionedCommand
from .options import column_reading, data_options, force_option, handle_errors, rows_option, windowed
from .order import MODEL_SUFFIXES, chart_first

__all__ = ["linearize"]


def _matrix(name: str, m, rows, cols) -> str:
    from ..tables import table

    return f"{name}:\n" + table([""] + list(cols), [[r, *map(float, line)] for r, line in zip(rows, m, strict=True)])


@click.command(name="linearize", cls=SectionedCommand,
               short_help="Linear model at an operating point: poles, damping, Bode.",
               sections={"Operating point": ("at", "kink"), "Output": ("control_path", "bode")})
@click.argument("model", type=click.Path(dir_okay=False))
@click.argument("data", nargs=-1, type=click.Path(dir_okay=False))
@click.option("--at", "at", multiple=True, metavar="NAME=VALUE,...",
              help="Operating point: values of states (integrators) and inputs; default 0 (at rest).")
@click.option("--kink", type=click.Choice(["zero", "smooth"]), default="zero", show_default=True,
              help="A Coulomb kink (sign_smooth): zero = the sign function's slope, smooth = the smoothed slope.")
@click.option("--control", "control_path", type=click.Path(dir_okay=False),
              help="Write A, B, C, D and the names for python-control (.npz, or JSON for any other name).")
@click.option("--bode", type=click.Path(dir_okay=False),
              help="Write the Bode figure (PNG), over the frequency response estimated from DATA when given.")
@click.option("--diagram", "chart", type=click.Path(dir_okay=False),
              help="With a RESULT.json: put its values into this chart instead of the identified chart beside it.")
@data_options
@rows_option()
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@force_option()
@handle_errors
def linearize(model, data, at, kink, control_path, bode, chart, mapping, units, fmt, force) -> None:
    """Linearise MODEL (an identified chart, or a RESULT.json with it) at an operating point: the continuous
    state-space model, its poles with natural frequencies and damping ratios. DATA (CSV records) feed the
    measured frequency response of --bode."""
    from ..analysis.linearize import linearize as run_linearize
    from ..analysis.linearize import parse_operating_point
    from ..atomic import check_output_path
    from ..identify import read_model
    from ..tables import table

    model, data = chart_first("sdnn linearize MODEL DATA...", model, data, MODEL_SUFFIXES)
    if data and not bode:
        raise click.UsageError("DATA is only read for --bode (the measured frequency response)")
    if bode:
        from ..report.canvas import require_matplotlib

        require_matplotlib()
    for path in (control_path, bode):
        if path:
            check_output_path(path, [model, *data] + ([chart] if chart else []), force=force)
    try:
        point = parse_operating_point(at)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--at") from None
    diagram, _ = read_model(model, chart)
    try:
        lin = run_linearize(diagram, point, kink)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--at") from None
    if control_path:
        from ..analysis.linearize import write_state_space

        write_state_space(lin, control_path)
    if bode:
        from ..analysis.response import empirical_response
        from ..data.csvdata import read_csv
        from ..identify import required_columns
        from ..report.bode import write_bode

        estimates = []
        maps, scales = column_reading(diagram, mapping, units)
        for d in data:
            ds = windowed(read_csv(d, required_columns(diagram), maps, diagram.sample_time, scale=scales))
            for o in lin.outputs:
                for i in lin.inputs:
                    estimates.append(empirical_response(ds.columns[i], ds.columns[o], diagram.sample_time, i, o))
        write_bode(lin, bode, estimates)
    if fmt == "json":
        doc = lin.to_dict()
        doc["damp"] = [{**d, "pole": [d["pole"].real, d["pole"].imag]} for d in lin.damp()]
        click.echo(json.dumps(strict_json(doc), indent=1))
    else:
        where = ", ".join(f"{k} = {v:g}" for k, v in lin.at.items())
        click.echo(f"{lin.name} linearised at {where}")
        click.echo("dx/dt = A x + B u, y = C x + D u (deviations from that point; states: "
                   + ", ".join(f"{s} in {lin.units.get(s) or '?'}" for s in lin.states) + ")")
        if any(abs(v) > 1e-9 for v in lin.xdot):
            click.echo("not an equilibrium: dx/dt there = " + ", ".join(f"{s}: {v:.4g}" for s, v in
                                                                      zip(lin.states, lin.xdot, strict=True)))
        for note in lin.notes:
            click.echo(f"note: {note}")
        click.echo(_matrix("A", lin.A, lin.states, lin.states), nl=False)
        click.echo(_matrix("B", lin.B, lin.states, lin.inputs), nl=False)
        click.echo(_matrix("C", lin.C, lin.outputs, lin.states), nl=False)
        click.echo(_matrix("D", lin.D, lin.outputs, lin.inputs), nl=False)
        rows = [[f"{d['pole'].real:.6g}" + (f" ± {abs(d['pole'].imag):.6g}j" if abs(d["pole"].imag) > 0 else ""),
                 d["wn"], d["f_hz"], d["zeta"], d["damped_hz"]] for d in lin.damp()]
        click.echo("poles:\n" + table(["pole (1/s)", "wn (rad/s)", "f (Hz)", "damping ratio", "damped f (Hz)"],
                                      rows), nl=False)
    for path in (control_path, bode):
        if path:
            click.echo(f"wrote {path}", err=fmt == "json")  # with --format json stdout stays the JSON

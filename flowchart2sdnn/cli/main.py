"""The `sdnn` group, its small commands (lint, compile, simulate, excite) and the registration of every command.

Layer: cli (the rule is in the package docstring). A command parses its flags, calls library functions and
formats their answers, nothing more.

Each command imports the library it needs inside its body: `sdnn --help` and `sdnn lint` should not pay for
numba.
"""

from __future__ import annotations

import json
import sys

import click

from .. import __version__
from ..errors import SdnnError
from .batch import batch
from .compare import compare
from .diagnose import diagnose
from .help import SectionedCommand, WorkflowGroup
from .identify import identify
from .linearize import linearize
from .options import (
    alignment_option,
    column_reading,
    data_options,
    force_option,
    handle_errors,
    rows_option,
    seed_option,
    settings_usage,
    substeps_option,
    windowed,
    with_substeps,
)
from .order import chart_first
from .report import report

__all__ = ["main"]


#: `sdnn --help` lists the commands as a first session uses them
WORKFLOW = ("lint", "compile", "excite", "simulate", "identify", "compare", "linearize", "diagnose", "batch", "report")


@click.group(cls=WorkflowGroup, order=WORKFLOW,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
             epilog="Every command reads the chart (or model) first, then the data: sdnn COMMAND CHART [DATA...]. "
                    "sdnn COMMAND --help lists its options.")
@click.version_option(__version__, prog_name="sdnn")
def main() -> None:
    """Grey-box identification of mechatronic systems from a YAML signal flow chart."""


# ------------------------------------------------------------------------------------------------ lint
@main.command(cls=SectionedCommand,
              short_help="Check a chart: loops, signals, units, bounds, identifiability.")
@click.argument("chart", type=click.Path(dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@handle_errors
def lint(chart: str, fmt: str) -> None:
    """Check CHART: loops, signals, units, bounds, identifiability. Exit 1 when any error."""
    from ..analysis.lint import curve_notes
    from ..compiler import check_file
    from ..diagram.validate import load_diagram

    diagnostics = check_file(chart)
    errors = [d for d in diagnostics if d.severity == "error"]
    notes = [] if errors else curve_notes(load_diagram(chart))  # what each learned curve can represent
    if fmt == "json":
        click.echo(json.dumps({"file": chart, "errors": len(errors), "diagnostics": [d.to_dict() for d in diagnostics],
                               "curves": [d.to_dict() for d in notes]}, indent=1))
    else:
        for d in diagnostics + notes:
            click.echo(d.one_line(), err=d.severity == "error")
        warnings = len(diagnostics) - len(errors)
        click.echo(f"{chart}: {len(errors)} error(s), {warnings} warning(s)", err=bool(errors))
    if errors:
        sys.exit(1)


# ------------------------------------------------------------------------------------------------ compile
@main.command(name="compile", cls=SectionedCommand, sections={"Output": ("dot", "svg", "explain")},
              short_help="Build a chart's network; explain it as equations, or draw it.")
@click.argument("chart", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Write the network file (JSON).")
@click.option("--explain", is_flag=True, help="Print every weight as an equation and every delayed edge.")
@click.option("--dot", type=click.Path(dir_okay=False), help="Write a Graphviz drawing of the network.")
@click.option("--svg", type=click.Path(dir_okay=False),
              help="Write the chart as a block diagram (SVG; no Graphviz needed).")
@seed_option("Seed for the initial learned weights.")
@substeps_option()
@force_option()
@handle_errors
def compile_(chart: str, output: str | None, explain: bool, dot: str | None, svg: str | None, seed: int, substeps,
             force: bool) -> None:
    """Compile CHART into a structured GDNN with administration matrices."""
    from ..atomic import atomic_write_text, check_output_path
    from ..compiler import compile_file
    from ..network.explain import explain_network, network_dot

    for path in (output, dot, svg):
        if path:
            check_output_path(path, [chart], force=force)
    comp = compile_file(chart, seed=seed, substeps=substeps)
    for w in comp.warnings:
        click.echo(w.one_line(), err=True)
    net = comp.network
    if output:
        atomic_write_text(output, net.to_json())
        click.echo(f"wrote {output}", err=True)  # stderr: stdout stays the network or the explanation
    if dot:
        atomic_write_text(dot, network_dot(net))
        click.echo(f"wrote {dot}", err=True)
    if svg:
        from ..analysis.drawing import chart_svg

        atomic_write_text(svg, chart_svg(comp.diagram))
        click.echo(f"wrote {svg}", err=True)
    if explain:
        click.echo(explain_network(net), nl=False)
        click.echo("\n" + comp.substeps.explain(net.sample_time))
    elif not output and not dot and not svg:
        click.echo(net.to_json(), nl=False)


# ------------------------------------------------------------------------------------------------ simulate
@main.command(cls=SectionedCommand,
              sections={"Data and chart": ("params",), "Simulation": ("continuous", "signals")},
              short_help="Run a chart on a record's inputs (network or continuous).")
@click.argument("chart", type=click.Path(dir_okay=False))
@click.argument("data", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Output CSV (default: stdout).")
@click.option("--params", type=click.Path(dir_okay=False), help="Identified values from a RESULT.json.")
@click.option("--continuous", is_flag=True, help="Simulate the chart itself with a fine-step ODE solver.")
@click.option("--signals", type=click.Choice(["outputs", "all"]), default="outputs", show_default=True)
@alignment_option()
@substeps_option()
@data_options
@rows_option()
@force_option("Overwrite an existing output file.")
@handle_errors
def simulate(chart, data, output, params, continuous, signals, alignment, substeps, mapping, units, force) -> None:
    """Run CHART on the inputs in DATA (CSV) and write time and output columns."""
    import numpy as np

    from ..atomic import check_output_path
    from ..data.csvdata import read_csv, write_csv
    from ..diagram.validate import load_diagram
    from ..simulate.run import simulate_chart, simulation_columns

    chart, (data,) = chart_first("sdnn simulate CHART DATA", chart, (data,))
    if output:
        check_output_path(output, [chart, data] + ([params] if params else []), force=force)
    diagram = with_substeps(load_diagram(chart), substeps)
    if params:
        from ..identify import apply_result_file

        diagram = apply_result_file(diagram, params)
    maps, scales = column_reading(diagram, mapping, units)
    ds = windowed(read_csv(data, simulation_columns(diagram), maps, diagram.sample_time, scale=scales))
    columns = simulate_chart(diagram, ds, alignment=alignment, continuous=continuous, all_signals=signals == "all")
    if output:
        write_csv(output, columns)
        click.echo(f"wrote {output}: {ds.n_rows} rows, columns {', '.join(columns)}", err=True)
    else:
        names = list(columns)
        click.echo(",".join(names))
        arr = np.column_stack([columns[n] for n in names])
        for row in arr:
            click.echo(",".join(f"{v:.10g}" for v in row))


# ------------------------------------------------------------------------------------------------ excite
EXCITATION = {"Excitation": ("seconds", "input_name", "amplitude", "hold", "relay_level", "relay_switch", "relay_band",
                             "relay_band_scale", "speed", "noise_std")}


@main.command(cls=SectionedCommand, sections=EXCITATION,
              short_help="Virtual test bench: simulate a plant chart under excitation.")
@click.argument("plant", type=click.Path(dir_okay=False))
@click.option("--seconds", type=click.FloatRange(min=0, min_open=True), required=True)
@seed_option()
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True, help="Data CSV to write.")
@click.option("--amplitude", nargs=2, type=float, default=(-7.0, 7.0), show_default=True,
              help="APRBS level range.")
@click.option("--hold", nargs=2, type=float, default=(0.010, 0.250), show_default=True,
              help="APRBS hold time range, s.")
@click.option("--relay-level", type=float, default=4.0, show_default=True)
@click.option("--relay-switch", type=float, default=10.0, show_default=True,
              help="Relay switches when |speed| exceeds this.")
@click.option("--relay-band", type=float, default=2.0, show_default=True,
              help="Relay output scaled while |speed| is below this.")
@click.option("--relay-band-scale", type=float, default=0.2, show_default=True)
@click.option("--noise", "noise_std", type=float, default=0.0, show_default=True,
              help="Std of Gaussian measurement noise on every output.")
@click.option("--input", "input_name", help="Excited input (default: the chart's first input).")
@click.option("--speed", help="Signal the relay watches (default: the first output).")
@click.option("--substeps", type=click.IntRange(1, 10000), default=20, show_default=True,
              help="Integration steps per sample.")
@force_option("Overwrite an existing output file.")
@handle_errors
def excite(plant, seconds, seed, output, amplitude, hold, relay_level, relay_switch, relay_band, relay_band_scale,
           noise_std, input_name, speed, substeps, force) -> None:
    """Virtual test bench: simulate PLANT continuously under the paper's APRBS + relay excitation."""
    from ..atomic import check_output_path
    from ..data.csvdata import write_csv
    from ..diagram.validate import load_diagram
    from ..simulate.excitation import ExcitationSettings
    from ..simulate.excitation import excite as run_excite

    with settings_usage(noise_std="--noise"):
        settings = ExcitationSettings(seconds=seconds, seed=seed, amplitude=tuple(amplitude), hold=tuple(hold),
                                      relay_level=relay_level, relay_switch=relay_switch, relay_band=relay_band,
                                      relay_band_scale=relay_band_scale, noise_std=noise_std, input=input_name,
                                      speed=speed)
    check_output_path(output, [plant], force=force)
    diagram = load_diagram(plant)
    if input_name is not None and input_name not in diagram.input_names:
        raise click.BadParameter(f"'{input_name}' is not an input of {plant} ({', '.join(diagram.input_names)})",
                                 param_hint="--input")
    try:
        columns = run_excite(diagram, settings, substeps=substeps)
    except ValueError as exc:  # the chart cannot be simulated as asked (e.g. a hold shorter than a sample)
        raise SdnnError.at("EXC001", str(exc), plant) from None
    write_csv(output, columns)
    n = len(columns["time"])
    click.echo(f"wrote {output}: {n} samples ({seconds:g} s at T = {diagram.sample_time:g} s), seed {seed}", err=True)


# ------------------------------------------------------------------------------------------------ the rest
for _command in (identify, diagnose, batch, report, compare, linearize):
    main.add_command(_command)

"""The `sdnn` command: a thin click layer over the library. The only module that prints or knows exit codes.

Exit codes: 0 success, 1 a user error (bad chart, bad data, failed run; one line on stderr), 2 bad usage.
"""

from __future__ import annotations

import functools
import json
import os
import sys

import click

from . import __version__
from .errors import SdnnError

# Our matrices are small (P x P, or M x P with P ~ 10): threaded BLAS only adds contention. On a shared 2-core
# machine one J^T J took 1.6 s with default threads and 11 ms with one. Set before numpy is first imported;
# a user's own setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# Each command imports what it needs: `sdnn --help` and `sdnn lint` should not pay for numba.


def _fail(message: str) -> None:
    click.echo(message, err=True)
    sys.exit(1)


def handle_errors(func):
    """Turn library errors into one line on stderr and exit 1: never a traceback, never a partial file."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except SdnnError as exc:
            first = exc.diagnostics[0].one_line()
            more = len([d for d in exc.diagnostics if d.severity == "error"]) - 1
            _fail(first + (f" (+{more} more error(s); run 'sdnn lint' to see all)" if more > 0 else ""))
        except KeyboardInterrupt:
            _fail("interrupted")
        except (click.exceptions.Exit, click.ClickException, SystemExit):
            raise
        except MemoryError:
            _fail("error: out of memory")
        except Exception as exc:  # noqa: BLE001 - the promise is one line, not a traceback
            _fail(f"internal error ({type(exc).__name__}): {' '.join(str(exc).split())[:300]} "
                  "- please report this with the command line")

    return wrapper


def executor_options(work: str):
    """`--workers N` and `--scheduler ADDRESS` (see flowchart2sdnn.executors.make_executor), worded for `work`."""

    def decorate(func):
        func = click.option("--scheduler", metavar="ADDRESS",
                            help=f"Run {work} on a Dask cluster (tcp://host:8786, or 'local').")(func)
        return click.option("--workers", type=click.IntRange(min=1),
                            help=f"Run {work} in N local worker processes.")(func)

    return decorate


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="sdnn")
def main() -> None:
    """Grey-box identification of mechatronic systems from a YAML signal flow chart."""


# ------------------------------------------------------------------------------------------------ lint
@main.command()
@click.argument("chart", type=click.Path(dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@handle_errors
def lint(chart: str, fmt: str) -> None:
    """Check CHART: loops, signals, units, bounds, identifiability. Exit 1 when any error."""
    from .analysis.lint import lint_diagram
    from .compiler import compile_diagram
    from .diagram.validate import load_diagram

    diagnostics: list = []
    try:
        diagram = load_diagram(chart)
        diagnostics = lint_diagram(diagram)
        if not any(d.severity == "error" for d in diagnostics):
            compile_diagram(diagram)  # what only the compiler finds (a loop of gains, an overflowing weight)
    except SdnnError as exc:
        diagnostics = diagnostics + list(exc.diagnostics)
    errors = [d for d in diagnostics if d.severity == "error"]
    if fmt == "json":
        click.echo(json.dumps({"file": chart, "errors": len(errors), "diagnostics": [d.to_dict() for d in diagnostics]},
                              indent=1))
    else:
        for d in diagnostics:
            click.echo(d.one_line(), err=d.severity == "error")
        warnings = len(diagnostics) - len(errors)
        click.echo(f"{chart}: {len(errors)} error(s), {warnings} warning(s)", err=bool(errors))
    if errors:
        sys.exit(1)


# ------------------------------------------------------------------------------------------------ compile
@main.command(name="compile")
@click.argument("chart", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Write the network file (JSON).")
@click.option("--explain", is_flag=True, help="Print every weight as an equation and every delayed edge.")
@click.option("--dot", type=click.Path(dir_okay=False), help="Write a Graphviz drawing of the network.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for the initial learned weights.")
@click.option("--force", is_flag=True, help="Overwrite existing output files.")
@handle_errors
def compile_(chart: str, output: str | None, explain: bool, dot: str | None, seed: int, force: bool) -> None:
    """Compile CHART into a structured GDNN with administration matrices."""
    from .atomic import atomic_write_text, check_output_path
    from .compiler import compile_file
    from .network.explain import explain_network, network_dot

    for path in (output, dot):
        if path:
            check_output_path(path, [chart], force=force)
    comp = compile_file(chart, seed=seed)
    for w in comp.warnings:
        click.echo(w.one_line(), err=True)
    net = comp.network
    if output:
        atomic_write_text(output, net.to_json())
    if dot:
        atomic_write_text(dot, network_dot(net))
    if explain:
        click.echo(explain_network(net), nl=False)
    elif not output and not dot:
        click.echo(net.to_json(), nl=False)


# ------------------------------------------------------------------------------------------------ simulate
@main.command()
@click.argument("chart", type=click.Path(dir_okay=False))
@click.argument("data", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Output CSV (default: stdout).")
@click.option("--params", type=click.Path(dir_okay=False), help="Identified values from a RESULT.json.")
@click.option("--continuous", is_flag=True, help="Simulate the chart itself with a fine-step ODE solver.")
@click.option("--signals", type=click.Choice(["outputs", "all"]), default="outputs", show_default=True)
@click.option("--alignment", type=click.Choice(["zoh", "direct"]), default="zoh", show_default=True,
              help="zoh: input sample k acts on [t_k, t_k+1) (logged data); direct: output k uses input k.")
@click.option("--map", "mapping", multiple=True, metavar="NAME=COLUMN", help="Take chart signal NAME from COLUMN.")
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
@handle_errors
def simulate(chart, data, output, params, continuous, signals, alignment, mapping, force) -> None:
    """Run CHART on the inputs in DATA (CSV) and write time and output columns."""
    import numpy as np

    from .atomic import check_output_path
    from .data.csvdata import parse_mapping, read_csv, write_csv
    from .diagram.validate import load_diagram

    if output:
        check_output_path(output, [chart, data] + ([params] if params else []), force=force)
    diagram = load_diagram(chart)
    if params:
        from .identify.document import apply_result_file

        diagram = apply_result_file(diagram, params)
    maps = parse_mapping(mapping)
    data_init_outputs = [b.name for b in diagram.blocks if b.kind == "integrator" and b.init == "data"]
    ds = read_csv(data, list(diagram.input_names) + data_init_outputs, maps, diagram.sample_time)
    u = np.column_stack([ds.columns[n] for n in diagram.input_names])
    init = {n: float(ds.columns[n][0]) for n in data_init_outputs}
    time = ds.time if ds.time is not None else np.arange(ds.n_rows) * diagram.sample_time
    if continuous:
        from .simulate.continuous import simulate_continuous

        result = simulate_continuous(diagram, u, init=init, signals=(signals == "all"))
        if signals == "all":
            columns = {"time": time, **{k: np.asarray(v) for k, v in result.items() if k not in diagram.input_names}}
        else:
            columns = {"time": time, **{n: result[:, i] for i, n in enumerate(diagram.output_names)}}
    else:
        from .compiler import compile_diagram
        from .network.alignment import run_aligned
        from .network.runtime import CompiledNetwork

        net = compile_diagram(diagram).network
        compiled = CompiledNetwork(net)
        theta = compiled.theta0()
        y = run_aligned(compiled, theta, u, alignment, init)
        columns = {"time": time, **{n: y[:, i] for i, n in enumerate(compiled.output_names)}}
        if signals == "all":
            from .network.alignment import network_inputs
            from .network.flat import flatten, signal_names

            p = network_inputs(u, alignment)
            names = signal_names(net)
            sig = compiled.signals(theta, p, init) if len(p) else {n: np.empty(0) for n in names}
            # zoh: row 0 is the initial state of every neuron (its history), as for the outputs
            history = dict(zip(names, flatten(net).history_with(init), strict=True))
            for name, values in sig.items():
                if name.endswith("__out") or name in columns:
                    continue
                columns[name] = np.concatenate([[history[name]], values]) if alignment == "zoh" else values
    if output:
        write_csv(output, columns)
    else:
        names = list(columns)
        click.echo(",".join(names))
        arr = np.column_stack([columns[n] for n in names])
        for row in arr:
            click.echo(",".join(f"{v:.10g}" for v in row))


# ------------------------------------------------------------------------------------------------ excite
@main.command()
@click.argument("plant", type=click.Path(dir_okay=False))
@click.option("--seconds", type=click.FloatRange(min=0, min_open=True), required=True)
@click.option("--seed", type=int, default=0, show_default=True)
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
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
@handle_errors
def excite(plant, seconds, seed, output, amplitude, hold, relay_level, relay_switch, relay_band, relay_band_scale,
           noise_std, input_name, speed, substeps, force) -> None:
    """Virtual test bench: simulate PLANT continuously under the paper's APRBS + relay excitation."""
    from .atomic import check_output_path
    from .data.csvdata import write_csv
    from .diagram.validate import load_diagram
    from .simulate.excitation import ExcitationSettings
    from .simulate.excitation import excite as run_excite

    check_output_path(output, [plant], force=force)
    diagram = load_diagram(plant)
    settings = ExcitationSettings(seconds=seconds, seed=seed, amplitude=tuple(amplitude), hold=tuple(hold),
                                  relay_level=relay_level, relay_switch=relay_switch, relay_band=relay_band,
                                  relay_band_scale=relay_band_scale, noise_std=noise_std, input=input_name,
                                  speed=speed)
    columns = run_excite(diagram, settings, substeps=substeps)
    write_csv(output, columns)
    n = len(columns["time"])
    click.echo(f"wrote {output}: {n} samples ({seconds:g} s at T = {diagram.sample_time:g} s), seed {seed}", err=True)


def _register_optional_commands() -> None:
    """Commands that live in their own modules (identify, diagnose, ...) register themselves when present."""
    import importlib

    for module in ("flowchart2sdnn.identify.cli", "flowchart2sdnn.diagnose.cli", "flowchart2sdnn.batch.cli"):
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name and module.startswith(exc.name):
                continue
            raise
        mod.register(main)


_register_optional_commands()

if __name__ == "__main__":  # pragma: no cover
    main()

__all__ = ["main", "handle_errors"]

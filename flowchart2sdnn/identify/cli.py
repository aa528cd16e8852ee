"""`sdnn identify`: the click layer over identify.run (formatting lives in identify.report)."""

from __future__ import annotations

import signal
import sys
import threading
import time
from pathlib import Path

import click

__all__ = ["register", "Progress", "CtrlC"]


class CtrlC:
    """The first Ctrl-C only asks the run to stop (it then writes the best result so far); a second one aborts.

    A KeyboardInterrupt raised at an arbitrary point (inside numba code, while computing the uncertainty)
    could lose the whole run, so SIGINT sets a flag that the trainer polls between iterations instead.
    Only the main thread can own signal handlers; elsewhere this is an inert flag.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)

    def _handle(self, signum, frame) -> None:
        if self.requested:
            self.restore()
            raise KeyboardInterrupt
        self.requested = True

    def __call__(self) -> bool:
        return self.requested

    def restore(self) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


class Progress:
    """Progress on stderr: a redrawn line on a terminal, an occasional plain line elsewhere; silent if quiet."""

    def __init__(self, quiet: bool, min_interval: float = 1.0):
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.start = time.monotonic()
        self.last = 0.0
        self.min_interval = min_interval if self.tty else 5.0
        self.drawn = False

    def __call__(self, text: str, fraction: float | None = None) -> None:
        if self.quiet:
            return
        now = time.monotonic()
        if now - self.start < 1.0 or now - self.last < self.min_interval:
            return  # nothing for runs shorter than a second
        self.last = now
        bar = ""
        if fraction is not None:
            filled = int(round(20 * max(0.0, min(1.0, fraction))))
            bar = "[" + "#" * filled + "." * (20 - filled) + f"] {100 * fraction:3.0f}% "
        line = f"{bar}{text} ({now - self.start:.0f} s)"
        if self.tty:
            click.echo("\r" + line[:150].ljust(150), nl=False, err=True)
            self.drawn = True
        else:
            click.echo(line, err=True)

    def close(self) -> None:
        if self.drawn:
            click.echo("\r" + " " * 150 + "\r", nl=False, err=True)


def register(main: click.Group) -> None:
    from ..cli import executor_options, handle_errors

    @main.command()
    @click.argument("data", nargs=-1, required=True, type=click.Path(dir_okay=False))
    @click.option("--diagram", "chart", required=True, type=click.Path(dir_okay=False), help="The chart (YAML).")
    @click.option("-o", "--output", type=click.Path(dir_okay=False),
                  help="RESULT.json; the identified chart is written beside it as RESULT.chart.yaml.")
    @click.option("--fix-from", type=click.Path(dir_okay=False),
                  help="Fix parameters and nonlinear blocks with matching names from an earlier RESULT.json.")
    @click.option("--validate", "validation", type=click.Path(dir_okay=False), help="Validation record (CSV).")
    @click.option("--split", type=click.FloatRange(0, 1, min_open=True, max_open=True),
                  help="Train on this leading fraction of DATA, validate on the rest.")
    @click.option("--starts", type=click.IntRange(min=1), default=1, show_default=True,
                  help="Multi-start: number of seeded starts (the first is the chart's init); with --online, that many "
                       "quasi-online runs, the one with the lowest final window cost reported.")
    @click.option("--seed", type=int, default=0, show_default=True, help="Seed for starts and initial curves.")
    @click.option("--online", is_flag=True, help="Quasi-online LM over a sliding window (paper section 3.1).")
    @click.option("--window", type=click.IntRange(min=2), default=25000, show_default=True,
                  help="Quasi-online window Q (samples).")
    @click.option("--average", type=click.IntRange(min=1), default=25000, show_default=True,
                  help="Quasi-online: report the mean over the last K steps.")
    @click.option("--max-iter", type=click.IntRange(min=0), default=100, show_default=True)
    @click.option("--alignment", type=click.Choice(["zoh", "direct"]), default="zoh", show_default=True,
                  help="zoh: input sample k acts on [t_k, t_k+1) (logged data); direct: output k uses input k.")
    @click.option("--map", "mapping", multiple=True, metavar="NAME=COLUMN",
                  help="Take chart signal NAME from CSV column COLUMN (repeatable).")
    @click.option("--plots", type=click.Path(file_okay=False),
                  help="Directory for the figures (PNG; created if needed, figures of the same name replaced). "
                       "Needs matplotlib: pip install flowchart2sdnn[plots].")
    @click.option("--force", is_flag=True, help="Overwrite existing output files.")
    @click.option("--quiet", is_flag=True, help="No progress and no table.")
    @executor_options("the multi-start fits")
    @handle_errors
    def identify(data, chart, output, fix_from, validation, split, starts, seed, online, window, average,
                 max_iter, alignment, mapping, plots, force, quiet, workers=None, scheduler=None) -> None:
        """Identify the physical parameters of the chart from measured DATA (CSV; several records are fitted
        together, each simulated from its own initial state)."""
        from ..atomic import atomic_write_text, check_output_path
        from ..data.csvdata import parse_mapping, read_csv
        from ..diagram.dump import dump_diagram
        from ..diagram.validate import load_diagram
        from ..errors import SdnnError
        from .document import dumps, fix_from_result
        from .problem import required_columns
        from .run import IdentifySettings
        from .run import identify as run_identify
        from .summary import format_result

        if validation and split:
            raise click.UsageError("give either --validate or --split, not both")
        inputs = [*data, chart] + [p for p in (fix_from, validation) if p]
        if plots:
            from .plots import require_matplotlib

            require_matplotlib()  # before any work: a missing extra must not cost a whole run
        chart_out = None
        if output:
            chart_out = str(Path(output).with_suffix("")) + ".chart.yaml"
            check_output_path(output, inputs, force=force)
            check_output_path(chart_out, inputs, force=force)
        diagram = load_diagram(chart)
        fixed = []
        if fix_from:
            diagram, fixed = fix_from_result(diagram, fix_from)
        maps = parse_mapping(mapping)
        cols = required_columns(diagram)
        train = [read_csv(d, cols, maps, diagram.sample_time) for d in data]
        val = read_csv(validation, cols, maps, diagram.sample_time) if validation else None
        settings = IdentifySettings(starts=starts, seed=seed, max_iter=max_iter, alignment=alignment, split=split,
                                    online=online, window=window, average=average, fixed_from=tuple(fixed))
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
        result = outcome.to_document()
        if result["status"] == "diverged_at_start":
            raise SdnnError.at("FIT001", result["message"], chart,
                               hint="the start values make the model unstable on this data: change 'init'")
        result["command"] = {"data": data[0] if len(data) == 1 else list(data), "diagram": chart, "fix_from": fix_from, "validate": validation,
                             "map": dict(maps)}
        if output:
            result["identified_chart"] = chart_out
            # both texts first: a failure here must not leave one file without the other
            chart_text = dump_diagram(outcome.diagram, {"from": output, "status": result["status"]})
            result_text = dumps(result)
            atomic_write_text(chart_out, chart_text)
            atomic_write_text(output, result_text)
        if plots:
            from .plots import write_plots

            write_plots(outcome, plots)
        if not quiet:
            click.echo(format_result(outcome, fixed), nl=False)
            if output:
                click.echo(f"wrote {output} and {chart_out}")
        if result["status"] == "interrupted":
            click.echo(f"interrupted: {'the best result so far is in ' + output if output else 'no -o, nothing written'}",
                       err=True)
            sys.exit(1)

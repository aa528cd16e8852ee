"""What every `sdnn` command shares: its options (each declared once, here), its error handling, and the
mapping of library settings errors to usage errors.

Layer: cli (the rule is in the package docstring).

Exit codes: 0 success, 1 a user error (bad chart, bad data, failed run; one line on stderr), 2 bad usage.
"""

from __future__ import annotations

import functools
import re
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import click

from .. import rules
from ..errors import SdnnError

__all__ = ["fail", "handle_errors", "settings_usage", "executor_options", "force_option", "seed_option",
           "map_option", "unit_option", "data_options", "column_reading", "rows_option", "windowed", "alignment_option", "max_iter_option",
           "substeps_option", "with_substeps", "timebase_options", "read_records", "intersample_option",
           "with_intersample", "ALIGNMENT_HELP", "html_option", "require_figures"]

ALIGNMENT_HELP = "zoh: input sample k acts on [t_k, t_k+1) (logged data); direct: output k uses input k."


# ------------------------------------------------------------------------------------------------ errors
def fail(message: str) -> None:
    """One line on stderr, exit 1."""
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
            fail(first + (f" (+{more} more error(s); run 'sdnn lint' to see all)" if more > 0 else ""))
        except KeyboardInterrupt:
            fail("interrupted")
        except (click.exceptions.Exit, click.ClickException, SystemExit):
            raise
        except MemoryError:
            fail("error: out of memory")
        except Exception as exc:  # noqa: BLE001 - the promise is one line, not a traceback
            fail(f"internal error ({type(exc).__name__}): {' '.join(str(exc).split())[:300]} "
                 "- please report this with the command line")

    return wrapper


def flag_words(message: str, flags: Mapping[str, str]) -> str:
    """`message` with each settings field name (``max_iter``) replaced by its flag (``--max-iter``).

    A name already written as a flag (``--starts``) is left alone, so the message reads the same whether the
    library names its fields or (as it used to) the command line's flags.
    """
    for name in sorted(flags, key=len, reverse=True):
        message = re.sub(rf"(?<![\w-]){re.escape(name)}(?![\w-])", flags[name], message)
    return message


@contextmanager
def settings_usage(**extra_flags: str) -> Iterator[None]:
    """Library settings refuse a bad value in library words (``starts must be at least 1``); on the command line
    that is a usage error naming the flag (``--starts must be at least 1``), exit 2.

    The flags are those of the running command (a field ``max_iter`` is the option ``--max-iter``), plus
    `extra_flags` for fields named otherwise (``split="--split"``).
    """
    try:
        yield
    except ValueError as exc:
        flags: dict[str, str] = {}
        ctx = click.get_current_context(silent=True)
        if ctx is not None:
            for param in ctx.command.params:
                longs = [o for o in param.opts if o.startswith("--")]
                if isinstance(param, click.Option) and longs and param.name:
                    flags[param.name] = longs[0]
                    flags[longs[0][2:].replace("-", "_")] = longs[0]
        flags.update(extra_flags)
        raise click.UsageError(flag_words(str(exc), flags), ctx=ctx) from None


# ------------------------------------------------------------------------------------------------ options
def force_option(help: str = "Overwrite existing output files."):
    """``--force``: overwrite what a command writes (worded per command)."""
    return click.option("--force", is_flag=True, help=help)


def seed_option(help: str | None = None):
    """``--seed N`` (default 0): seeds starts, initial curves or weights, or an excitation."""
    return click.option("--seed", type=int, default=0, show_default=True, help=help)


MAP_HELP = ("Take chart signal NAME from CSV column COLUMN, or from a column expression: a header times or divided "
            "by constants, e.g. w1=speed_rpm*2*pi/60 (repeatable).")


def _check_map(ctx, param, value):
    """Option syntax first (exit 2): NAME=COLUMN items, no name mapped twice."""
    from ..data.csvdata import parse_mapping

    try:
        parse_mapping(value)
    except SdnnError as exc:
        message = exc.diagnostics[0].message
        raise click.BadParameter(message.removeprefix("--map "), ctx=ctx, param=param) from None
    return value


def map_option(help: str = MAP_HELP):
    """``--map NAME=COLUMN`` (repeatable), passed on as ``mapping``; see data.csvdata.parse_mapping."""
    return click.option("--map", "mapping", multiple=True, metavar="NAME=COLUMN", help=help, callback=_check_map)


def _check_units(ctx, param, value):
    from ..analysis.dataunits import parse_unit_items

    try:
        parse_unit_items(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None
    return value


def unit_option():
    """``--unit COLUMN=UNIT`` (repeatable): convert a logged column to the chart's unit; see analysis.dataunits."""
    return click.option("--unit", "units", multiple=True, metavar="COLUMN=UNIT", callback=_check_units,
                        help="Column COLUMN is logged in UNIT (rpm, mm, ms, deg, ...): convert it to the chart's "
                             "unit of the signal it feeds (repeatable).")


def data_options(func):
    """``--map`` and ``--unit`` together: how a command reads the columns of its CSV files."""
    return map_option()(unit_option()(func))


def column_reading(diagram, mapping, units) -> tuple[dict[str, str], dict[str, float]]:
    """The parsed ``--map`` and the factor per signal of ``--unit`` against `diagram` (a usage error naming
    --unit when a unit does not fit the chart)."""
    from ..analysis.dataunits import parse_unit_items, unit_scales
    from ..data.csvdata import parse_mapping

    maps = parse_mapping(mapping)
    try:
        return maps, unit_scales(diagram, parse_unit_items(units), maps)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="'--unit'") from None



_DELIMITER_CHOICES = {"auto": "auto", ",": ",", ";": ";", "tab": "\t", "|": "|"}


def timebase_options(func):
    """``--delimiter``, ``--decimal`` and ``--resample``: how a command reads its CSV files' dialect and time
    base (see data.timebase and docs/data_and_time.md)."""
    func = click.option("--resample", is_flag=True,
                        help="Resample records logged at another rate than the chart's sample time to it "
                             "(scipy.signal.resample_poly; a note says so). Without it such a record is refused.")(func)
    func = click.option("--decimal", type=click.Choice([".", ",", "auto"]), default="auto", show_default=True,
                        help="Decimal mark of the CSV files; auto: a comma where the delimiter is not one and the "
                             "first data row is written so (a note says so).")(func)
    return click.option("--delimiter", type=click.Choice(list(_DELIMITER_CHOICES)), default="auto",
                        show_default=True,
                        help="Field delimiter of the CSV files; auto: the one that splits the header into the most "
                             "fields (a note says when it is not ',').")(func)


def read_records(paths, diagram, maps, scales, delimiter: str, decimal: str, resample: bool,
                 window: bool = True) -> list:
    """The records of the CSV files `paths` on the chart's time base (data.timebase.conform: jitter snapped,
    gaps split, with --resample another rate resampled), each cut to --rows first when `window`."""
    from ..data.csvdata import read_csv
    from ..data.timebase import conform
    from ..identify import required_columns

    cols = required_columns(diagram)
    out = []
    for path in paths:
        with settings_usage():  # a decimal comma with a comma delimiter: a usage error naming the options
            data = read_csv(path, cols, maps, None, scale=scales, delimiter=_DELIMITER_CHOICES[delimiter],
                            decimal=decimal, check_steps=False)
        out += conform(windowed(data) if window else data, diagram.sample_time, resample)
    return out


def _parse_rows(ctx, param, value):
    """``FROM:TO`` -> a slice of data rows (0-based, TO excluded, either end may be left out), kept in the
    context for :func:`windowed`; a malformed value is a usage error."""
    if value is None:
        ctx.meta["rows"] = None
        return None
    parts = value.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, stop = (int(s) if s.strip() else None for s in parts)
    except ValueError:
        raise click.BadParameter(f"{value!r} is not FROM:TO (data row numbers, e.g. 1000:31000 or 5000:)",
                                 ctx=ctx, param=param) from None
    if (start is not None and start < 0) or (stop is not None and stop < 0) or \
            (start is not None and stop is not None and stop - start < 3):
        raise click.BadParameter(f"{value!r}: rows count from 0 and the window needs at least 3 rows",
                                 ctx=ctx, param=param)
    ctx.meta["rows"] = slice(start, stop)
    return None


def rows_option(which: str = "every record"):
    """``--rows FROM:TO``: use only data rows FROM..TO-1 of `which` (see :func:`windowed`)."""
    return click.option("--rows", metavar="FROM:TO", callback=_parse_rows, expose_value=False, is_eager=False,
                        help=f"Use only data rows FROM to TO-1 of {which} (0-based; either end may be left out, "
                             "e.g. 5000:).")


def windowed(data):
    """`data` (a Dataset) cut to the command line's ``--rows`` window; unchanged without it. A window that
    leaves fewer than 3 rows of the file is an error naming the file."""
    rows = click.get_current_context().meta.get("rows")
    if rows is None:
        return data
    part = data.slice(rows.start, rows.stop)
    if part.n_rows < 3:
        raise SdnnError.at("DATA005", f"--rows {rows.start or ''}:{rows.stop or ''} leaves {part.n_rows} of the "
                           f"file's {data.n_rows} rows (at least 3 are needed)", data.path)
    return part

def alignment_option(help: str | None = ALIGNMENT_HELP, default: str | None = "zoh"):
    """``--alignment zoh|direct`` (default zoh; None: the command chooses, e.g. the fit's); see network.alignment."""
    return click.option("--alignment", type=click.Choice(["zoh", "direct"]), default=default,
                        show_default=default is not None, help=help)


class _Substeps(click.ParamType):
    """A whole number of network steps per sample (1 to MAX_SUBSTEPS), or ``auto``."""

    name = "N|auto"

    def convert(self, value, param, ctx):
        from ..diagram.model import MAX_SUBSTEPS

        if isinstance(value, int) or value == "auto":
            return value
        text = str(value).strip().lower()
        if text == "auto":
            return "auto"
        if text.isdigit() and 1 <= int(text) <= MAX_SUBSTEPS:
            return int(text)
        self.fail(f"{value!r} is not a whole number from 1 to {MAX_SUBSTEPS} or 'auto'", param, ctx)


def _shooting(value: str):
    """--shooting: 'off', 'auto' or a whole number of samples >= 2 (a bad value exits 2 with one line)."""
    if value in ("off", "auto"):
        return value
    try:
        length = int(value)
    except ValueError:
        length = 0
    if length < 2:
        raise click.BadParameter(f"expected 'off', 'auto' or a segment length of at least 2 samples, got {value!r}")
    return length


def shooting_option(what: str = "the fit", default: str = "auto"):
    """``--shooting off|auto|L`` (identify, diagnose, batch): multiple shooting for `what`; identify and batch
    default to auto, diagnose to off (its benches and acceptance were measured single shooting)."""
    return click.option(
        "--shooting", default=default, show_default=True, callback=lambda ctx, param, v: _shooting(v),
        help=f"Multiple shooting for {what}: 'off'; L: the records cut into segments of L samples, merged "
             f"x{rules.value('segment_growth')} per stage up to single shooting over whole records; 'auto': L, "
             "or off, from how fast a moved start grows along the records.")


def substeps_option():
    """``--substeps N|auto``: network steps per data sample, overriding the chart's `substeps` (default: the
    chart's; a chart without it gets auto; 1 is the paper's network)."""
    return click.option("--substeps", type=_Substeps(), default=None,
                        help="network steps per sample, N or auto (overrides the chart's 'substeps'; "
                             "without either: auto; 1 is the paper's network)")


def with_substeps(diagram, substeps):
    """The chart with the command line's --substeps applied (unchanged when not given)."""
    if substeps is None:
        return diagram
    from dataclasses import replace

    return replace(diagram, substeps=substeps)


def _check_intersample(ctx, param, value):
    out = {}
    for item in value:
        name, equals, mode = (part.strip() for part in str(item).partition("="))
        if not equals or not name or mode not in ("hold", "linear"):
            raise click.BadParameter(f"{item!r} is not NAME=hold or NAME=linear", ctx=ctx, param=param)
        out[name] = mode
    return out


def intersample_option():
    """``--intersample NAME=linear`` (repeatable): what chart input NAME does between its samples, overriding the
    chart's `intersample` (see network.inputsignal)."""
    return click.option("--intersample", "intersample", multiple=True, metavar="NAME=hold|linear",
                        callback=_check_intersample,
                        help="Chart input NAME between its samples: hold (each sample acts until the next: a held "
                             "command, the default) or linear (straight between the samples: a smooth measured "
                             "signal); overrides the chart's inputs.NAME.intersample (repeatable).")


def with_intersample(diagram, intersample: Mapping[str, str]):
    """The chart with the command line's --intersample applied (a usage error naming an unknown input)."""
    if not intersample:
        return diagram
    from dataclasses import replace

    from ..errors import did_you_mean

    names = [s.name for s in diagram.inputs]
    for name in intersample:
        if name not in names:
            hint = did_you_mean(name, names)
            raise click.BadParameter(f"'{name}' is not an input of the chart (inputs: {', '.join(names)})"
                                     + (f"; {hint}" if hint else ""), param_hint="'--intersample'")
    inputs = tuple(replace(s, intersample=intersample.get(s.name, s.intersample)) for s in diagram.inputs)
    return replace(diagram, inputs=inputs)


def html_option():
    """``--html REPORT.html``: the run as one self-contained page (figures embedded; needs matplotlib)."""
    return click.option("--html", "html_path", type=click.Path(dir_okay=False),
                        help="Write the run as one self-contained HTML page: tables and figures embedded "
                             "(needs matplotlib: pip install flowchart2sdnn[plots]).")


def require_figures(plots, html_path) -> None:
    """Check matplotlib before any work when figures or a page are asked for (PLOT001 naming the option)."""
    if plots or html_path:
        from ..report.canvas import require_matplotlib

        require_matplotlib("--plots" if plots else "--html")


def max_iter_option(help: str | None = None, default: int | None = None):
    """``--max-iter N``: Levenberg-Marquardt iterations (a safety limit where fits stop on convergence); by default
    the rule book's ``fit_max_iter``, identify's and diagnose's."""
    return click.option("--max-iter", type=click.IntRange(min=0),
                        default=rules.value("fit_max_iter") if default is None else default,
                        show_default=True, help=help)


def executor_options(work: str):
    """`--workers N` and `--scheduler ADDRESS` (see flowchart2sdnn.executors.make_executor), worded for `work`."""

    def decorate(func):
        func = click.option("--scheduler", metavar="ADDRESS",
                            help=f"Run {work} on a Dask cluster (tcp://host:8786, or 'local').")(func)
        return click.option("--workers", type=click.IntRange(min=1),
                            help=f"Run {work} in N local worker processes.")(func)

    return decorate


def command_line() -> str:
    """The command line of this run, quoted for a shell: what a page prints so that the run can be repeated."""
    import shlex

    return shlex.join(["sdnn", *sys.argv[1:]])


def lags_option():
    """``--lags N``: the residual analysis's lags on the page and in --plots. The value goes to the context's
    meta (read with :func:`lags_given`), not to the command's parameters: a view's setting, kept out of the
    fitting's argument list."""
    def keep(ctx, param, value):
        ctx.meta["lags"] = value
        return value

    return click.option("--lags", type=click.IntRange(min=1), default=None, metavar="N", expose_value=False,
                        callback=keep, help="Lags of the residual correlation figures (--html, --plots); default: "
                                            "spanning the slowest mode of the linearised chart, at least 25.")


def lags_given() -> int | None:
    return click.get_current_context().meta.get("lags")

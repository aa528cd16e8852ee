"""`sdnn compare`: measured against model output on records, as a table and a figure (MATLAB's `compare`).

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

import json

import click

from ..strictjson import strict_json
from .help import SectionedCommand
from .options import (
    alignment_option,
    column_reading,
    data_options,
    force_option,
    handle_errors,
    rows_option,
    windowed,
)
from .order import MODEL_SUFFIXES, chart_first

__all__ = ["compare"]


@click.command(name="compare", cls=SectionedCommand, sections={"Comparison": ("horizon",)},
               short_help="Measured against model output: fit % and RMS per record.")
@click.argument("model", type=click.Path(dir_okay=False))
@click.argument("data", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--horizon", type=click.IntRange(min=1),
              help="k-step-ahead prediction: restart from the measured outputs every K samples (default: "
                   "free run).")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Write the figure (PNG; needs matplotlib: pip install flowchart2sdnn[plots]).")
@click.option("--diagram", "chart", type=click.Path(dir_okay=False),
              help="With a RESULT.json: put its values into this chart instead of the identified chart beside it.")
@alignment_option("Input alignment (default: the fit's with a RESULT.json, else zoh).", default=None)
@data_options
@rows_option()
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@force_option("Overwrite an existing figure.")
@handle_errors
def compare(model, data, horizon, output, chart, alignment, mapping, units, fmt, force) -> None:
    """Compare MODEL (a chart, or a RESULT.json with its identified chart) with the measured outputs of DATA
    (CSV records): fit % and RMS per record and output."""
    from pathlib import Path

    from ..atomic import check_output_path
    from ..compiler import compile_diagram
    from ..data.csvdata import read_csv
    from ..identify import compare_records, read_model, required_columns
    from ..network.runtime import CompiledNetwork
    from ..tables import table

    model, data = chart_first("sdnn compare MODEL DATA...", model, data, MODEL_SUFFIXES)
    if output:
        from ..report.canvas import require_matplotlib

        require_matplotlib()
        check_output_path(output, [model, *data] + ([chart] if chart else []), force=force)
    diagram, result = read_model(model, chart)
    alignment = alignment or (result.settings.alignment if result is not None else "zoh")
    maps, scales = column_reading(diagram, mapping, units)
    records = [(Path(d).name, windowed(read_csv(d, required_columns(diagram), maps, diagram.sample_time,
                                                 scale=scales)), 0) for d in data]
    compiled = CompiledNetwork(compile_diagram(diagram).network)
    comparison = compare_records(compiled, compiled.theta0(), records, alignment, horizon, diagram)
    if output:
        from ..report.figures import write_compare

        write_compare(comparison, output, diagram.name)
    rows = comparison.table()
    if fmt == "json":
        click.echo(json.dumps(strict_json({"model": model, "horizon": horizon, "alignment": alignment,
                                           "records": rows}), indent=1))
        if output:
            click.echo(f"wrote {output}", err=True)  # stderr: stdout stays the JSON
    else:
        what = "free run" if horizon is None else f"{horizon}-step-ahead prediction"
        click.echo(f"{diagram.name}, {what}:")
        click.echo(table(["record", "output", "fit %", "RMS", "max |error|", "unit", "rows"],
                         [[r["record"], r["output"], r["fit_percent"], r["rms"], r["max_error"], r["unit"] or "",
                           r["rows"]] for r in rows]), nl=False)
        if output:
            click.echo(f"wrote {output}")

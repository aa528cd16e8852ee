"""One argument order for every command: the chart (or model) first, then the data.

``sdnn lint CHART``, ``sdnn simulate CHART DATA``, ``sdnn identify CHART DATA...``, ``sdnn batch CHART DATA...``,
``sdnn compare MODEL DATA...``. Two older spellings still work, with a note on stderr saying how to write them:
``identify DATA... --diagram CHART`` (identify and diagnose before the order was one), and the chart written
after the data (``simulate run.csv chart.yaml``), recognised by its file name: a chart is YAML, a data record is
not.

Layer: cli (the rule is in the package docstring).
"""

from __future__ import annotations

from pathlib import Path

import click

__all__ = ["CHART_SUFFIXES", "MODEL_SUFFIXES", "chart_first", "chart_and_data"]

#: what a chart file is called (a RESULT.json is a model too, for compare and linearize)
CHART_SUFFIXES = (".yaml", ".yml")
MODEL_SUFFIXES = (*CHART_SUFFIXES, ".json")


def _note(text: str) -> None:
    click.echo(f"note: {text}", err=True)


def _is(path: str, suffixes: tuple[str, ...]) -> bool:
    return Path(path).suffix.lower() in suffixes


def chart_first(usage: str, chart: str, data: tuple[str, ...],
                suffixes: tuple[str, ...] = CHART_SUFFIXES) -> tuple[str, tuple[str, ...]]:
    """`chart` and `data` as written, or, when the chart was written among the data (the first argument is no
    chart, exactly one of the data is), the two put back in order with a note naming the order `usage`
    (``"sdnn simulate CHART DATA"``)."""
    if _is(chart, suffixes):
        return chart, data
    charts = [d for d in data if _is(d, suffixes)]
    if len(charts) != 1:
        return chart, data  # nothing to recognise: the command reads them as given and says what is wrong
    _note(f"'{charts[0]}' read as the chart: the chart comes first ({usage})")
    return charts[0], tuple(p for p in (chart, *data) if p != charts[0])


def chart_and_data(command: str, paths: tuple[str, ...], diagram: str | None) -> tuple[str, tuple[str, ...]]:
    """The chart and the data records of ``sdnn COMMAND CHART DATA...``, also from the old
    ``sdnn COMMAND DATA... --diagram CHART`` (with a note: that order will go)."""
    usage = f"sdnn {command} CHART DATA..."
    if diagram is not None:
        if paths and _is(paths[0], CHART_SUFFIXES):
            raise click.UsageError(f"two charts: '{paths[0]}' and --diagram '{diagram}'; write '{usage}'")
        _note(f"'sdnn {command} DATA... --diagram CHART' is the old argument order and will go: "
              f"write '{usage}'")
        return diagram, paths
    if len(paths) < 2:
        raise click.UsageError(f"expected the chart and at least one data record: '{usage}'")
    return chart_first(usage, paths[0], paths[1:])

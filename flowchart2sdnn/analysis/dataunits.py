"""Units of logged columns: ``--unit speed_rpm=rpm`` converts a column to the chart's unit of its signal.

A column logged in another unit than the chart declares (speed in rpm where the chart says rad/s, a position
in mm where it says m, time in ms) is multiplied on reading by the ratio of the two units' scales; the units
must have the same dimension. The column is named as in the file (a header a ``--map`` reads, plainly or in a
column expression) or by the chart signal it feeds; ``time`` is in seconds. Unknown units, columns that feed
no chart signal, signals whose unit the chart does not declare and dimensions that do not match are a
ValueError naming the item.

Layer 3 (analysis): the chart's units (:mod:`flowchart2sdnn.diagram.units`) meet the data's columns.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ..data.columns import source_header
from ..diagram.model import Diagram
from ..diagram.units import UnitError, parse_unit

__all__ = ["parse_unit_items", "chart_signal_units", "unit_scales"]


def parse_unit_items(items: Sequence[str]) -> dict[str, str]:
    """``["speed_rpm=rpm", "t_ms=ms"]`` -> ``{"speed_rpm": "rpm", "t_ms": "ms"}``; ValueError naming a bad item
    (no ``=``, an empty side, a unit that does not parse, a column given twice)."""
    out: dict[str, str] = {}
    for item in items:
        column, equals, unit = (part.strip() for part in str(item).partition("="))
        if not equals or not column or not unit:
            raise ValueError(f"{str(item)!r} is not COLUMN=UNIT (e.g. speed_rpm=rpm)")
        try:
            parse_unit(unit)
        except UnitError as exc:
            raise ValueError(f"{column}={unit}: {exc}") from None
        if out.get(column, unit) != unit:
            raise ValueError(f"column '{column}' is given two units: {out[column]} and {unit}")
        out[column] = unit
    return out


def chart_signal_units(diagram: Diagram) -> dict[str, str | None]:
    """The unit of every measured signal (declared under inputs/outputs, else on its block) and of time."""
    blocks = {b.name: b.unit for b in diagram.blocks}
    units = {s.name: s.unit or blocks.get(s.name) for s in (*diagram.inputs, *diagram.outputs)}
    return {**units, "time": "s"}


def unit_scales(diagram: Diagram, units: Mapping[str, str], mapping: Mapping[str, str] | None = None
                ) -> dict[str, float]:
    """The factor per chart signal (or ``time``) that converts the logged columns of `units` to the chart's units.

    Parameters
    ----------
    diagram : Diagram
        The chart; its declared units are the targets.
    units : mapping of str to str
        Column (a header, or a chart signal's name) -> the unit it is logged in (``{"speed_rpm": "rpm"}``).
    mapping : mapping of str to str, optional
        The ``--map`` items (chart name -> header or column expression): they say which signal a header feeds.

    Returns
    -------
    dict of str to float
        Chart signal name -> factor (``rpm`` to ``rad/s``: 2*pi/60), for :func:`~flowchart2sdnn.data.csvdata.read_csv`'s
        ``scale``.

    Raises
    ------
    ValueError
        Naming the item, for an unknown unit, a column that feeds no chart signal, a signal scaled twice (a
        column expression and a unit), a signal without a declared unit, or units of different dimensions.
    """
    mapping = dict(mapping or {})
    targets = chart_signal_units(diagram)
    feeds: dict[str, str] = {}
    for name, text in mapping.items():
        feeds[text] = name
        feeds.setdefault(source_header(text), name)
    scales: dict[str, float] = {}
    for column, text in parse_unit_items([f"{c}={u}" for c, u in units.items()]).items():
        name = feeds.get(column) or (column if column in targets and column not in mapping else None)
        if name is None or name not in targets:
            needed = ", ".join(n for n in targets if n != "time")
            raise ValueError(f"{column}={text}: column '{column}' feeds no signal of chart '{diagram.name}' "
                             f"(its signals: {needed}, time; map a column of another name with "
                             f"--map NAME={column})")
        if name in mapping and mapping[name] != column and source_header(mapping[name]) == column:
            raise ValueError(f"{column}={text}: '{name}' is already scaled by the column expression "
                             f"{mapping[name]!r}; give either the unit or the expression")
        if name in scales:
            raise ValueError(f"{column}={text}: '{name}' is given a unit twice")
        target = targets[name]
        if not target:
            raise ValueError(f"{column}={text}: chart '{diagram.name}' declares no unit for '{name}' "
                             f"(declare one under inputs/outputs, or scale with --map {name}={column}*FACTOR)")
        logged, wanted = parse_unit(text), _chart_unit(target, name)
        if not logged.same_dimension(wanted):
            raise ValueError(f"{column}={text}: {text} [{logged}] cannot be converted to {target} [{wanted}], the "
                             f"chart's unit of '{name}' (expected a unit of the same dimension)")
        scales[name] = logged.scale / wanted.scale
    return scales


def _chart_unit(text: str, name: str):
    try:
        return parse_unit(text)
    except UnitError as exc:
        raise ValueError(f"the chart's unit of '{name}', {text!r}, does not parse: {exc}") from None

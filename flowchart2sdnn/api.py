"""The public Python API: the few calls a script needs, re-exported by ``flowchart2sdnn``.

>>> import flowchart2sdnn as sd
>>> chart = sd.load_chart("diagrams/engine.yaml")
>>> data = sd.read_csv("examples/data/engine_idle.csv")
>>> result = sd.identify(chart, data, max_iter=50)
>>> result.parameters["J1"].value, result.parameters["J1"].ci95

Every function raises :class:`~flowchart2sdnn.errors.SdnnError` for bad input (its message names the file,
the place and what was expected) and ValueError naming the setting for a bad setting.

Layer: the top of the library (everything else lies below it; only the command line is above).
"""

from __future__ import annotations

import csv
import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from .compiler import Compilation, compile_diagram
from .data.columns import source_header
from .data.csvdata import TIME_COLUMNS, Dataset
from .data.csvdata import read_csv as _read_csv_columns
from .diagnose.document import read_report
from .diagnose.loop import DiagnoseSettings, Diagnosis
from .diagnose.loop import diagnose as _diagnose
from .diagram.model import Diagram
from .diagram.validate import load_diagram
from .errors import Diagnostic, SdnnError, did_you_mean
from .identify import Identification, read_result
from .identify import identify as _identify

__all__ = ["load_chart", "compile_chart", "read_csv", "dataset_from_frame", "identify", "diagnose", "read_result",
           "read_report"]


def load_chart(path: str | Path) -> Diagram:
    """Read and validate a chart (YAML, format 1); SdnnError listing every problem with file:line."""
    return load_diagram(path)


def compile_chart(chart: Diagram | str | Path, seed: int = 0, substeps: int | str | None = None) -> Compilation:
    """Lint, analyse loops, discretize and emit the GDNN; ``.network`` is the compiled network.

    `substeps` (N >= 1 or "auto") overrides the chart's, as ``--substeps`` does; a chart without the key gets
    "auto", and without `delays` the torques rule (``substeps=1`` on a `delays: search` chart is the paper's
    network). ``.substeps`` says which N was used and why.
    """
    return compile_diagram(_chart(chart), seed, substeps)


def read_csv(path: str | Path, map: Mapping[str, str] | None = None, chart: Diagram | str | Path | None = None,
             sample_time: float | None = None, units: Mapping[str, str] | None = None, delimiter: str = "auto",
             decimal: str = "auto") -> Dataset:
    """A record from a CSV file: every column (or only the ones `chart` needs), checked value by value.

    Parameters
    ----------
    path : str or Path
    map : {name: header}, optional
        Read chart signal `name` from CSV column `header` (``{"time": header}`` names the time column), or from
        a column expression: a header times or divided by constants (``{"w1": "speed_rpm*2*pi/60"}``).
    chart : Diagram or path, optional
        Keep only the columns this chart needs (and check its sample time against the time column).
    sample_time : float, optional
        Expected time step in seconds: each step is checked against it here (CSV020, CSV021). Without it the
        time column is read as logged and :func:`identify` and :func:`diagnose` check it against the chart's
        sample time as the command line does (snapping jitter, splitting at gaps, each with a note in the
        record's ``notes``; see docs/data_and_time.md).
    units : {column: unit}, optional
        Columns logged in another unit than the chart's (``{"speed_rpm": "rpm", "t_ms": "ms"}``), converted to
        the chart's unit of the signal they feed; needs `chart`. ValueError naming an item that does not fit.
    delimiter, decimal : str
        ``","``, ``";"``, tab, ``"|"`` / ``"."``, ``","``; "auto" (default) reads them off the file, with a
        note when they are not ``","`` and ``"."``.
    """
    dialect = {"delimiter": delimiter, "decimal": decimal, "check_steps": sample_time is not None}
    mapping = dict(map or {})
    if chart is not None:
        diagram = _chart(chart)
        from .analysis.dataunits import unit_scales
        from .identify import required_columns

        scale = unit_scales(diagram, units or {}, mapping)
        return _read_csv_columns(path, required_columns(diagram), mapping, sample_time, scale=scale, **dialect)
    if units:
        raise ValueError("units need the chart whose units the columns are converted to (give chart=...)")
    header = _header(path, delimiter)
    mapped_from = set(mapping.values()) | {source_header(h) for h in mapping.values()}
    time_header = source_header(mapping["time"]) if "time" in mapping else \
        next((h for h in header if h.lower() in TIME_COLUMNS), None)
    names = [n for n in mapping if n != "time"]
    names += [h for h in header if h not in mapped_from and h != time_header and h not in names]
    return _read_csv_columns(path, names, mapping, sample_time, **dialect)


def dataset_from_frame(frame, time: str | None = None, inputs: Sequence[str] | None = None,
                       outputs: Sequence[str] | None = None, name: str = "<DataFrame>") -> Dataset:
    """A record from a pandas DataFrame (or any mapping of column name -> 1-D array).

    Parameters
    ----------
    frame : pandas.DataFrame or mapping
    time : str, optional
        The time column (seconds, strictly increasing).
    inputs, outputs : sequence of str, optional
        The columns to keep (default: every column but `time`).
    name : str
        How error messages and the result file name this record.
    """
    columns = [str(c) for c in (frame.columns if hasattr(frame, "columns") else frame.keys())]
    wanted = list(inputs or []) + [c for c in (outputs or []) if c not in (inputs or [])]
    if not wanted:
        wanted = [c for c in columns if c != time]
    for c in wanted + ([time] if time else []):
        if c not in columns:
            raise SdnnError.at("CSV012", f"column '{c}' is missing (columns: {', '.join(columns)})", name)
    values = {c: _column(frame, c, name) for c in wanted}
    n = len(next(iter(values.values()))) if values else 0
    if n < 3:
        raise SdnnError.at("CSV009", f"{n} rows, expected at least 3", name)
    t = step = deviation = None
    if time:
        t = _column(frame, time, name)
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0)) + 1
            raise SdnnError.at("CSV019", f"column '{time}' row {k}: time decreases or repeats a value", name)
        step = float(np.median(steps))
        deviation = float(np.max(np.abs(steps - step)) / step)
    digest = hashlib.sha256()
    for c in wanted + ([time] if time else []):
        digest.update(c.encode())
        digest.update((t if c == time else values[c]).tobytes())
    return Dataset(path=name, columns=values, time=t, n_rows=n, sample_time=step, max_step_deviation=deviation,
                   sha256=digest.hexdigest(), source_columns={c: c for c in wanted}, time_column=time)


def identify(chart: Diagram | str | Path, data: Dataset | Sequence[Dataset], validation: Dataset | None = None,
             resample: bool = False, fix_from: Identification | str | Path | None = None,
             **settings) -> Identification:
    """Identify the chart's physical parameters and learned curves from measured records (``sdnn identify``).

    Parameters
    ----------
    chart : Diagram or path
        The chart (:func:`load_chart`), or its YAML file.
    data : Dataset or sequence of Dataset
        The training record(s) (:func:`read_csv`, :func:`dataset_from_frame`), each with the chart's input and
        output columns; several are fitted together, each simulated from its own initial state. A DataFrame is
        not a record: SdnnError saying how to make one.
    validation : Dataset, optional
        A record to score the fit on (a record split at time gaps: its longest part).
    resample : bool
        Resample records of another rate onto the chart's sample time (``--resample``).
    fix_from : Identification or path of a RESULT.json, optional
        An earlier result whose matching parameters and learned curves are taken and kept fixed (the paper's
        stages, ``--fix-from``); their names become the ``fixed_from`` setting.
    **settings
        The fields of :class:`~flowchart2sdnn.identify.settings.IdentifySettings` by name: ``starts=8, seed=1,
        max_iter=300, split=0.7, online=True, alignment="zoh", shooting="auto", ...``; a bad value raises
        ValueError naming it, an unknown name TypeError.

    Returns
    -------
    Identification
        ``.parameters[name]`` an :class:`~flowchart2sdnn.identify.result.Estimate` (value, stderr, ci95, unit),
        ``.fit``, ``.status``, ``.warnings``, ``.chart`` the identified chart; ``.summary()``, ``.simulate(data)``,
        ``.compare(data)``, ``.linearize()``, ``.parameters_table()``, ``.to_json()`` (RESULT.json).

    Each record's time column is checked against the chart's sample time first, as ``sdnn identify`` does
    (:func:`~flowchart2sdnn.data.timebase.conform`: jitter snapped to the grid, a record split at its gaps, with
    `resample` data of another rate resampled; each with a note among the answer's ``.warnings``).
    """
    diagram = _chart(chart)
    if fix_from is not None:
        from .identify import fix_from_result

        diagram, fixed = fix_from_result(diagram, fix_from)
        settings.setdefault("fixed_from", tuple(fixed))
    train, val = prepared(diagram, data, validation, resample)
    return with_data_notes(_identify(diagram, train, val, **settings), [*train, *([val] if val else [])])


def diagnose(chart: Diagram | str | Path, data: Dataset | Sequence[Dataset],
             validation: Sequence[Dataset] = (), resample: bool = False, effects: Sequence[str] | None = None,
             **settings) -> Diagnosis:
    """Trace the residual of a fit of `chart` to effects the chart lacks, add them, refit, report
    (``sdnn diagnose``).

    Parameters
    ----------
    chart : Diagram or path
        The chart as written (never modified).
    data : Dataset or sequence of Dataset
        The training record(s), with the chart's input and output columns.
    validation : sequence of Dataset
        Validation records; none: the last 30 % of a single training record (``split=0.7``).
    resample : bool
        Resample records of another rate onto the chart's sample time.
    effects : sequence of str, optional
        The built-in effects to try, by name (``["friction", "dead_time"]``, or ``"friction,dead_time"`` as
        ``--effects``); default all. SdnnError naming an unknown one.
    **settings
        The fields of :class:`~flowchart2sdnn.diagnose.fitting.DiagnoseSettings` by name (``rounds=2, seed=0,
        top=5, criterion="bic", ...``).

    Returns
    -------
    Diagnosis
        ``.accepted`` the effects added, ``.rounds``, ``.candidates``, ``.before`` / ``.after`` the error of the
        chart as given and of the final chart, ``.identification`` the final fit, ``.diagram`` the augmented
        chart, ``.warnings``; ``.summary()``, ``.candidates_table()``, ``.to_json()`` (REPORT.json), ``.report``
        its body as a dict.

    The records' time columns are checked and prepared as for :func:`identify` (their notes in ``data_notes``).
    """
    from .data.timebase import conform, record_notices
    from .notices import messages

    diagram = _chart(chart)
    records = _records(diagram, data, "data")
    checked = _records(diagram, validation, "validation")
    train = [p for d in records for p in conform(d, diagram.sample_time, resample)]
    val = [p for d in checked for p in conform(d, diagram.sample_time, resample)]
    library = None
    if effects is not None:
        from .diagnose.effects import effect_library, select_effects

        names = effects.split(",") if isinstance(effects, str) else list(effects)  # "friction,damping" as --effects
        library = select_effects(names, effect_library(), "effects")
    out = _diagnose(diagram, train, tuple(val), DiagnoseSettings(**settings), library)
    notes = record_notices([*train, *val])
    return replace(out, data_notes=messages(notes), data_notices=tuple(notes)) if notes else out


def prepared(diagram: Diagram, data: Dataset | Sequence[Dataset], validation: Dataset | None,
             resample: bool = False) -> tuple[list[Dataset], Dataset | None]:
    """The training records and the validation record on the chart's time base (data.timebase.conform); a
    validation record split at gaps is its longest part (said in its notes). SdnnError for data that are not
    records or lack a column the chart needs."""
    from .data.timebase import conform, longest

    records = _records(diagram, data, "data")
    if validation is not None:
        validation = _records(diagram, validation, "validation")[0]
    train = [p for d in records for p in conform(d, diagram.sample_time, resample)]
    val = None if validation is None else longest(conform(validation, diagram.sample_time, resample))
    return train, val


def _records(diagram: Diagram, data, what: str) -> list[Dataset]:
    """`data` (a record or a sequence of records) as a list, each checked: a record (not a DataFrame, a mapping
    or a path) holding every column the chart reads."""
    from .identify import required_columns

    items = [data] if isinstance(data, Dataset) or _not_a_sequence(data) else list(data)
    needed = required_columns(diagram)
    for item in items:
        if not isinstance(item, Dataset):
            raise SdnnError(_not_a_record(item, what))
        missing = [c for c in needed if c not in item.columns]
        if missing:
            have = ", ".join(item.columns) or "none"
            raise SdnnError.at("CSV012", f"column '{missing[0]}' is missing: chart '{diagram.name}' reads "
                               f"{', '.join(needed)} (columns: {have})", item.path,
                               hint=did_you_mean(missing[0], item.columns)
                               or "rename with read_csv(..., map={name: header})")
    return items


def _not_a_sequence(data) -> bool:
    # a DataFrame or a mapping iterates over its column names, a path over its characters: each one thing
    return isinstance(data, (str, Path, Mapping)) or hasattr(data, "columns") or not hasattr(data, "__iter__")


def _not_a_record(item, what: str) -> Diagnostic:
    columns = [str(c) for c in item.columns] if hasattr(item, "columns") else \
        [str(c) for c in item] if isinstance(item, Mapping) else []
    listed = f" (columns: {', '.join(columns)})" if columns else ""
    if columns:
        hint = "make one with sd.dataset_from_frame(frame, time=..., inputs=[...], outputs=[...])"
    elif isinstance(item, (str, Path)):
        hint = "read the file with sd.read_csv(path)"
    else:
        hint = "make one with sd.read_csv(path) or sd.dataset_from_frame(frame, time=...)"
    return Diagnostic("API001", "error", f"{what}: a {type(item).__name__} is not a record (Dataset){listed}",
                      hint=hint)


def with_data_notes(ident: Identification, records: Sequence[Dataset]) -> Identification:
    """`ident` with the records' data notes (time base, delimiter) before its own warnings, and after them the
    warning of a residual that follows a held input at lag 0 (identify.assess.lagzero)."""
    from .data.timebase import record_notices
    from .identify import lag_zero_warnings
    from .notices import messages

    notes = record_notices(records)
    # the fit's own point: with per-record quantities ident.x holds their mean, the optimizer's result all of them
    point = getattr(ident.lm, "x", None) if ident.lm is not None else ident.x
    lag = lag_zero_warnings(ident.problem, point) if ident.problem is not None and point is not None else []
    if not notes and not lag:
        return ident
    notices = (*notes, *ident.notices, *lag)
    return replace(ident, warnings=messages(notices), notices=notices)


def _chart(chart: Diagram | str | Path) -> Diagram:
    return chart if isinstance(chart, Diagram) else load_diagram(chart)


def _column(frame, column: str, name: str) -> np.ndarray:
    raw = frame[column]
    raw = raw.to_numpy() if hasattr(raw, "to_numpy") else raw
    try:
        values = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise SdnnError.at("CSV004", f"column '{column}' is not numeric", name) from None
    if values.ndim != 1:
        raise SdnnError.at("CSV004", f"column '{column}' is not one-dimensional", name)
    bad = ~np.isfinite(values)
    if np.any(bad):
        raise SdnnError.at("CSV005", f"column '{column}' row {int(np.argmax(bad))}: NaN or infinite value", name)
    values.setflags(write=False)
    return values


def _header(path: str | Path, delimiter: str = ",") -> list[str]:
    if delimiter == "auto":
        from .data.csvdata import sniff_dialect

        try:
            delimiter = sniff_dialect(str(path), "auto", ".")[0]
        except ValueError:
            delimiter = ","
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            return [h.strip() for h in next(csv.reader(f, delimiter=delimiter), [])]
    except (OSError, UnicodeDecodeError):
        return []  # read_csv itself says what is wrong with the file

"""Measured data from CSV files: read safely, stream row by row, and explain every problem with file:line.

A data file is UTF-8 text (a BOM is accepted), comma-separated, with a header row naming the columns; CRLF
line ends and quoted fields are accepted, blank lines are skipped, header names and cells are stripped of
surrounding blanks. Only the columns a chart needs (and the time column) are kept: the file is read with the
:mod:`csv` module row by row into ``array('d')`` buffers, so files of hundreds of MB need no more memory
than the kept columns. Numbers are plain ASCII decimals (``1.5``, ``-2e-3``); NaN, infinities, empty cells,
``_`` separators and non-ASCII digits are refused.

A column is found by the chart's name, or by the header that ``mapping[name]`` names, or by a column
expression there (``speed_rpm*2*pi/60``: a header times or divided by constants, see :mod:`.columns`);
``scale[name]`` multiplies a column further (a unit conversion). Scaled values are what the Dataset holds,
and the time column is checked after its scale. The time column is
``mapping["time"]`` when given, else the first of :data:`TIME_COLUMNS` present (case-insensitive). Its steps
must be positive and lie within ``jitter_tolerance`` (relative) of the sample time, which is ``sample_time``
when given and the median step otherwise; the largest deviation seen is reported in the :class:`Dataset`.

Every problem is an :class:`~flowchart2sdnn.errors.SdnnError` whose one line names the file, the 1-based
line (the header is line 1 unless blank lines precede it), the column and what was expected, e.g.
``data.csv:17: error[CSV004] column 'w2': 'abc' is not a number (expected a decimal number)``. Errors in
the rows are reported for the first bad row. Codes:

======  ==============================================================================
code    meaning
======  ==============================================================================
CSV001  the file does not exist
CSV002  the path is not a regular file (a directory, a device, a pipe)
CSV003  the file cannot be opened or read (permissions, I/O error)
CSV004  a needed cell is not a number (text, ``1_000``, non-ASCII digits)
CSV005  a needed cell is NaN or infinite (``nan``, ``inf``, ``-inf``, ``1e999``)
CSV006  a needed cell is empty
CSV007  the file is empty (no header row)
CSV008  the file holds a header but no data rows
CSV009  fewer data rows than ``min_rows``
CSV010  a row has fewer fields than the header
CSV011  a row has more fields than the header
CSV012  a column the chart needs is missing (with did-you-mean and the headers found)
CSV013  a needed column name occurs more than once in the header
CSV014  wrong delimiter: the header is one field holding ``;``, tab, ``|`` or blanks
CSV015  not UTF-8 text: a binary file, UTF-16, or bytes of another encoding
CSV016  the mapping names a header that the file does not have
CSV017  one header would feed two names (mapped twice, or mapped onto another needed column)
CSV018  the file is larger than ``max_bytes``
CSV019  the time column decreases or repeats a value
CSV020  a time step deviates from the sample time by more than ``jitter_tolerance``
CSV021  the median time step disagrees with the given ``sample_time`` (wrong unit?)
CSV022  malformed CSV quoting (an unterminated quote, a field beyond the csv field size limit)
CSV023  no header row: the first row holds numbers
CSV024  a ``--map`` item is not ``NAME=HEADER``, or maps one name twice
CSV025  the mapping names something the chart does not need
CSV026  ``sample_time`` is not a positive finite number
CSV027  a mapping target is neither a header nor a column expression (a header times/divided by constants)
======  ==============================================================================
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping, Sequence

import numpy as np

from flowchart2sdnn.atomic import atomic_open
from flowchart2sdnn.errors import SdnnError, did_you_mean

from .csvfile import check_file, fail, first_bad_utf8, hashing_text_reader, shown, sniff_binary, sniff_dialect
from .csvrows import TIME_COLUMNS, Rows, check_time, resolve_header, scaled
from .dataset import Dataset

__all__ = ["TIME_COLUMNS", "Dataset", "read_csv", "parse_mapping", "sniff_dialect", "write_csv"]


def parse_mapping(items: Sequence[str]) -> dict[str, str]:
    """Parse ``--map`` items ``NAME=HEADER`` into ``{NAME: HEADER}``.

    Parameters
    ----------
    items : sequence of str
        E.g. ``["M1=torque_Nm", "w2=speed_rad_s"]``; blanks around either side are dropped and the header
        is everything after the first ``=``.

    Raises
    ------
    SdnnError
        CSV024 when an item has no ``=``, an empty side, or maps a name already mapped to another header.
    """
    result: dict[str, str] = {}
    for item in items:
        name, equals, header = (part.strip() for part in str(item).partition("="))
        if not equals or not name or not header:
            raise SdnnError.at(
                "CSV024", f"--map {shown(str(item))} is not NAME=HEADER", hint="e.g. --map M1=torque_Nm"
            )
        if result.get(name, header) != header:
            raise SdnnError.at(
                "CSV024", f"--map maps '{name}' twice: to '{result[name]}' and to '{header}'"
            )
        result[name] = header
    return result


def _positive(value: object) -> bool:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    return math.isfinite(number) and number > 0


def _check_options(
    file: str, required: Sequence[str], mapping: Mapping[str, str], sample_time: float | None,
    min_rows: int, jitter_tolerance: float,
) -> None:
    if any(not isinstance(name, str) or not name for name in required):
        raise ValueError(f"required column names must be non-empty strings, got {list(required)!r}")
    if min_rows < 1 or not 0 <= jitter_tolerance < 1:
        raise ValueError(f"need min_rows >= 1 and 0 <= jitter_tolerance < 1, got {min_rows}, {jitter_tolerance}")
    if sample_time is not None and not _positive(sample_time):
        raise fail("CSV026", f"sample time {sample_time!r} is not a positive number (expected seconds > 0)", file)
    known = [*required, "time"]
    for name in mapping:
        if name not in known:
            raise fail("CSV025", f"the mapping names '{name}', which the chart does not need "
                        f"(needed: {', '.join(repr(n) for n in required)})", file, hint=did_you_mean(name, known))


def read_csv(
    path: str | os.PathLike,
    required: Sequence[str],
    mapping: Mapping[str, str] | None = None,
    sample_time: float | None = None,
    min_rows: int = 3,
    max_bytes: int = 2_000_000_000,
    jitter_tolerance: float = 0.01,
    scale: Mapping[str, float] | None = None,
    delimiter: str = ",",
    decimal: str = ".",
    check_steps: bool = True,
) -> Dataset:
    """Read the columns a chart needs from a CSV file, checking everything a user could get wrong.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file (UTF-8, comma-separated, header row).
    required : sequence of str
        The chart's names of the columns to keep.
    mapping : mapping of str to str, optional
        ``mapping[name] = header`` reads ``name`` from another header; ``mapping["time"]`` names the time
        column explicitly (see :func:`parse_mapping`). A target that is not a header of the file and holds an
        operator is a column expression: ``{"w1": "speed_rpm*2*pi/60"}`` (see :mod:`.columns`).
    sample_time : float, optional
        Expected time step in seconds; each step of the time column must lie within ``jitter_tolerance``
        of it. Without it the steps are checked against their median.
    min_rows : int
        Minimum number of data rows.
    max_bytes : int
        Larger files are refused before reading.
    jitter_tolerance : float
        Allowed relative deviation of each time step (0.01 = 1 %).
    scale : mapping of str to float, optional
        ``scale[name]`` multiplies the column read for ``name`` (or the time column, ``"time"``), e.g. a unit
        conversion (see :func:`flowchart2sdnn.analysis.dataunits.unit_scales`).
    delimiter : str
        The field separator: ``","``, ``";"``, a tab or ``"|"``; ``"auto"`` reads it off the header (the
        separator that splits it into the most fields, ``","`` on a tie) and says so in ``notes`` when it is
        not a comma.
    decimal : str
        ``"."`` or ``","`` (a decimal comma, with another delimiter); ``"auto"``: a comma where the delimiter
        is not one and the first data row holds numbers written with a comma (said in ``notes``).
    check_steps : bool
        Check the time steps against ``sample_time`` (or their median) within ``jitter_tolerance``; False
        checks only that time increases (:func:`flowchart2sdnn.data.timebase.conform` does the rest).

    Returns
    -------
    Dataset

    Raises
    ------
    SdnnError
        With one of the codes CSV001-CSV026 of the module's table; the message names file, line, column.
    """
    file = os.fspath(path)
    required = list(dict.fromkeys(required))
    mapping = dict(mapping or {})
    _check_options(file, required, mapping, sample_time, min_rows, jitter_tolerance)
    scale = dict(scale or {})
    for name, factor in scale.items():
        if name not in required and name != "time":
            raise ValueError(f"scale names '{name}', which is not read (read: {', '.join(required)}, time)")
        if not (isinstance(factor, (int, float)) and math.isfinite(factor) and factor != 0):
            raise ValueError(f"scale of '{name}' must be a finite non-zero number, not {factor!r}")
    factors: dict[str, float] = {}
    sample_time = None if sample_time is None else float(sample_time)
    if check_file(file, max_bytes) == 0:
        raise fail("CSV007", "the file is empty (expected a header row naming the columns)", file)
    sniff_binary(file)
    delimiter, decimal, notes = sniff_dialect(file, delimiter, decimal)
    try:
        with hashing_text_reader(file) as (text, digest):
            reader = csv.reader(text, strict=True, delimiter=delimiter)
            header, line = None, 0
            for record in reader:
                start, line = line + 1, reader.line_num
                if record and (len(record) > 1 or record[0].strip()):
                    header = [name.strip() for name in record]
                    break
            if header is None:
                raise fail("CSV007", "the file holds no header row (expected column names)", file)
            index, time_field, sources = resolve_header(file, header, start, required, mapping, factors,
                                                  delimiter)
            fields = {*index.values(), *([time_field] if time_field is not None else [])}
            rows = Rows(file, header, list(fields), start + 1, decimal)
            rows.read(reader, line)
            sha256 = digest()
    except csv.Error as exc:  # in the header: rows.read reports its own
        raise fail("CSV022", f"malformed CSV: {exc} (expected properly quoted fields)", file, line + 1) from None
    except UnicodeDecodeError:
        bad_line, byte = first_bad_utf8(file)
        raise fail("CSV015", f"byte 0x{byte:02x} is not UTF-8 (expected UTF-8 text)", file, bad_line,
                    hint="save the file as UTF-8 CSV") from None
    except OSError as exc:
        raise fail("CSV003", f"cannot read the file: {exc.strerror or exc}", file) from None
    error = rows.nonfinite()
    if error is not None:
        raise error
    if rows.n == 0:
        raise fail("CSV008", "the file holds a header but no data rows", file, start)
    if rows.n < min_rows:
        raise fail("CSV009", f"{rows.n} data row{'s' if rows.n != 1 else ''}, fewer than the {min_rows} needed",
                    file)
    arrays = rows.arrays()
    for name, factor in scale.items():
        factors[name] = factors.get(name, 1.0) * float(factor)
    columns = {name: arrays[field] for name, field in index.items()}
    time = arrays[time_field] if time_field is not None else None
    for name, factor in factors.items():
        if name == "time" and name not in index:
            time = scaled(rows, time, factor, time_field) if time is not None else None
        else:
            columns[name] = scaled(rows, columns[name], factor, index[name])
    deviation = None
    if time is not None and check_steps:
        sample_time, deviation = check_time(rows, time, time_field, sample_time, jitter_tolerance)
    elif time is not None:
        sample_time = float(np.median(np.diff(time))) if len(time) > 1 else sample_time
    return Dataset(
        path=file,
        columns=columns,
        time=time,
        n_rows=rows.n,
        sample_time=sample_time,
        max_step_deviation=deviation,
        sha256=sha256,
        source_columns=sources,
        scales={name: f for name, f in factors.items() if f != 1.0},
        notes=tuple(notes),
        time_column=header[time_field] if time_field is not None else None,
        lines=(tuple(rows.breaks_row), tuple(rows.breaks_line)),
    )


def write_csv(path: str | os.PathLike, columns: Mapping[str, np.ndarray], float_format: str = "%.10g") -> None:
    """Write equal-length 1-D columns as a comma-separated file with a header row, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The target; replaced only once the whole file is written (:func:`~flowchart2sdnn.atomic.atomic_open`).
    columns : mapping of str to array_like
        Header -> values, in the order given.
    float_format : str
        ``%``-format of one value; ``"%.17g"`` round-trips float64 exactly.
    """
    names = list(columns)
    values = [np.asarray(columns[name], dtype=np.float64) for name in names]
    if not names:
        raise ValueError("write_csv needs at least one column")
    if any(v.ndim != 1 for v in values) or len({len(v) for v in values}) != 1:
        raise ValueError(f"columns must be 1-D of one length, got shapes {[v.shape for v in values]}")
    block = 65536  # rows per formatting step: bounded memory for long files
    with atomic_open(path, "w", newline="") as handle:
        csv.writer(handle, lineterminator="\n").writerow(names)
        for begin in range(0, len(values[0]), block):
            chunk = np.column_stack([v[begin:begin + block] for v in values])
            np.savetxt(handle, chunk, fmt=float_format, delimiter=",")

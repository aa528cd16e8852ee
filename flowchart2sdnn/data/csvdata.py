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

import bisect
import codecs
import csv
import dataclasses
import hashlib
import io
import math
import os
import re
import stat
from array import array
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from flowchart2sdnn.atomic import atomic_open
from flowchart2sdnn.errors import SdnnError, did_you_mean
from flowchart2sdnn.expr import ExprError
from flowchart2sdnn.notices import Notice

from .columns import EXAMPLE, column_scale

__all__ = ["TIME_COLUMNS", "Dataset", "read_csv", "parse_mapping", "sniff_dialect", "write_csv"]

TIME_COLUMNS = ("time", "t", "time_s")
_OTHER_DELIMITERS = {";": "';'", "\t": "tab", "|": "'|'"}
_SHOWN_HEADERS = 20


@dataclass(frozen=True, eq=False)
class Dataset:
    """Columns read from one CSV file (arrays are float64, read-only, all of length ``n_rows``).

    Attributes
    ----------
    path : str
        The file as given.
    columns : dict of str to ndarray
        The requested names (chart names, before mapping to headers) -> values.
    time : ndarray or None
        The time column, when the file has one.
    n_rows : int
        Number of data rows.
    sample_time : float or None
        The median step of the time column; without a time column the ``sample_time`` given (or None).
    max_step_deviation : float or None
        Largest ``|step - Ts| / Ts`` seen, ``Ts`` the given sample time (else the median step); None
        without a time column or with fewer than two rows.
    sha256 : str
        Hex digest of the file's bytes.
    source_columns : dict of str to str
        Requested name -> the CSV header it came from.
    scales : dict of str to float
        Requested name (or ``"time"``) -> the factor its column was multiplied by (a column expression of the
        mapping times a ``scale``); names read as logged are absent.
    notes : tuple of Notice
        What was done to the data on the way in (a detected delimiter, snapped timestamps, a split at a gap,
        a resampling): each one line, shown with the run's output (see :mod:`.timebase`).
    time_column : str or None
        The header of the time column.
    lines : (rows, lines) or None
        Where the file's line numbering jumps (blank lines, multi-line fields): data row ``rows[i]`` is on line
        ``lines[i]``; None for records not read from a file.
    row0 : int
        The file's data row of this record's row 0 (a slice starts later).
    """

    path: str
    columns: dict[str, np.ndarray]
    time: np.ndarray | None
    n_rows: int
    sample_time: float | None
    max_step_deviation: float | None
    sha256: str
    source_columns: dict[str, str]
    scales: dict[str, float] = dataclasses.field(default_factory=dict)
    notes: tuple[Notice, ...] = ()
    time_column: str | None = None
    lines: tuple[tuple[int, ...], tuple[int, ...]] | None = None
    row0: int = 0

    def line_of(self, row: int) -> int | None:
        """The file line of this record's data row `row` (None when not read from a file)."""
        if self.lines is None:
            return None
        rows, lines = self.lines
        row += self.row0
        at = bisect.bisect_right(rows, row) - 1
        return lines[at] + row - rows[at]

    def slice(self, start: int | None, stop: int | None) -> Dataset:
        """Rows ``start:stop`` (Python slice rules) as a new Dataset sharing the read-only arrays."""
        rows = slice(start, stop)
        time = None if self.time is None else self.time[rows]
        deviation = self.max_step_deviation
        if time is not None and self.sample_time is not None:
            deviation = _max_deviation(time, self.sample_time)
        return replace(
            self,
            columns={name: values[rows] for name, values in self.columns.items()},
            time=time,
            n_rows=len(range(*rows.indices(self.n_rows))),
            max_step_deviation=deviation,
            row0=self.row0 + rows.indices(self.n_rows)[0],
        )


def _max_deviation(time: np.ndarray, step: float) -> float | None:
    if len(time) < 2:
        return None
    return float(np.max(np.abs(np.diff(time) - step)) / step)


def _fail(code: str, message: str, file: str, line: int | None = None, hint: str | None = None) -> SdnnError:
    return SdnnError.at(code, message, file=file, line=line, hint=hint)


def _shown(text: str, limit: int = 40) -> str:
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _headers_found(header: Sequence[str]) -> str:
    shown = ", ".join(repr(h) for h in header[:_SHOWN_HEADERS])
    more = f", ... ({len(header)} in all)" if len(header) > _SHOWN_HEADERS else ""
    return f"headers found: {shown}{more}"


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


class _HashingRaw(io.RawIOBase):
    """A raw binary reader that feeds every byte it passes on into a SHA-256."""

    def __init__(self, raw: io.FileIO):
        self._raw = raw
        self.sha = hashlib.sha256()

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = self._raw.readinto(buffer)
        if n:
            self.sha.update(memoryview(buffer)[:n])
        return n or 0

    def close(self) -> None:
        self._raw.close()
        super().close()


@contextmanager
def _hashing_text_reader(file: str) -> Iterator[tuple[io.TextIOWrapper, Callable[[], str]]]:
    """UTF-8 text of ``file`` for the csv module, and a function giving the digest of the bytes read so far."""
    raw = _HashingRaw(io.FileIO(file, "r"))
    text = io.TextIOWrapper(io.BufferedReader(raw, 1 << 20), encoding="utf-8-sig", newline="")
    with text:
        yield text, raw.sha.hexdigest


def _sniff_binary(file: str) -> None:
    """Refuse UTF-16/32 and binary files by their first bytes, before the csv module sees them."""
    try:
        with open(file, "rb") as handle:
            head = handle.read(1 << 16)
    except OSError as exc:
        raise _fail("CSV003", f"cannot read the file: {exc.strerror or exc}", file) from None
    for bom, name in ((codecs.BOM_UTF32_LE, "UTF-32"), (codecs.BOM_UTF32_BE, "UTF-32"),
                      (codecs.BOM_UTF16_LE, "UTF-16"), (codecs.BOM_UTF16_BE, "UTF-16")):
        if head.startswith(bom):
            raise _fail("CSV015", f"the file is {name} text (expected UTF-8)", file, 1,
                        hint="save the file as UTF-8 CSV")
    nul = head.find(b"\0")
    if nul >= 0:
        raise _fail("CSV015", "NUL byte: a binary file (expected UTF-8 text)", file, head.count(b"\n", 0, nul) + 1)


def _first_bad_utf8(file: str) -> tuple[int | None, int]:
    """The line and value of the first byte that is not UTF-8 (line None if none is found)."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    line = 1
    with open(file, "rb") as handle:
        while chunk := handle.readline(1 << 20):  # bounded even for a file without newlines
            try:
                decoder.decode(chunk)
            except UnicodeDecodeError as exc:
                return line, exc.object[exc.start]
            line += chunk.count(b"\n")
        try:
            decoder.decode(b"", final=True)
        except UnicodeDecodeError as exc:
            return line, exc.object[exc.start]
    return None, 0


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
                "CSV024", f"--map {_shown(str(item))} is not NAME=HEADER", hint="e.g. --map M1=torque_Nm"
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


def _suggest(name: str, header: Sequence[str]) -> str | None:
    """Did-you-mean over the headers: same name in another case, the name with a unit suffix, or a near miss."""
    folded = name.casefold()
    for match in (lambda h: h.casefold() == folded, lambda h: h.casefold().startswith(folded)):
        hit = next((h for h in header if match(h)), None)
        if hit is not None:
            return f"did you mean '{hit}'?"
    return did_you_mean(name, header)


def _check_options(
    file: str, required: Sequence[str], mapping: Mapping[str, str], sample_time: float | None,
    min_rows: int, jitter_tolerance: float,
) -> None:
    if any(not isinstance(name, str) or not name for name in required):
        raise ValueError(f"required column names must be non-empty strings, got {list(required)!r}")
    if min_rows < 1 or not 0 <= jitter_tolerance < 1:
        raise ValueError(f"need min_rows >= 1 and 0 <= jitter_tolerance < 1, got {min_rows}, {jitter_tolerance}")
    if sample_time is not None and not _positive(sample_time):
        raise _fail("CSV026", f"sample time {sample_time!r} is not a positive number (expected seconds > 0)", file)
    known = [*required, "time"]
    for name in mapping:
        if name not in known:
            raise _fail("CSV025", f"the mapping names '{name}', which the chart does not need "
                        f"(needed: {', '.join(repr(n) for n in required)})", file, hint=did_you_mean(name, known))


def _check_file(file: str, max_bytes: int) -> int:
    """The file's size, after checking that it is a readable regular file of allowed size."""
    try:
        info = os.stat(file)
    except FileNotFoundError:
        raise _fail("CSV001", "file not found (expected a CSV data file)", file) from None
    except OSError as exc:
        raise _fail("CSV003", f"cannot read the file: {exc.strerror or exc}", file) from None
    if stat.S_ISDIR(info.st_mode):
        raise _fail("CSV002", "is a directory (expected a CSV data file)", file)
    if not stat.S_ISREG(info.st_mode):
        raise _fail("CSV002", "is not a regular file (expected a CSV data file)", file)
    if info.st_size > max_bytes:
        raise _fail("CSV018", f"the file has {info.st_size} bytes, more than the limit of {max_bytes} "
                    "(expected a smaller file; raise max_bytes if it is right)", file)
    return info.st_size


def _is_expression(target: str) -> bool:
    """Whether a mapping target that is not a header is read as a column expression (it has an operator)."""
    return any(op in target for op in "*/^") or target.lstrip().startswith("-")


def _resolve(
    file: str, header: list[str], line: int, required: Sequence[str], mapping: Mapping[str, str],
    factors: dict[str, float], delimiter: str = ",",
) -> tuple[dict[str, int], int | None, dict[str, str]]:
    """Column index per required name, the time column's index, and the header each name reads; the factor
    of every column expression is put into `factors`."""
    if len(header) == 1 and delimiter == ",":
        found = [label for sep, label in _OTHER_DELIMITERS.items() if sep in header[0]]
        if not found and len(header[0].split()) > 1:
            found = ["blanks"]
        wanted = {mapping.get(name, name) for name in required}
        if found and wanted != {header[0]}:
            sep = next((s for s, label in _OTHER_DELIMITERS.items() if label == found[0]), None)
            hint = (f"give the delimiter (--delimiter '{sep}'), let it be detected (--delimiter auto), or "
                    "save the file with ',' as delimiter" if sep else "save the file with ',' as delimiter")
            raise _fail("CSV014", f"the header is one field {_shown(header[0])}: expected comma-separated "
                        f"columns, found {found[0]}", file, line, hint=hint)
    if all(_is_number(h) for h in header):
        raise _fail("CSV023", f"no header row: line {line} holds numbers (expected column names such as "
                    f"{', '.join(repr(n) for n in required[:3])})", file, line)
    positions: dict[str, list[int]] = {}
    for index, name in enumerate(header):
        positions.setdefault(name, []).append(index)
    targets: dict[str, str] = {}
    for name, target in mapping.items():
        targets[name], factor = target, 1.0
        if target not in positions and _is_expression(target):
            try:
                targets[name], factor = column_scale(target)
            except ExprError as exc:
                raise _fail("CSV027", f"the mapping {name}={target}: '{target}' is neither a header of the file "
                            f"nor a column expression: {exc.message} (expected a header, or a header times or "
                            f"divided by constants such as {EXAMPLE})", file, line) from None
            if factor != 1.0:
                factors[name] = factor
        if targets[name] not in positions:
            missing = targets[name]
            raise _fail("CSV016", f"the mapping {name}={target} names header '{missing}', which the file does "
                        f"not have ({_headers_found(header)})", file, line, hint=_suggest(missing, header))
    sources: dict[str, str] = {}
    users: dict[str, str] = {}
    for name in [*required, *(["time"] if "time" in mapping else [])]:
        source = targets.get(name, name)
        if source not in positions:
            hint = _suggest(source, header) or f"map it with --map {name}=HEADER"
            raise _fail("CSV012", f"column '{name}' is missing ({_headers_found(header)})", file, line, hint=hint)
        if source in users and users[source] != name:
            raise _fail("CSV017", f"header '{source}' would feed both '{users[source]}' and '{name}' "
                        "(expected one header per name)", file, line)
        users[source] = name
        sources[name] = source
    time_source = sources.pop("time", None) if "time" not in required else sources["time"]
    if time_source is None:
        folded = [h.casefold() for h in header]
        time_source = next((h for key in TIME_COLUMNS for h, f in zip(header, folded, strict=True) if f == key), None)
        if time_source is not None:
            twins = [h for h in header if h.casefold() == time_source.casefold()]
            if len(twins) > 1:
                raise _fail("CSV013", f"time column '{time_source}' occurs {len(twins)} times "
                            f"({', '.join(repr(t) for t in twins)}); expected one", file, line,
                            hint="name the time column with --map time=HEADER")
    for source in {*sources.values(), *([time_source] if time_source else [])}:
        if len(positions[source]) > 1:
            where = ", ".join(str(i + 1) for i in positions[source])
            raise _fail("CSV013", f"column '{source}' occurs {len(positions[source])} times (fields {where}); "
                        "expected one", file, line)
    index = {name: positions[source][0] for name, source in sources.items()}
    time_index = positions[time_source][0] if time_source is not None else None
    return index, time_index, sources


class _Rows:
    """Streaming state: one buffer per kept field, and the file line of every data row."""

    def __init__(self, file: str, header: list[str], fields: list[int], first_line: int, decimal: str = "."):
        self.file = file
        self.comma = decimal == ","
        self.header = header
        self.fields = sorted(fields)
        self.buffers = [array("d") for _ in self.fields]
        self.n = 0
        self.breaks_row = [0]  # rows where the line numbering jumps (blank lines, multi-line quoted fields)
        self.breaks_line = [first_line]

    def line_of(self, row: int) -> int:
        at = bisect.bisect_right(self.breaks_row, row) - 1
        return self.breaks_line[at] + row - self.breaks_row[at]

    def read(self, reader, prev_line: int) -> None:
        try:
            self._read(reader, prev_line)
        except csv.Error as exc:  # the broken record starts on the line after the last one read
            raise self.nonfinite() or _fail(
                "CSV022", f"malformed CSV: {exc} (expected properly quoted fields)", self.file, self.last_line + 1
            ) from None

    def _read(self, reader, prev_line: int) -> None:
        ncols = len(self.header)
        pairs = list(zip(self.buffers, self.fields, strict=True))
        n, base = 0, self.breaks_line[0]
        self.last_line = prev_line
        for row in reader:
            start, prev_line = prev_line + 1, reader.line_num
            self.last_line = prev_line
            if len(row) != ncols:
                if not row or (len(row) == 1 and not row[0].strip()):
                    continue
                self.n = n
                raise self.ragged(row, start)
            if start != base + n:
                self.breaks_row.append(n)
                self.breaks_line.append(start)
                base = start - n
            for buffer, field in pairs:
                cell = row[field]
                if self.comma:
                    if "." in cell:  # a thousands separator or a point: either way not this file's numbers
                        self.n = n
                        raise self.bad_cell(cell, field, start)
                    cell = cell.replace(",", ".")
                if not cell.isascii() or "_" in cell:
                    self.n = n
                    raise self.bad_cell(cell, field, start)
                try:
                    buffer.append(float(cell))
                except ValueError:
                    self.n = n
                    raise self.bad_cell(cell, field, start) from None
            n += 1
        self.n = n

    def column_name(self, field: int) -> str:
        return f"column '{self.header[field]}'"

    def nonfinite(self) -> SdnnError | None:
        """The error for the first NaN/inf kept so far, or None."""
        first: tuple[int, int, float] | None = None
        for buffer, field in zip(self.buffers, self.fields, strict=True):
            values = np.frombuffer(buffer, dtype=np.float64) if len(buffer) else np.empty(0)
            bad = np.flatnonzero(~np.isfinite(values))
            if len(bad) and (first is None or bad[0] < first[0]):
                first = (int(bad[0]), field, float(values[bad[0]]))
        if first is None:
            return None
        row, field, value = first
        return _fail("CSV005", f"{self.column_name(field)}: {value!r} is not a finite number "
                     "(expected a decimal number)", self.file, self.line_of(row))

    def ragged(self, row: list[str], line: int) -> SdnnError:
        earlier = self.nonfinite()
        if earlier is not None:
            return earlier
        code, fewer = ("CSV010", "fewer") if len(row) < len(self.header) else ("CSV011", "more")
        hint = None
        if len(row) == 1:
            hint = next((f"expected comma-separated, found {label}" for sep, label in _OTHER_DELIMITERS.items()
                         if sep in row[0]), None)
        return _fail(code, f"row has {len(row)} fields, {fewer} than the header's {len(self.header)} "
                     f"(expected {len(self.header)} comma-separated fields)", self.file, line, hint=hint)

    def bad_cell(self, cell: str, field: int, line: int) -> SdnnError:
        earlier = self.nonfinite()
        if earlier is not None:
            return earlier
        if not cell.strip():
            return _fail("CSV006", f"{self.column_name(field)}: the cell is empty (expected a decimal number)",
                         self.file, line)
        expected = "a decimal number with a decimal comma" if self.comma else "a decimal number"
        return _fail("CSV004", f"{self.column_name(field)}: {_shown(cell)} is not a number (expected {expected})",
                     self.file, line)

    def arrays(self) -> dict[int, np.ndarray]:
        out = {}
        for buffer, field in zip(self.buffers, self.fields, strict=True):
            values = np.frombuffer(buffer, dtype=np.float64) if len(buffer) else np.empty(0)
            values.flags.writeable = False
            out[field] = values
        return out


def _check_time(rows: _Rows, time: np.ndarray, field: int, sample_time: float | None,
                tolerance: float) -> tuple[float | None, float | None]:
    """Sample time (median step) and max relative deviation, after checking the steps."""
    if len(time) < 2:
        return sample_time, None
    steps = np.diff(time)
    median = float(np.median(steps))
    expected = sample_time if sample_time is not None else median
    column = rows.column_name(field)
    if expected > 0:
        deviation = np.abs(steps - expected) / expected
        bad = np.flatnonzero((steps <= 0) | (deviation > tolerance))
    else:
        deviation, bad = None, np.flatnonzero(steps <= 0)
    if len(bad) == 0:
        return median, float(np.max(deviation))
    k = int(bad[0])
    line, found = rows.line_of(k + 1), float(steps[k])
    if found <= 0:
        what = "repeats the previous time" if found == 0 else "goes back in time"
        raise _fail("CSV019", f"{column}: {what}: step {found:.6g} (expected a step of "
                    f"{expected:.6g} s, time strictly increasing)", rows.file, line)
    if sample_time is not None and abs(median - sample_time) > tolerance * sample_time:
        raise _fail("CSV021", f"{column}: step {found:.6g} (expected {sample_time:.6g} s, the sample time; "
                    f"the median step is {median:.6g})", rows.file, line,
                    hint="is the time column in another unit, or the sample time wrong?")
    raise _fail("CSV020", f"{column}: step {found:.6g} deviates {100 * float(deviation[k]):.3g} % from "
                f"{expected:.6g} (expected within {100 * tolerance:.3g} %)", rows.file, line)


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
    if _check_file(file, max_bytes) == 0:
        raise _fail("CSV007", "the file is empty (expected a header row naming the columns)", file)
    _sniff_binary(file)
    delimiter, decimal, notes = sniff_dialect(file, delimiter, decimal)
    try:
        with _hashing_text_reader(file) as (text, digest):
            reader = csv.reader(text, strict=True, delimiter=delimiter)
            header, line = None, 0
            for record in reader:
                start, line = line + 1, reader.line_num
                if record and (len(record) > 1 or record[0].strip()):
                    header = [name.strip() for name in record]
                    break
            if header is None:
                raise _fail("CSV007", "the file holds no header row (expected column names)", file)
            index, time_field, sources = _resolve(file, header, start, required, mapping, factors,
                                                  delimiter)
            fields = {*index.values(), *([time_field] if time_field is not None else [])}
            rows = _Rows(file, header, list(fields), start + 1, decimal)
            rows.read(reader, line)
            sha256 = digest()
    except csv.Error as exc:  # in the header: rows.read reports its own
        raise _fail("CSV022", f"malformed CSV: {exc} (expected properly quoted fields)", file, line + 1) from None
    except UnicodeDecodeError:
        bad_line, byte = _first_bad_utf8(file)
        raise _fail("CSV015", f"byte 0x{byte:02x} is not UTF-8 (expected UTF-8 text)", file, bad_line,
                    hint="save the file as UTF-8 CSV") from None
    except OSError as exc:
        raise _fail("CSV003", f"cannot read the file: {exc.strerror or exc}", file) from None
    error = rows.nonfinite()
    if error is not None:
        raise error
    if rows.n == 0:
        raise _fail("CSV008", "the file holds a header but no data rows", file, start)
    if rows.n < min_rows:
        raise _fail("CSV009", f"{rows.n} data row{'s' if rows.n != 1 else ''}, fewer than the {min_rows} needed",
                    file)
    arrays = rows.arrays()
    for name, factor in scale.items():
        factors[name] = factors.get(name, 1.0) * float(factor)
    columns = {name: arrays[field] for name, field in index.items()}
    time = arrays[time_field] if time_field is not None else None
    for name, factor in factors.items():
        if name == "time" and name not in index:
            time = _scaled(rows, time, factor, time_field) if time is not None else None
        else:
            columns[name] = _scaled(rows, columns[name], factor, index[name])
    deviation = None
    if time is not None and check_steps:
        sample_time, deviation = _check_time(rows, time, time_field, sample_time, jitter_tolerance)
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


_DELIMITERS = {",": "','", ";": "';'", "\t": "tab", "|": "'|'"}
_COMMA_NUMBER = re.compile(r"^\s*[-+]?\d*,\d+([eE][-+]?\d+)?\s*$")


def sniff_dialect(file: str, delimiter: str, decimal: str) -> tuple[str, str, list[Notice]]:
    """The delimiter and decimal mark to read `file` with, detected where "auto", and the notes saying so."""
    if delimiter != "auto" and delimiter not in _DELIMITERS:
        raise ValueError(f"delimiter must be one of ',', ';', tab, '|' or 'auto', not {delimiter!r}")
    if decimal not in (".", ",", "auto"):
        raise ValueError(f"decimal must be '.', ',' or 'auto', not {decimal!r}")
    if delimiter == "," and decimal == ",":
        raise ValueError("decimal ',' needs a delimiter other than ',' (e.g. delimiter ';')")
    if delimiter != "auto" and decimal != "auto":
        return delimiter, decimal, []
    head = _first_lines(file, 2)
    notes = []
    if delimiter == "auto":
        counts = {sep: len(next(csv.reader([head[0]], delimiter=sep), [])) for sep in _DELIMITERS} if head else {}
        delimiter = max(counts, key=lambda sep: (counts[sep], sep == ","), default=",")
        if delimiter != ",":
            notes.append(Notice("READ001", f"delimiter {_DELIMITERS[delimiter]} (detected from the header; "
                                "--delimiter to set it)", {"delimiter": delimiter}, "--delimiter to set it"))
    if decimal == "auto":
        cells = next(csv.reader([head[1]], delimiter=delimiter), []) if len(head) > 1 else []
        decimal = "," if delimiter != "," and any(_COMMA_NUMBER.match(c) for c in cells) else "."
        if decimal == ",":
            notes.append(Notice("READ002", "decimal comma (detected from the first data row; --decimal to set it)",
                                {"decimal": ","}, "--decimal to set it"))
    return delimiter, decimal, notes


def _first_lines(file: str, n: int) -> list[str]:
    """The first `n` non-blank lines of `file` (fewer at its end; none when it cannot be read as UTF-8: the
    reader reports that)."""
    out: list[str] = []
    try:
        with open(file, encoding="utf-8-sig", newline="") as handle:
            for line in handle:
                if line.strip():
                    out.append(line.rstrip("\r\n"))
                    if len(out) == n:
                        break
    except (OSError, UnicodeDecodeError):
        return []
    return out


def _scaled(rows: _Rows, values: np.ndarray, factor: float, field: int) -> np.ndarray:
    """`values` times `factor` (read-only), refusing a product that overflows."""
    if factor == 1.0:
        return values
    with np.errstate(over="ignore"):
        out = values * factor
    bad = np.flatnonzero(~np.isfinite(out))
    if len(bad):
        raise _fail("CSV005", f"{rows.column_name(field)}: {values[bad[0]]!r} times the scale {factor:.6g} is not "
                    "a finite number (expected a smaller value or scale)", rows.file, rows.line_of(int(bad[0])))
    out.flags.writeable = False
    return out


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

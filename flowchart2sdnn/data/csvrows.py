"""The rows of a CSV file: its header resolved to the columns a chart needs (mapping, column expressions, the
time column), the kept columns streamed row by row into buffers with the file line of every row, scaled, and
the time steps checked. The error codes are :mod:`.csvdata`'s."""

from __future__ import annotations

import bisect
import csv
from array import array
from collections.abc import Mapping, Sequence

import numpy as np

from flowchart2sdnn.errors import SdnnError, did_you_mean
from flowchart2sdnn.expr import ExprError

from .columns import EXAMPLE, column_scale
from .csvfile import fail, shown

__all__ = ["TIME_COLUMNS", "resolve_header", "Rows", "check_time", "scaled"]

TIME_COLUMNS = ("time", "t", "time_s")
_OTHER_DELIMITERS = {";": "';'", "\t": "tab", "|": "'|'"}
_SHOWN_HEADERS = 20


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


def _suggest(name: str, header: Sequence[str]) -> str | None:
    """Did-you-mean over the headers: same name in another case, the name with a unit suffix, or a near miss."""
    folded = name.casefold()
    for match in (lambda h: h.casefold() == folded, lambda h: h.casefold().startswith(folded)):
        hit = next((h for h in header if match(h)), None)
        if hit is not None:
            return f"did you mean '{hit}'?"
    return did_you_mean(name, header)


def _is_expression(target: str) -> bool:
    """Whether a mapping target that is not a header is read as a column expression (it has an operator)."""
    return any(op in target for op in "*/^") or target.lstrip().startswith("-")


def resolve_header(
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
            raise fail("CSV014", f"the header is one field {shown(header[0])}: expected comma-separated "
                        f"columns, found {found[0]}", file, line, hint=hint)
    if all(_is_number(h) for h in header):
        raise fail("CSV023", f"no header row: line {line} holds numbers (expected column names such as "
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
                raise fail("CSV027", f"the mapping {name}={target}: '{target}' is neither a header of the file "
                            f"nor a column expression: {exc.message} (expected a header, or a header times or "
                            f"divided by constants such as {EXAMPLE})", file, line) from None
            if factor != 1.0:
                factors[name] = factor
        if targets[name] not in positions:
            missing = targets[name]
            raise fail("CSV016", f"the mapping {name}={target} names header '{missing}', which the file does "
                        f"not have ({_headers_found(header)})", file, line, hint=_suggest(missing, header))
    sources: dict[str, str] = {}
    users: dict[str, str] = {}
    for name in [*required, *(["time"] if "time" in mapping else [])]:
        source = targets.get(name, name)
        if source not in positions:
            hint = _suggest(source, header) or f"map it with --map {name}=HEADER"
            raise fail("CSV012", f"column '{name}' is missing ({_headers_found(header)})", file, line, hint=hint)
        if source in users and users[source] != name:
            raise fail("CSV017", f"header '{source}' would feed both '{users[source]}' and '{name}' "
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
                raise fail("CSV013", f"time column '{time_source}' occurs {len(twins)} times "
                            f"({', '.join(repr(t) for t in twins)}); expected one", file, line,
                            hint="name the time column with --map time=HEADER")
    for source in {*sources.values(), *([time_source] if time_source else [])}:
        if len(positions[source]) > 1:
            where = ", ".join(str(i + 1) for i in positions[source])
            raise fail("CSV013", f"column '{source}' occurs {len(positions[source])} times (fields {where}); "
                        "expected one", file, line)
    index = {name: positions[source][0] for name, source in sources.items()}
    time_index = positions[time_source][0] if time_source is not None else None
    return index, time_index, sources


class Rows:
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
            raise self.nonfinite() or fail(
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
        return fail("CSV005", f"{self.column_name(field)}: {value!r} is not a finite number "
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
        return fail(code, f"row has {len(row)} fields, {fewer} than the header's {len(self.header)} "
                     f"(expected {len(self.header)} comma-separated fields)", self.file, line, hint=hint)

    def bad_cell(self, cell: str, field: int, line: int) -> SdnnError:
        earlier = self.nonfinite()
        if earlier is not None:
            return earlier
        if not cell.strip():
            return fail("CSV006", f"{self.column_name(field)}: the cell is empty (expected a decimal number)",
                         self.file, line)
        expected = "a decimal number with a decimal comma" if self.comma else "a decimal number"
        return fail("CSV004", f"{self.column_name(field)}: {shown(cell)} is not a number (expected {expected})",
                     self.file, line)

    def arrays(self) -> dict[int, np.ndarray]:
        out = {}
        for buffer, field in zip(self.buffers, self.fields, strict=True):
            values = np.frombuffer(buffer, dtype=np.float64) if len(buffer) else np.empty(0)
            values.flags.writeable = False
            out[field] = values
        return out


def check_time(rows: Rows, time: np.ndarray, field: int, sample_time: float | None,
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
        raise fail("CSV019", f"{column}: {what}: step {found:.6g} (expected a step of "
                    f"{expected:.6g} s, time strictly increasing)", rows.file, line)
    if sample_time is not None and abs(median - sample_time) > tolerance * sample_time:
        raise fail("CSV021", f"{column}: step {found:.6g} (expected {sample_time:.6g} s, the sample time; "
                    f"the median step is {median:.6g})", rows.file, line,
                    hint="is the time column in another unit, or the sample time wrong?")
    raise fail("CSV020", f"{column}: step {found:.6g} deviates {100 * float(deviation[k]):.3g} % from "
                f"{expected:.6g} (expected within {100 * tolerance:.3g} %)", rows.file, line)


def scaled(rows: Rows, values: np.ndarray, factor: float, field: int) -> np.ndarray:
    """`values` times `factor` (read-only), refusing a product that overflows."""
    if factor == 1.0:
        return values
    with np.errstate(over="ignore"):
        out = values * factor
    bad = np.flatnonzero(~np.isfinite(out))
    if len(bad):
        raise fail("CSV005", f"{rows.column_name(field)}: {values[bad[0]]!r} times the scale {factor:.6g} is not "
                    "a finite number (expected a smaller value or scale)", rows.file, rows.line_of(int(bad[0])))
    out.flags.writeable = False
    return out

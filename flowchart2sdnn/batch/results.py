"""The results table of `sdnn batch`: one row per data file, safe against a kill at any moment.

CSV (the default) is a journal: the header is written once, then each finished file is appended as one line,
flushed and fsynced. A kill can tear at most the last line; :func:`read_results` drops a line without its
newline (or with the wrong number of fields), so the file in progress is simply redone. When a run ends the
table is rewritten atomically, sorted by file name, so equal runs give equal files whatever the order in which
workers finished. Parquet (needs pyarrow) cannot be appended to; it is rewritten atomically after every file.

Numbers are written with ``repr`` (exact round trip), missing values as empty cells.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..atomic import atomic_open
from ..errors import SdnnError

__all__ = ["Columns", "columns_for", "read_results", "ResultsWriter", "parquet_available", "TEXT_COLUMNS",
           "INT_COLUMNS"]

#: Columns holding text; the others hold numbers (or nothing).
TEXT_COLUMNS = frozenset({"file", "sha256", "status", "error", "warnings", "effects", "config"})
INT_COLUMNS = frozenset({"rows", "iterations", "starts"})


@dataclass(frozen=True)
class Columns:
    """The header of a results table, derived from the chart."""

    names: tuple[str, ...]
    parameters: tuple[str, ...]
    outputs: tuple[str, ...]


def columns_for(parameters: Sequence[str], outputs: Sequence[str], diagnose: bool = False) -> Columns:
    """Header: file facts, status, fit, then each parameter with its 95 % interval (``p``, ``p_lo``, ``p_hi``)."""
    names = ["file", "sha256", "status", "error", "t_start", "t_end", "rows", "cost", "iterations", "starts"]
    names += [f"fit_{o}" for o in outputs]
    for p in parameters:
        names += [p, f"{p}_lo", f"{p}_hi"]
    names += ["warnings"] + (["effects"] if diagnose else []) + ["seconds", "config"]
    return Columns(tuple(names), tuple(parameters), tuple(outputs))


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    # one line per row: a torn last line can then always be recognised and dropped
    return " ".join(str(value).splitlines())


def _value(name: str, text: str):
    if text == "":
        return None
    if name in TEXT_COLUMNS:
        return text
    if name in INT_COLUMNS:
        return int(text)
    return float(text)


def parquet_available() -> bool:
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def _need_parquet(path: str) -> None:
    if not parquet_available():
        raise SdnnError.at("BATCH003", "writing Parquet needs pyarrow, which is not installed: pip install pyarrow "
                           "(or write CSV: -o RESULTS.csv)", path)


def is_parquet(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in (".parquet", ".pq")


def read_results(path: str | os.PathLike) -> tuple[list[str], list[dict], int]:
    """(header, rows, dropped) of an existing results table; ``dropped`` counts torn or malformed lines."""
    name = os.fspath(path)
    if is_parquet(name):
        _need_parquet(name)
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(name)
        except Exception as exc:  # noqa: BLE001 - any unreadable file gets one line naming it
            raise SdnnError.at("BATCH004", f"cannot read the results table: {exc}", name) from None
        return list(table.column_names), table.to_pylist(), 0
    try:
        text = Path(name).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SdnnError.at("BATCH004", f"cannot read the results table: {exc}", name) from None
    dropped = 0
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # a line torn by a kill: that file is simply redone
        dropped += 1
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if not header:
        return [], [], dropped
    if header[0] != "file" or "sha256" not in header or "config" not in header:
        raise SdnnError.at("BATCH004", "not a results table of sdnn batch (no file/sha256/config columns)", name)
    rows = []
    for fields in reader:
        if len(fields) != len(header):
            dropped += 1
            continue
        try:
            rows.append({h: _value(h, v) for h, v in zip(header, fields, strict=True)})
        except ValueError:
            dropped += 1
    return header, rows, dropped


class ResultsWriter:
    """Write rows as they come, so that a kill loses at most the file in progress.

    Parameters
    ----------
    path : str or os.PathLike
        RESULTS.csv (a journal, appended to) or RESULTS.parquet (rewritten atomically after each row).
    columns : Columns
    rows : iterable of dict
        Rows kept from an earlier run; the table is rewritten with them at once (dropping torn lines).
    """

    def __init__(self, path: str | os.PathLike, columns: Columns, rows: Iterable[dict] = ()):
        self.path = os.fspath(path)
        self.columns = columns
        self.parquet = is_parquet(self.path)
        if self.parquet:
            _need_parquet(self.path)
        self.rows: list[dict] = list(rows)
        self._handle = None
        self.rewrite(sort=False)
        if not self.parquet:
            self._handle = open(self.path, "a", encoding="utf-8", newline="")  # noqa: SIM115 - kept for appends
            self._writer = csv.writer(self._handle, lineterminator="\n")

    def append(self, row: dict) -> None:
        """Add a row and make it durable before returning."""
        self.rows.append(row)
        if self.parquet:
            self.rewrite(sort=False)
            return
        self._writer.writerow([_cell(row.get(c)) for c in self.columns.names])
        self._handle.flush()
        os.fsync(self._handle.fileno())

    def rewrite(self, sort: bool = True) -> None:
        """Replace the table atomically by the rows held (sorted by file when ``sort``)."""
        # a file redone (changed content, --retry-errors) has two rows in the journal: the later one wins
        self.rows = list({str(r.get("file")): r for r in self.rows}.values())
        rows = sorted(self.rows, key=lambda r: str(r.get("file"))) if sort else self.rows
        if self.parquet:
            self._write_parquet(rows)
            return
        with atomic_open(self.path, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(self.columns.names)
            for row in rows:
                writer.writerow([_cell(row.get(c)) for c in self.columns.names])

    def _write_parquet(self, rows: list[dict]) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        fields = []
        for c in self.columns.names:
            kind = pa.string() if c in TEXT_COLUMNS else pa.int64() if c in INT_COLUMNS else pa.float64()
            fields.append(pa.field(c, kind))
        schema = pa.schema(fields)
        table = pa.Table.from_pylist([{c: r.get(c) for c in self.columns.names} for r in rows], schema=schema)
        with atomic_open(self.path, "wb") as handle:
            pq.write_table(table, handle)

    def close(self, sort: bool = True) -> None:
        """Close the journal and leave the table sorted by file."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
        self.rewrite(sort=sort)

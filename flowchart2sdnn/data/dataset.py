"""The columns read from one CSV file, frozen: what every user of measured data holds (:class:`Dataset`)."""

from __future__ import annotations

import bisect
import dataclasses
from dataclasses import dataclass, replace

import numpy as np

from flowchart2sdnn.notices import Notice

__all__ = ["Dataset"]


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

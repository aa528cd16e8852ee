"""A record's time column against the chart's sample time: checked, and where it can be, prepared.

The one place that decides what a time column means, for the command line and the Python API alike (both
call :func:`conform` on each record, so they give the same error or the same note):

* the median step must be the chart's sample time within STEP_TOLERANCE (CSV021 otherwise: a time column in
  ms, or data logged at another rate), unless ``resample`` is asked for: then every column is resampled to
  the chart's sample time (:func:`scipy.signal.resample_poly`, its anti-aliasing filter included);
* each timestamp is read as the nearest point of the grid ``t0 + k T`` (the grid's step fitted to the
  timestamps, so a logger clock a little off is not read as jitter); stamps within SNAP of a step of their
  point are snapped to it (a note when some were more than STEP_TOLERANCE off), farther ones are refused
  (CSV020): the logger's clock jitters, its samples are still one sample apart;
* where grid points are skipped (a logger dropout), the record is split into records at the gap (a note),
  each simulated from its own initial state; parts of fewer than MIN_PART rows are dropped (said in the note).

Layer 2 (data): numpy and scipy only.
"""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import numpy as np

from ..errors import SdnnError
from ..notices import Notice, messages
from .csvdata import Dataset

__all__ = ["STEP_TOLERANCE", "SNAP", "MIN_PART", "conform", "longest", "record_notes", "record_notices"]

#: the median step may differ this much (relative) from the sample time; a step this far off is a note
STEP_TOLERANCE = 0.01
#: a timestamp within this fraction of a step from its grid point is that point
SNAP = 0.3
#: parts of a split record with fewer rows are dropped
MIN_PART = 10
#: resampling ratios are approximated by fractions with denominators up to this
MAX_DENOMINATOR = 1000


def conform(data: Dataset, sample_time: float, resample: bool = False) -> list[Dataset]:
    """`data` on the grid of `sample_time`: one record, or several where gaps split it (module docstring).

    Raises
    ------
    SdnnError
        CSV019 (time decreases or repeats), CSV020 (a timestamp off the grid), CSV021 (the median step is not
        the sample time and `resample` is off), CSV009 (no part of at least MIN_PART rows is left).
    """
    t = data.time
    if t is None or len(t) < 2:
        return [data]
    steps = np.diff(t)
    column = f"column '{data.time_column or 'time'}'"
    bad = np.flatnonzero(steps <= 0)
    if len(bad):
        k = int(bad[0])
        what = "repeats the previous time" if steps[k] == 0 else "goes back in time"
        raise _fail(data, "CSV019", f"{column}: {what}: step {steps[k]:.6g} (expected a step of {sample_time:.6g} s, "
                    "time strictly increasing)", k + 1)
    median = float(np.median(steps))
    if abs(median - sample_time) > STEP_TOLERANCE * sample_time and not resample:
        k = int(np.argmax(np.abs(steps - sample_time) > STEP_TOLERANCE * sample_time))
        raise _fail(data, "CSV021", f"{column}: step {steps[k]:.6g} (expected {sample_time:.6g} s, the sample time; "
                    f"the median step is {median:.6g})", k + 1,
                    hint="is the time column in another unit (--unit TIME=ms), or logged at another rate "
                         "(--resample)?")
    step = median if resample else sample_time
    index = np.concatenate([[0], np.cumsum(np.maximum(1, np.rint(steps / step)).astype(np.int64))])
    slope, t0 = np.polyfit(index, t, 1) if index[-1] > 0 else (step, t[0])
    off = (t - (t0 + slope * index)) / slope
    worst = int(np.argmax(np.abs(off)))
    if abs(off[worst]) > SNAP:
        raise _fail(data, "CSV020", f"{column}: time {t[worst]:.6g} lies {100 * abs(off[worst]):.3g} % of a step "
                    f"off the grid of {slope:.6g} s steps (expected within {100 * SNAP:.3g} %)", worst,
                    hint="a clock this irregular needs the data resampled onto a grid before identification")
    notes = list(data.notes)
    grid = t0 + slope * index
    if np.max(np.abs(np.diff(off))) > STEP_TOLERANCE:  # a step off by more than the strict check allowed
        notes.append(Notice("TIME001", f"{column}: timestamps up to {abs(off[worst]) * slope:.3g} s "
                            f"({100 * abs(off[worst]):.3g} % of a step) off the grid of {slope:.6g} s steps: snapped to it",
                            {"column": column, "off": float(abs(off[worst]) * slope), "step": float(slope)},
                            "nothing, if the logger's clock jitters; else check the time column"))
        t = grid
    data = replace(data, time=_frozen(t), sample_time=slope, max_step_deviation=float(np.max(np.abs(np.diff(off)))),
                   notes=tuple(notes))
    parts = _split(data, index, column)
    if resample and abs(slope - sample_time) > STEP_TOLERANCE * sample_time:
        parts = [_resample(p, sample_time) for p in parts]
    return parts


def longest(parts: list[Dataset]) -> Dataset:
    """The longest of a record's parts (a record that must stay one, e.g. a validation record), noted."""
    best = max(parts, key=lambda p: p.n_rows)
    if len(parts) == 1:
        return best
    note = Notice("TIME004", f"of the {len(parts)} parts the longest ({best.n_rows} rows) is used",
                  {"parts": len(parts), "rows": best.n_rows}, "give the other parts as records of their own")
    return replace(best, notes=best.notes + (note,))


def record_notices(records) -> list[Notice]:
    """Every record's notes, each once, prefixed by its file."""
    found = (n.prefixed(f"{d.path}: ") for d in records for n in d.notes)
    return list({n.message: n for n in found}.values())


def record_notes(records) -> list[str]:
    """The sentences of :func:`record_notices`."""
    return list(messages(record_notices(records)))


def _split(data: Dataset, index: np.ndarray, column: str) -> list[Dataset]:
    """`data` cut where grid points are skipped; parts shorter than MIN_PART dropped; one note for it all."""
    jumps = np.flatnonzero(np.diff(index) > 1)
    if not len(jumps):
        return [data]
    bounds = [0, *(int(j) + 1 for j in jumps), data.n_rows]
    parts = [(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    kept = [(a, b) for a, b in parts if b - a >= MIN_PART]
    gaps = ", ".join(f"{int(index[j + 1] - index[j] - 1)} after line {data.line_of(int(j)) or int(j)}"
                     for j in jumps[:5]) + (", ..." if len(jumps) > 5 else "")
    note = (f"{column}: {len(jumps)} gap{'s' if len(jumps) > 1 else ''} of missing samples ({gaps}): split into "
            f"{len(kept)} record{'s' if len(kept) != 1 else ''} (rows {', '.join(f'{a}-{b - 1}' for a, b in kept)})")
    if len(kept) < len(parts):
        note += f"; {len(parts) - len(kept)} part(s) shorter than {MIN_PART} rows dropped"
    if not kept:
        raise _fail(data, "CSV009", f"{note}: no part of at least {MIN_PART} rows is left", None)
    said = Notice("TIME002", note, {"column": column, "gaps": len(jumps), "records": [[a, b - 1] for a, b in kept],
                                    "dropped": len(parts) - len(kept)},
                  "nothing, if the logger dropped samples; each part is fitted from its own initial state")
    base = replace(data, notes=data.notes + (said,))
    return [base.slice(a, b) for a, b in kept]


def _resample(data: Dataset, sample_time: float) -> Dataset:
    """Every column of `data` resampled from its step to `sample_time` (polyphase, with scipy's default
    anti-aliasing window, edges padded by a line so the ends do not fall towards zero)."""
    from scipy.signal import resample_poly

    ratio = Fraction(data.sample_time / sample_time).limit_denominator(MAX_DENOMINATOR)
    up, down = ratio.numerator, ratio.denominator
    columns = {name: _frozen(resample_poly(np.asarray(v, dtype=float), up, down, padtype="line"))
               for name, v in data.columns.items()}
    n = len(next(iter(columns.values())))
    time = _frozen(data.time[0] + sample_time * np.arange(n))
    note = Notice("TIME003", f"resampled from {data.sample_time:.6g} s to the chart's {sample_time:.6g} s "
                  f"(scipy.signal.resample_poly, up {up}, down {down}): {data.n_rows} rows -> {n}",
                  {"from": float(data.sample_time), "to": float(sample_time), "up": up, "down": down,
                   "rows": data.n_rows, "rows_after": n}, "log at the chart's sample time to fit the raw samples")
    return replace(data, columns=columns, time=time, n_rows=n, sample_time=sample_time, max_step_deviation=0.0,
                   notes=data.notes + (note,), lines=None, row0=0)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _fail(data: Dataset, code: str, message: str, row: int | None, hint: str | None = None) -> SdnnError:
    line = None if row is None else data.line_of(row)
    if row is not None and line is None:
        message = f"row {row}: {message}"
    return SdnnError.at(code, message, file=data.path, line=line, hint=hint)

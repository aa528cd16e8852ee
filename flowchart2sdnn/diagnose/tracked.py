"""The part of each training record the current fit still follows, for the score test of an unpredictable chart.

On a chaotic drive (motor cogging on the two-mass bench) a first fit of the chart without the effect follows the
record for a while and then loses it: its residual grows from the noise to the size of the difference of two
unrelated trajectories and stays there. Over the whole record the score test (:mod:`.score`) then linearises a
residual the parameters cannot move by small steps, and it ranks whatever bends the diverged part most (the
cogging bench, seeds 2 and 3: the cogging place 6th and 8th among the places, behind friction, input offset,
saturation and overflow; docs/diagnose.md). Scored on the leading part before the divergence is complete the
same candidates rank the cogging place first.

The rule (:func:`tracked_rows`): per record, the running mean square of the residual over ``WINDOW`` rows
(averaged over the outputs); the tracked part ends where that first exceeds ``FOLLOW_FRACTION``² times the
record's own whole mean square, i.e. where the running RMS has reached half of the level the diverged residual
keeps. Not the noise level: the part where the fit stays within NOISE_MARGIN x the noise (100-300 rows on the
cogging bench) is where the missing effect has not shown yet; scored there the cogging place ranks 5th-8th
(docs/diagnose.md). A record whose whole residual is at the noise floor (RMS within NOISE_MARGIN x the noise) is
followed whole.

When (:func:`score_rows`): only when the current fit is unpredictable (:func:`~.fitting.unpredictable`: its chart
amplifies a moved start beyond SUSPECT_PEAK and its residual is off the noise floor), and only when some record's
tracked part is shorter than the record. The tracked part is never shorter than ``min_rows``: the growing
horizon's first stage (``settings.horizon``), and at least ``ROWS_PER_QUANTITY`` rows per fitted quantity; where
that floor makes the part, it must still be followed better than the rest (:func:`record_rows`), else the record
is scored whole: a residual off the floor from the start (a missing friction) is no lost record.

Layer: diagnose.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .. import rules
from ..data.csvdata import Dataset
from ..errors import SdnnError
from ..identify import NOISE_MARGIN, Problem, build_problem, noise_level
from .fitting import DiagnoseSettings, Fitted, unpredictable

__all__ = ["WINDOW", "FOLLOW_FRACTION", "ROWS_PER_QUANTITY", "tracked_rows", "record_rows", "score_rows", "prefix_records",
           "prefix_problem"]

#: rows of the running mean square: the mean square of 100 rows of white noise (per output) spreads by
#: sqrt(2/100) = 14 %, far inside the bound, so noise alone does not end the tracked part
WINDOW = rules.value("tracked_window")
#: the tracked part ends where the running RMS reaches this fraction of the record's whole residual RMS
FOLLOW_FRACTION = rules.value("follow_fraction")
#: the tracked part's floor: this many rows per fitted quantity (and the growing horizon's first stage)
ROWS_PER_QUANTITY = rules.value("rows_per_quantity")


def tracked_rows(residual: np.ndarray, window: int = WINDOW, fraction: float = FOLLOW_FRACTION,
                 floor_ms: float = 0.0) -> int:
    """How many leading rows of one record's residual the fit follows.

    Parameters
    ----------
    residual : (rows, n_out) ndarray
    window : int
        Rows of the running mean square (averaged over the outputs).
    fraction : float
        The tracked part ends at the last row of the first window whose mean square exceeds ``fraction**2``
        times the whole residual's mean square.
    floor_ms : float
        A residual whose whole mean square is at most this is followed whole (the noise floor).

    Returns
    -------
    int
        ``i + window - 1`` for the first window ``[i, i + window)`` over the bound (every window inside the
        result is within it), or ``rows`` when none is.
    """
    e = np.asarray(residual, dtype=float)
    if e.ndim == 1:
        e = e[:, None]
    rows = e.shape[0]
    if rows < window:
        return rows
    ms = np.mean(e * e, axis=1)
    whole = float(np.mean(ms))
    if not whole > floor_ms:
        return rows
    running = np.convolve(ms, np.ones(window) / window, mode="valid")
    over = np.flatnonzero(running > fraction * fraction * whole)
    return int(over[0] + window - 1) if over.size else rows


def record_rows(residual: np.ndarray, floor_ms: float, min_rows: int) -> int:
    """One record's scored rows: its tracked part (:func:`tracked_rows`) raised to `min_rows`, or the whole record
    when the raised part is not followed better than the rest (its mean square above the bound of
    :func:`tracked_rows`: a residual off the floor all along, not a fit that loses the record, where the floor
    alone would make the part)."""
    e = np.asarray(residual, dtype=float).reshape(len(residual), -1)
    n = e.shape[0]
    rows = min(n, max(min_rows, tracked_rows(e, floor_ms=floor_ms)))
    if rows < n and np.mean(e[:rows] ** 2) > FOLLOW_FRACTION ** 2 * np.mean(e ** 2):
        return n
    return rows


def score_rows(fitted: Fitted, problem: Problem, train: Sequence[Dataset],
               settings: DiagnoseSettings) -> list[int] | None:
    """Per training record, the rows (of its fitted targets) the score test should use, or None for all of them.

    None unless the fit is unpredictable and some record's tracked part (:func:`tracked_rows`, raised to the
    floor) is shorter than the record.
    """
    if not unpredictable(fitted, train, settings):
        return None
    x = problem.compiled.theta0()
    e = problem.residual(x)
    if e is None:
        return None
    floor_ms = NOISE_MARGIN ** 2 * noise_level(problem)
    min_rows = max(settings.horizon, ROWS_PER_QUANTITY * len(problem.names), 2 * WINDOW)
    rows, at = [], 0
    for s in problem.segments:
        n, n_out = s.targets.shape
        rows.append(record_rows(e[at:at + n * n_out].reshape(n, n_out), floor_ms, min_rows))
        at += n * n_out
    if all(r >= s.targets.shape[0] for r, s in zip(rows, problem.segments, strict=True)):
        return None
    return rows


def prefix_records(train: Sequence[Dataset], problem: Problem, rows: Sequence[int]) -> list[Dataset]:
    """Each training record cut so that its problem fits `rows` target rows (the alignment may drop leading
    rows: the cut keeps the same number of dropped rows)."""
    out = []
    for ds, s, n in zip(train, problem.segments, rows, strict=True):
        dropped = ds.n_rows - s.targets.shape[0]
        out.append(ds.slice(0, n + dropped))
    return out


def prefix_problem(fitted: Fitted, train: Sequence[Dataset], settings: DiagnoseSettings,
                   rows: Sequence[int]) -> tuple[Problem, list[Dataset]] | None:
    """The current chart on the tracked parts (same values, so the same residual and Jacobian rows), or None."""
    try:
        problem = build_problem(fitted.diagram, train[0], settings.alignment, settings.seed, more=tuple(train[1:]))
        cut = prefix_records(train, problem, rows)
        return build_problem(fitted.diagram, cut[0], settings.alignment, settings.seed, more=tuple(cut[1:])), cut
    except (SdnnError, ValueError, KeyError):
        return None

"""The maintenance view of a fleet: each parameter over time per drive, and which drives drift.

Drive and day come from each row's file name. The default rule (:data:`DEFAULT_GROUP`) reads names such as
``drive07_day012.csv``, ``pump-3_2024-05-01.csv`` or ``drive07/2024-05-01.csv``: the day is the last number
or ISO date of the name, the drive is what precedes it (or the directory name when the stem is only a day).
``group`` replaces the rule by a regular expression searched in the file path; it must have a named group
``drive`` and may have ``day`` (an integer or an ISO date; without it the rows' ``t_start`` order the days).

Drift of a parameter on a drive (:func:`drift_table`) is the robust (Theil-Sen) slope over the days, so a day
whose fit went wrong does not decide it: it is flagged when the change it implies over the days seen is at
least ``threshold`` of the median value, the slope is at least ``t_min`` robust standard errors away from zero,
and that change exceeds ``ci_factor`` times the typical 95 % half-width of a single file's estimate. Days far
off the trend (4 robust standard deviations) are listed as outliers.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import PurePath

import numpy as np

from ..errors import SdnnError
from .results import read_results

__all__ = ["DEFAULT_GROUP", "Point", "Fleet", "trusted", "UNCONVERGED_STATUSES", "parse_group", "load_fleet",
           "drift_table", "effects_table", "day_text"]

_DAY = r"(?P<day>\d{4}-\d{2}-\d{2}|\d+)"
#: The default rule: tried on the stem ("drive07_day012"), then on "directory/stem" ("drive07/2024-05-01").
DEFAULT_GROUP = (re.compile(rf"^(?P<drive>.+?)[_\-. ]+(?:day[_\-]?)?{_DAY}$", re.IGNORECASE),
                 re.compile(rf"(?:^|/)(?P<drive>[^/]+)/(?:day[_\-]?)?{_DAY}$", re.IGNORECASE))
_ONLY_DAY = re.compile(rf"^(?:day[_\-]?)?{_DAY}$", re.IGNORECASE)


@dataclass(frozen=True)
class Point:
    """One identified file of a drive: its day and the row of the results table."""

    drive: str
    day: int | dt.date | None
    x: float  # the day as a number (a date's ordinal), for fitting slopes
    row: dict


@dataclass(frozen=True)
class Fleet:
    """A results table grouped by drive.

    Attributes
    ----------
    drives : dict of str to tuple of Point   ordered by day
    parameters : tuple of str   parameters that were identified (fixed ones are left out)
    errors : tuple of str       files whose row is an error
    unmatched : tuple of str    files whose name the grouping rule could not read
    unconverged : tuple of str  files whose fit did not converge: left out of the trends (one such fit can
                                fake or hide a drift)
    """

    drives: dict[str, tuple[Point, ...]]
    parameters: tuple[str, ...]
    errors: tuple[str, ...]
    unmatched: tuple[str, ...]
    unconverged: tuple[str, ...] = ()


def _day(text: str | None):
    if text is None:
        return None
    if "-" in text:
        try:
            return dt.date.fromisoformat(text)
        except ValueError:
            return None
    return int(text)


def parse_group(file: str, group: re.Pattern | None = None) -> tuple[str, int | dt.date | None] | None:
    """(drive, day) read from a file path, or None when the rule does not match."""
    path = PurePath(file).as_posix()
    stem = path.rsplit("/", 1)[-1]
    stem = stem[: stem.rfind(".")] if "." in stem else stem
    if group is not None:
        m = group.search(path)
        if not m or not m.groupdict().get("drive"):
            return None
        return m.group("drive"), _day(m.groupdict().get("day"))
    if _ONLY_DAY.match(stem):  # "2024-05-01.csv": the day alone, the drive is the directory
        parent = path.rsplit("/", 1)[0] if "/" in path else ""
        m = DEFAULT_GROUP[1].search(f"{parent}/{stem}") if parent else None
    else:
        m = DEFAULT_GROUP[0].match(stem)
    if m is None:
        return None
    day = _day(m.group("day"))
    return (m.group("drive"), day) if day is not None else None


def _free_parameters(header: Sequence[str], rows: Sequence[dict]) -> tuple[str, ...]:
    names = [h for h in header if f"{h}_lo" in header and f"{h}_hi" in header]
    out = []
    for p in names:
        values = {r.get(p) for r in rows if r.get(p) is not None}
        if len(values) > 1 or any(r.get(f"{p}_lo") is not None for r in rows):
            out.append(p)
    return tuple(out)


def load_fleet(path: str | os.PathLike, group: str | None = None) -> Fleet:
    """Read a results table and group its rows by drive and day.

    Raises
    ------
    SdnnError
        REP001 when ``group`` is not a valid pattern with a ``drive`` group, REP002 when no row can be grouped.
    """
    name = os.fspath(path)
    if not os.path.exists(name):
        raise SdnnError.at("REP003", "no such results table", name)
    pattern = None
    if group is not None:
        try:
            pattern = re.compile(group)
        except re.error as exc:
            raise SdnnError.at("REP001", f"--group is not a valid regular expression: {exc}") from None
        if "drive" not in pattern.groupindex:
            raise SdnnError.at("REP001", "--group needs a named group (?P<drive>...) (and may have (?P<day>...))")
    header, rows, _ = read_results(name)
    errors = tuple(sorted(str(r["file"]) for r in rows if r.get("status") == "error"))
    doubtful = tuple(sorted(str(r["file"]) for r in rows if r.get("status") != "error" and not trusted(r)))
    good = [r for r in rows if r.get("status") != "error" and trusted(r)]
    drives: dict[str, list[Point]] = {}
    unmatched = []
    for r in good:
        g = parse_group(str(r["file"]), pattern)
        if g is None:
            unmatched.append(str(r["file"]))
            continue
        drive, day = g
        if day is None:
            x = float(r.get("t_start") or 0.0)
        else:
            x = float(day.toordinal() if isinstance(day, dt.date) else day)
        drives.setdefault(drive, []).append(Point(drive, day, x, r))
    if good and not drives:
        raise SdnnError.at("REP002", f"no file name gives a drive and a day (e.g. '{good[0]['file']}')", name,
                           hint="name files like drive07_day012.csv, or give --group with (?P<drive>...) "
                                "and (?P<day>...)")
    kinds = {type(p.day) for pts in drives.values() for p in pts if p.day is not None}
    if len(kinds) > 1:
        raise SdnnError.at("REP002", "some days are dates and some are numbers; give --group", name)
    ordered = {d: tuple(sorted(pts, key=lambda p: (p.x, str(p.row["file"])))) for d, pts in sorted(drives.items())}
    return Fleet(ordered, _free_parameters(header, good), errors, tuple(sorted(unmatched)), doubtful)


#: Statuses of a fit that stopped before it converged (see fit.lm.CONVERGED_STATUSES for the others).
UNCONVERGED_STATUSES = frozenset({"max_iter", "interrupted", "max_mu_tries", "callback_stop"})


def trusted(row: dict) -> bool:
    """Whether a results row's fit converged (its status is not one of :data:`UNCONVERGED_STATUSES`)."""
    return row.get("status") not in UNCONVERGED_STATUSES


def _trend(x: np.ndarray, y: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Robust slope of y over x, its standard error, and which points are outliers.

    The Theil-Sen slope (median of the pairwise slopes) with the residual scale 1.4826 * MAD about that line,
    so that a few failed fits (a local minimum on one day) neither hide a drift nor fake one. When more than
    half the residuals are exactly zero (three points) the scale is the root mean square residual instead.
    The standard error is scale / sqrt(sum (x - mean x)^2), as for least squares; inf when undetermined.
    """
    from scipy.stats import theilslopes

    xm = x - x.mean()
    sxx = float(xm @ xm)
    if len(x) < 3 or sxx == 0:
        return math.nan, math.inf, np.zeros(len(x), dtype=bool)
    b = float(theilslopes(y, x)[0])
    r = y - b * x
    r = r - np.median(r)  # the intercept that centres the residuals (scipy's default need not)
    scale = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    if scale == 0:
        scale = math.sqrt(float(r @ r) / (len(x) - 2))
    outliers = np.abs(r) > 4 * scale if scale > 0 else np.zeros(len(x), dtype=bool)
    return b, scale / math.sqrt(sxx), outliers


def drift_table(fleet: Fleet, threshold: float = 0.10, t_min: float = 3.0, ci_factor: float = 2.0) -> list[dict]:
    """Per drive and parameter: the trend over the days and whether it is a drift.

    Parameters
    ----------
    fleet : Fleet
    threshold : float
        Smallest change over the days seen, as a fraction of the mean value, that counts as a drift.
    t_min : float
        Smallest |slope| / standard error that counts.
    ci_factor : float
        The change over the days must also exceed this many median 95 % half-widths of the single files'
        estimates (a parameter the data barely determine does not drift by wandering inside its interval).

    Returns
    -------
    list of dict
        Keys drive, parameter, n, first_day, last_day, first, last, mean (the median value), slope_per_day,
        slope_stderr, t, change_percent, ci_halfwidth (median over the files), outliers (days, space
        separated), drift ("rising", "falling" or "").
    """
    out = []
    for drive, points in fleet.drives.items():
        for p in fleet.parameters:
            pts = [q for q in points if q.row.get(p) is not None]
            if not pts:
                continue
            x = np.array([q.x for q in pts])
            y = np.array([float(q.row[p]) for q in pts])
            b, se, outliers = _trend(x, y)
            mean = float(np.median(y))
            span = float(x.max() - x.min())
            change = b * span / abs(mean) if math.isfinite(b) and mean != 0 else math.nan
            t = b / se if math.isfinite(b) and se > 0 else (math.inf if math.isfinite(b) and b != 0 else 0.0)
            # the typical 95 % half-width of one file's estimate: a drift must be larger than that noise
            halves = [(q.row[f"{p}_hi"] - q.row[f"{p}_lo"]) / 2 for q in pts
                      if q.row.get(f"{p}_lo") is not None and q.row.get(f"{p}_hi") is not None]
            half = float(np.median(halves)) if halves else 0.0
            drift = ""
            if (math.isfinite(change) and abs(change) >= threshold and abs(t) >= t_min
                    and abs(b) * span >= ci_factor * half):
                drift = "rising" if b > 0 else "falling"
            out.append({"drive": drive, "parameter": p, "n": len(pts), "first_day": day_text(pts[0].day),
                        "last_day": day_text(pts[-1].day), "first": float(y[0]), "last": float(y[-1]),
                        "mean": mean, "slope_per_day": b, "slope_stderr": se, "t": t,
                        "change_percent": 100 * change, "ci_halfwidth": half,
                        "outliers": " ".join(day_text(q.day) for q, o in zip(pts, outliers, strict=True) if o),
                        "drift": drift})
    return out


def effects_table(fleet: Fleet) -> list[dict]:
    """Per drive and effect that ``sdnn batch --diagnose`` accepted: the days it was found on.

    Returns
    -------
    list of dict
        Keys drive, effect, days (list of day texts), of (days diagnosed on that drive), first_day.
    """
    out = []
    for drive, points in fleet.drives.items():
        diagnosed = [q for q in points if q.row.get("effects")]
        found: dict[str, list[str]] = {}
        for q in diagnosed:
            text = str(q.row["effects"])
            if text == "none" or text.startswith("diagnose failed"):
                continue
            for effect in text.split("; "):
                found.setdefault(effect, []).append(day_text(q.day))
        for effect, days in found.items():
            out.append({"drive": drive, "effect": effect, "days": days, "of": len(diagnosed), "first_day": days[0]})
    return out


def day_text(day) -> str:
    return "" if day is None else day.isoformat() if isinstance(day, dt.date) else str(day)

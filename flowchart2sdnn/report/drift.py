"""`sdnn report`: the fleet's plots and tables (drift.csv, report.md) from :mod:`flowchart2sdnn.batch.drift`.

One ``PARAM.png`` per parameter (every drive over the days; drifting drives in colour with their change, the
others grey), one ``drive_ID.png`` per drive (each parameter with its 95 % interval), ``drift.csv`` and
``report.md`` (the drifting drives first).
"""

from __future__ import annotations

import csv
import datetime as dt
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..batch.drift import Fleet, Point, day_text, effects_table
from ..errors import SdnnError

__all__ = ["write_report", "plots_available"]


def _pyplot_free_figure(**kwargs):
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise SdnnError.at("REP004", "plots need matplotlib, which is not installed: "
                           "pip install flowchart2sdnn[plots]") from None
    return Figure(**kwargs)


def _save(fig, path: Path) -> None:
    with atomic_open(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=110)


def _xs(points: Sequence[Point]):
    return [p.day if p.day is not None else p.x for p in points]


def _errorbars(points: Sequence[Point], p: str) -> tuple[list, list, np.ndarray]:
    xs, ys, lo, hi = [], [], [], []
    for q, xv in zip(points, _xs(points), strict=True):
        v = q.row.get(p)
        if v is None:
            continue
        xs.append(xv)
        ys.append(v)
        lo.append(v - q.row[f"{p}_lo"] if q.row.get(f"{p}_lo") is not None else 0.0)
        hi.append(q.row[f"{p}_hi"] - v if q.row.get(f"{p}_hi") is not None else 0.0)
    return xs, ys, np.array([lo, hi])


def _day_axis(fig, ax, fleet: Fleet) -> None:
    days = [q.day for pts in fleet.drives.values() for q in pts]
    if any(isinstance(d, dt.date) for d in days):
        fig.autofmt_xdate()
    elif days and all(isinstance(d, int) for d in days):
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def plots_available() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _parameter_plot(fleet: Fleet, p: str, flagged: dict, path: Path) -> None:
    fig = _pyplot_free_figure(figsize=(8, 4.5))
    ax = fig.add_subplot()
    for drive, points in fleet.drives.items():
        xs, ys, err = _errorbars(points, p)
        d = flagged.get((drive, p))
        if d is None:
            ax.plot(xs, ys, color="0.7", lw=0.8, marker=".", ms=3)
        else:
            ax.errorbar(xs, ys, yerr=err, lw=1.5, marker="o", ms=4, capsize=2,
                        label=f"{drive} ({d['change_percent']:+.0f} %)")
    _value_limits(ax, [q.row[p] for pts in fleet.drives.values() for q in pts if q.row.get(p) is not None])
    ax.set_title(f"{p} per drive ({sum(1 for k in flagged if k[1] == p)} drifting, in colour)")
    ax.set_xlabel("day")
    ax.set_ylabel(p)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="small", ncol=2)
    _day_axis(fig, ax, fleet)
    _save(fig, path)


def _value_limits(ax, ys: Sequence[float]) -> None:
    """Scale the axis to the values, not their intervals: one failed day's huge interval would flatten the rest."""
    if len(ys) < 2:
        return
    lo, hi = float(min(ys)), float(max(ys))
    pad = 0.1 * (hi - lo) if hi > lo else 0.05 * abs(hi) or 1.0
    ax.set_ylim(lo - pad, hi + pad)


def _drive_plot(fleet: Fleet, drive: str, table: dict, path: Path) -> None:
    n = max(1, len(fleet.parameters))
    fig = _pyplot_free_figure(figsize=(7, 1.9 * n + 0.6))
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for ax, p in zip(axes, fleet.parameters, strict=False):
        points = fleet.drives[drive]
        xs, ys, err = _errorbars(points, p)
        info = table.get((drive, p)) or {}
        d = info if info.get("drift") else None
        ax.errorbar(xs, ys, yerr=err, marker="o", ms=3, capsize=2, color="C3" if d else "C0")
        odd = set(str(info.get("outliers") or "").split())
        out = [(x, q.row[p]) for x, q in zip(_xs(points), points, strict=True)
               if q.row.get(p) is not None and day_text(q.day) in odd]
        if out:
            ax.plot([o[0] for o in out], [o[1] for o in out], "x", color="k", ms=8, label="off the trend")
            ax.legend(fontsize="x-small", loc="best")
        _value_limits(ax, ys)
        ax.set_ylabel(p)
        ax.grid(alpha=0.3)
        if d:
            ax.set_title(f"{p}: {d['drift']} {d['change_percent']:+.1f} % over the days", fontsize="small",
                         color="C3")
    axes[-1].set_xlabel("day")
    _day_axis(fig, axes[-1], fleet)
    fig.suptitle(f"drive {drive}")
    fig.tight_layout()
    _save(fig, path)


def write_report(fleet: Fleet, drift: list[dict], directory: str | os.PathLike, plots: bool = True) -> list[str]:
    """Write the plots and tables into `directory` (created if needed); return the files written.

    One ``PARAM.png`` per parameter (every drive over the days; drifting drives in colour with their change,
    the others grey), one ``drive_ID.png`` per drive (each parameter with its 95 % interval), ``drift.csv``
    and ``report.md`` (the drifting drives first). ``plots=False`` writes the tables only (no matplotlib).
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    written: list[str] = []
    flagged = {(d["drive"], d["parameter"]): d for d in drift if d["drift"]}
    if plots:
        for p in fleet.parameters:
            _parameter_plot(fleet, p, flagged, out / f"{_safe(p)}.png")
            written.append(str(out / f"{_safe(p)}.png"))
        table = {(d["drive"], d["parameter"]): d for d in drift}
        for drive in fleet.drives:
            _drive_plot(fleet, drive, table, out / f"drive_{_safe(drive)}.png")
            written.append(str(out / f"drive_{_safe(drive)}.png"))
    keys = ["drive", "parameter", "n", "first_day", "last_day", "first", "last", "mean", "slope_per_day",
            "slope_stderr", "t", "change_percent", "ci_halfwidth", "outliers", "drift"]
    with atomic_open(out / "drift.csv", "w", newline="") as handle:
        w = csv.writer(handle, lineterminator="\n")
        w.writerow(keys)
        for d in drift:
            w.writerow([f"{d[k]:.6g}" if isinstance(d[k], float) else d[k] for k in keys])
    written.append(str(out / "drift.csv"))
    lines = ["# Fleet report", "", f"{sum(len(v) for v in fleet.drives.values())} identified files of "
             f"{len(fleet.drives)} drives; {len(fleet.errors)} error row(s); "
             f"{len(fleet.unconverged)} fit(s) left out as not converged; "
             f"{len(fleet.unmatched)} file(s) without drive/day.", "", "## Drifting", ""]
    lines += [f"- drive {d['drive']}: {d['parameter']} {d['drift']} {d['change_percent']:+.1f} % "
              f"({d['first']:.4g} -> {d['last']:.4g}, days {d['first_day']}..{d['last_day']}, t = {d['t']:.1f})"
              for d in drift if d["drift"]] or ["(none)"]
    effects = effects_table(fleet)
    if effects or any(q.row.get("effects") for pts in fleet.drives.values() for q in pts):
        lines += ["", "## Effects found by --diagnose", ""]
        lines += [f"- drive {e['drive']}: {e['effect']} on {len(e['days'])} of {e['of']} days, first on day "
                  f"{e['first_day']}" for e in effects] or ["(none)"]
    lines += ["", "## Plots", ""]
    lines += [f"- [{Path(f).name}]({Path(f).name})" for f in written if f.endswith(".png")] or [
        "(none: install matplotlib, pip install flowchart2sdnn[plots])"]
    with atomic_open(out / "report.md", "w") as handle:
        handle.write("\n".join(lines) + "\n")
    written.append(str(out / "report.md"))
    return written

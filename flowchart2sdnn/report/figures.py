"""The figures engineers hand on: measured against model (MATLAB's `compare`) and residual analysis (`resid`).

* :func:`compare_figure`: per record and output, measured and model output over the scored rows with fit % and
  RMS in the legend, units from the chart on the axis, and beside it a zoom on the stretch with the largest
  error (so a fit of 99 % still shows where it misses).
* :func:`resid_figure`: for one output, the residual's autocorrelation (lags 0..L) and its cross-correlation
  with each input (lags -L..L), with the 99 % band of a white residual independent of the input drawn and
  labelled (the numbers of :mod:`flowchart2sdnn.fit.correlation`) and the test's verdict in the title; L is
  25 unless the caller sets it from the dynamics (a page: the slowest mode's period).
* :func:`residual_time_figure`: the residual over time, per record and output, RMS in the title.

Numbers in legends and captions are formatted by :func:`fit_number`, as the tables beside them.

Each figure is built on its own Agg canvas (:mod:`.canvas`); ``write_*`` save it atomically.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..fit.correlation import LEVEL, MAX_LAG, bound, whiteness, xcorr
from ..identify import Comparison
from .canvas import new_figure, require_matplotlib, save_png

__all__ = ["axis_label", "compare_figure", "write_compare", "resid_figure", "write_resid", "safe_name",
           "fit_number", "residual_time_figure", "verdict"]

#: the zoom shows this fraction of the record around the largest error (at least _ZOOM_MIN samples): narrow
#: enough that a sensor-noise-sized error is visible against the signal's range
_ZOOM_FRACTION = 0.005
_ZOOM_MIN = 40


def safe_name(name: str) -> str:
    """A signal name as a piece of a file name."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


def axis_label(name: str, unit: str | None) -> str:
    return f"{name} in {unit}" if unit else name


def fit_number(x: float | None) -> str:
    """A fit % as every table, legend and caption shows it (four significant digits)."""
    return "n/a" if x is None else f"{x:.4g}"


def _number(x: float | None, unit: str | None = None, digits: int = 3) -> str:
    if x is None:
        return "n/a"
    return f"{x:.{digits}g}" + (f" {unit}" if unit else "")


def compare_figure(comparison: Comparison, title: str = ""):
    """The compare figure (a matplotlib Figure): one row per record and output, full record and zoom."""
    names = comparison.outputs
    rows = [(r, name) for r in comparison.records for name in names]
    fig, axes = new_figure(len(rows), 2, width=12.0, height=2.7, gridspec_kw={"width_ratios": [3, 1]})
    what = "free run" if comparison.horizon is None else f"{comparison.horizon}-step prediction"
    for (rec, name), (ax, zoom) in zip(rows, axes, strict=True):
        unit = comparison.units.get(name)
        t, y, m = rec.time, rec.measured[name], rec.model[name]
        label = f"model ({what}): fit {fit_number(rec.fit_percent[name])} %, RMS {_number(rec.rms[name], unit)}"
        for a, marker in ((ax, None), (zoom, ".")):
            a.plot(t, y, color="0.35", lw=0.8, marker=marker, ms=3, label="measured")
            a.plot(t, m, color="tab:red", lw=1.0, ls="--", label=label)
            a.grid(alpha=0.3)
        ax.set_ylabel(axis_label(name, unit))
        ax.set_title(f"{rec.label}: {name}", fontsize="medium", loc="left")
        # above the axes, right-aligned beside the title: a legend inside would hide part of the record
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=2, fontsize="small", frameon=False,
                  borderaxespad=0.1)
        ax.set_xlabel("time in s")
        e = np.abs(y - m)
        if np.any(np.isfinite(e)) and len(t) > 1:
            k = int(np.nanargmax(e))
            half = max(_ZOOM_MIN, int(_ZOOM_FRACTION * len(t))) // 2
            lo, hi = max(0, k - half), min(len(t) - 1, k + half)
            zoom.set_xlim(t[lo], t[hi])
            window = np.concatenate([y[lo:hi + 1], m[lo:hi + 1]])
            window = window[np.isfinite(window)]
            if window.size:
                pad = 0.1 * max(float(np.ptp(window)), 1e-12)
                zoom.set_ylim(float(window.min()) - pad, float(window.max()) + pad)
            ax.axvspan(t[lo], t[hi], color="tab:orange", alpha=0.3, lw=0)
            zoom.axvline(t[k], color="tab:orange", lw=1.0)
            zoom.set_title(f"largest error {_number(float(e[k]), unit)} at {t[k]:.4g} s", fontsize="small")
        zoom.set_xlabel("time in s")
    if title:
        fig.suptitle(title)
    return fig


def write_compare(comparison: Comparison, path: str | Path, name: str = "") -> Path:
    """Draw :func:`compare_figure` into a PNG file (replaced atomically)."""
    require_matplotlib()
    what = "free run" if comparison.horizon is None else f"{comparison.horizon}-step-ahead prediction"
    title = f"{name}: measured and model output ({what})" if name else ""
    return save_png(compare_figure(comparison, title), path)


def verdict(residual: np.ndarray, inputs: np.ndarray, output: str, input_names: Sequence[str],
            max_lag: int = MAX_LAG, level: float = LEVEL) -> str:
    """The residual test in words: white or not, independent of the inputs or not, with how many lags fall
    outside the band (the rule of :func:`flowchart2sdnn.fit.correlation.whiteness`)."""
    e = np.asarray(residual, dtype=float)
    u = np.atleast_2d(np.asarray(inputs, dtype=float).T).T
    w = whiteness(e[:, None], u, [output], list(input_names), max_lag, level)
    auto = w["autocorrelation"][output]
    words = [f"{'white' if w['white'] else 'not white'} ({auto['outside']} of {max_lag} lags outside the "
             f"{100 * level:g} % band"
             + ("" if w["white"] else f", largest |r| {auto['max_abs']:.2f} at lag {auto['lag_of_max']}") + ")"]
    for i, (name, c) in enumerate(w["cross_correlation"][output].items()):
        ok = whiteness(e[:, None], u[:, [i]], [output], [name], max_lag, level)["independent"]  # this input alone
        words.append(f"{'independent of' if ok else 'correlated with'} {name} ({c['outside']} of "
                     f"{2 * max_lag + 1} lags outside" + ("" if ok else f", largest at lag {c['lag_of_max']}") + ")")
    return "; ".join(words)


def resid_figure(residual: np.ndarray, inputs: np.ndarray, output: str, input_names: Sequence[str],
                 title: str = "", unit: str | None = None, max_lag: int = MAX_LAG, level: float = LEVEL,
                 sample_time: float | None = None):
    """Residual analysis of one output: autocorrelation (lags 0..max_lag) and cross-correlation with each
    input (lags -max_lag..max_lag, positive: the input leads), with the `level` band of white noise; with
    `sample_time` a second axis gives the lag in seconds."""
    e = np.asarray(residual, dtype=float)
    u = np.atleast_2d(np.asarray(inputs, dtype=float).T).T
    band = bound(e.size, level)
    fig, axes = new_figure(1 + len(input_names), 1, width=8.0, height=2.5)
    panels = [(axes[0, 0], np.arange(0, max_lag + 1), e, f"autocorrelation of the residual of {output}")]
    panels += [(axes[i + 1, 0], np.arange(-max_lag, max_lag + 1), u[:, i],
                f"cross-correlation of the residual of {output} with input {name}")
               for i, name in enumerate(input_names)]
    for ax, lags, other, what in panels:
        r = xcorr(e, other, lags)
        outside = np.abs(r) > band
        outside[lags == 0] &= other is not e  # r_ee(0) = 1 by definition
        ax.axhspan(-band, band, color="tab:blue", alpha=0.15, lw=0,
                   label=f"{100 * level:g} % band ±{band:.3g} (white, independent)")
        ax.vlines(lags, 0, r, color="0.3", lw=1.2)
        ax.plot(lags[~outside], r[~outside], "o", ms=3.5, color="0.3")
        if outside.any():
            ax.plot(lags[outside], r[outside], "o", ms=4.5, color="tab:red",
                    label=f"{int(outside.sum())} lag(s) outside")
        ax.axhline(0, color="0.3", lw=0.6)
        ax.set_title(what, fontsize="medium", loc="left")
        ax.set_ylabel("correlation")
        ax.set_xlim(lags[0] - 0.5, lags[-1] + 0.5)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize="small", framealpha=0.85)
        if sample_time:
            top = ax.secondary_xaxis("top", functions=(lambda k: k * sample_time, lambda t: t / sample_time))
            top.tick_params(labelsize="small")
    axes[-1, 0].set_xlabel("lag in samples" + (f" (one sample = {sample_time:g} s; top axis: lag in s)"
                                               if sample_time else ""))
    rms = float(np.sqrt(np.mean(e**2))) if e.size and np.all(np.isfinite(e)) else None
    head = f" ({title})" if title else ""
    fig.suptitle(f"residual analysis of {output}{head}\n{e.size} samples, RMS {_number(rms, unit)}: "
                 + verdict(e, u, output, input_names, max_lag, level).split(";")[0], fontsize="medium", wrap=True)
    return fig


def residual_time_figure(comparison: Comparison, title: str = ""):
    """Measured minus model output over time: one row per record and output, RMS and largest error in the
    title, the output's unit on the axis."""
    rows = [(r, name) for r in comparison.records for name in comparison.outputs]
    fig, axes = new_figure(len(rows), 1, width=12.0, height=2.2)
    for (rec, name), ax in zip(rows, axes[:, 0], strict=True):
        unit = comparison.units.get(name)
        e = rec.measured[name] - rec.model[name]
        ax.plot(rec.time, e, color="tab:purple", lw=0.6)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel(axis_label(f"{name} residual", unit))
        ax.set_title(f"{rec.label}: {name} measured - model, RMS {_number(rec.rms[name], unit)}, largest "
                     f"{_number(rec.max_error[name], unit)}", fontsize="medium", loc="left")
        ax.grid(alpha=0.3)
        ax.set_xlabel("time in s")
    if title:
        fig.suptitle(title)
    return fig


def write_resid(residual: np.ndarray, inputs: np.ndarray, outputs: Sequence[str], input_names: Sequence[str],
                directory: str | Path, title: str = "", units: dict | None = None,
                prefix: str = "resid", max_lag: int = MAX_LAG, sample_time: float | None = None) -> list[Path]:
    """One residual-analysis PNG per output, ``<prefix>_<output>.png`` in `directory`; skips a residual that
    is not finite (a diverged run has nothing to analyse)."""
    e = np.atleast_2d(np.asarray(residual, dtype=float).T).T
    written = []
    for j, name in enumerate(outputs):
        if not np.all(np.isfinite(e[:, j])) or e.shape[0] < 3:
            continue
        fig = resid_figure(e[:, j], inputs, name, input_names, title, (units or {}).get(name), max_lag,
                           sample_time=sample_time)
        written.append(save_png(fig, Path(directory) / f"{prefix}_{safe_name(name)}.png"))
    return written

"""`sdnn diagnose --plots DIR`: the residual against the signal each accepted effect was traced to.

For every accepted effect, ``residual_<effect>_<at>.png`` shows, per output, the residual (measured minus
simulated, training record) of the chart as given (left) and of the final chart (right) against the signal
the effect attaches to (a speed for friction, an input for a dead time, ...): a friction curve shows up as
a step at zero speed on the left and is gone on the right. ``whiteness.png`` shows the residual
autocorrelation before and after with the 99 % band, over lags spanning the final chart's slowest mode;
``resid_<output>.png`` the residual analysis of the final chart (autocorrelation and cross-correlation with
each input, 99 % band; see :mod:`.figures`). Written like the identify figures: an Agg canvas per figure,
rendered to bytes and written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.csvdata import Dataset
from ..diagnose.loop import Diagnosis, Fitted
from ..fit.correlation import LEVEL, bound, xcorr
from ..identify import build_problem, signal_units
from .canvas import new_figure, save_png
from .figures import axis_label, resid_figure, safe_name
from .linear import residual_lags

__all__ = ["write_plots", "figures"]

_MAX_POINTS = 20000


def _figure(rows: int, cols: int):
    return new_figure(rows, cols, width=4.5 * cols, height=2.6)


def _traces(f: Fitted, train: Dataset, alignment: str, seed: int):
    problem = build_problem(f.diagram, train, alignment, seed)
    x = problem.compiled.theta0()
    with np.errstate(all="ignore"):
        e = problem.residual(x)
        sig = problem.compiled.signals(x, problem.inputs, problem.init)
    sig = dict(sig)
    for i, name in enumerate(problem.compiled.input_names):
        sig[name] = problem.inputs[:, i]
    e = None if e is None else e.reshape(problem.targets.shape)
    return e, sig, problem.compiled.output_names


def whiteness_lags(diagnosis: Diagnosis, train: Dataset, lags: int | None = None) -> tuple[int, str]:
    """(lags, why) of the before/after autocorrelation: `lags` (``--lags``), else spanning the final chart's
    slowest mode (:func:`.linear.residual_lags`)."""
    return residual_lags(diagnosis.final.identification, train.n_rows, lags)


def figures(diagnosis: Diagnosis, train: Dataset, resid: bool = True,
            lags: int | None = None) -> list[tuple[str, object]]:
    """(file name, matplotlib Figure) of every figure of the module docstring; `resid` False leaves out the
    residual analysis of the final chart (the HTML report draws it with the final fit); `lags` of the
    autocorrelations (default: spanning the final chart's slowest mode)."""
    settings = diagnosis.report["settings"]
    alignment, seed = settings["alignment"], settings["seed"]
    if settings.get("split") is not None:
        train = train.slice(0, max(3, int(round(settings["split"] * train.n_rows))))
    e0, _, names = _traces(diagnosis.nominal, train, alignment, seed)
    e1, s1, _ = _traces(diagnosis.final, train, alignment, seed)
    inputs = list(diagnosis.final.diagram.input_names)
    first = 1 if alignment == "zoh" else 0
    measured = {n: np.asarray(train.columns[n])[first:] for n in names}  # outputs on the fitted rows
    out = []
    rng = np.random.default_rng(0)
    units = signal_units(diagnosis.final.diagram)
    blocks = {b.name: b.unit for b in diagnosis.final.diagram.blocks}
    for a in diagnosis.report["accepted"]:
        at = a["at"]
        # one abscissa for both panels: the measured signal, else the final chart's (the better estimate)
        x = measured.get(at, s1.get(at))
        if e0 is None or e1 is None or x is None:
            continue
        n = e0.shape[0]
        pick = np.sort(rng.choice(n, size=min(n, _MAX_POINTS), replace=False))
        fig, axes = _figure(len(names), 2)
        for i, out_name in enumerate(names):
            for j, (e, title) in enumerate(((e0, "chart as given"), (e1, "final chart"))):
                ax = axes[i, j]
                ax.plot(x[pick], e[pick, i], ".", ms=1.5, color="tab:blue" if j == 0 else "tab:green")
                ax.axhline(0.0, color="0.3", lw=0.6)
                ax.set_xlabel(axis_label(at, units.get(at) or blocks.get(at)))
                ax.set_ylabel(axis_label(f"residual {out_name}", units.get(out_name)))
                ax.set_title(f"{title}: {a['effect']} at {at}", fontsize=9)
        out.append((f"residual_{a['effect']}_{at}.png", fig))
    lags, why = whiteness_lags(diagnosis, train, lags)
    finite = e0 is not None and e1 is not None and np.all(np.isfinite(e0)) and np.all(np.isfinite(e1))
    if finite and e0.shape[0] > lags:
        # the residuals drawn above, over lags that span the final chart's dynamics (REPORT.json's own test
        # keeps MATLAB's 25 lags)
        fig, axes = _figure(len(names), 1)
        k = np.arange(1, lags + 1)
        band = bound(e0.shape[0], LEVEL)
        for i, out_name in enumerate(names):
            ax = axes[i, 0]
            for e, key, color in ((e0, "chart as given", "tab:blue"), (e1, "final chart", "tab:green")):
                ax.plot(k, xcorr(e[:, i], e[:, i], k), "o-", ms=2, lw=0.8, color=color, label=key)
            ax.axhspan(-band, band, color="0.85", label=f"{100 * LEVEL:g} % band ±{band:.3g}")
            ax.set_xlabel(f"lag in samples (one sample = {diagnosis.final.diagram.sample_time:g} s); {lags} lags, "
                          f"{why}")
            ax.set_ylabel(f"autocorrelation {out_name}")
            ax.legend(fontsize=8, loc="upper right")
        out.append(("whiteness.png", fig))
    if resid and e1 is not None:  # MATLAB's resid figure of the final chart, one per output
        u = np.column_stack([s1[n] for n in inputs])
        for j, name in enumerate(names):
            if np.all(np.isfinite(e1[:, j])) and e1.shape[0] >= 3:
                fig = resid_figure(e1[:, j], u, name, inputs, "final chart, training record", units.get(name),
                                   lags, sample_time=diagnosis.final.diagram.sample_time)
                out.append((f"resid_{safe_name(name)}.png", fig))
    return out


def write_plots(diagnosis: Diagnosis, train: Dataset, directory: str | Path, lags: int | None = None) -> list[Path]:
    """Write the figures; returns the paths written. Needs matplotlib (checked by the CLI first)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    return [save_png(fig, directory / name) for name, fig in figures(diagnosis, train, lags=lags)]

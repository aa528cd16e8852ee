"""`sdnn identify --plots DIR`: the figures of the paper for one identification, as PNG files.

What is drawn (file names in DIR):

- ``output.png`` (Fig. 8): measured and model output per output over the training record (free run with
  the identified values) and, below, the cost: per LM iteration offline, the window cost over time online.
- ``residual.png``: measured minus model output over time, per output.
- ``compare.png``: measured and model output (free run) for every training and validation record, fit % and
  RMS in the legend, units from the chart, a zoom on the largest error (:func:`.figures.compare_figure`).
- ``resid_<output>.png`` (training record) and ``resid_validation_<output>.png`` (the validation record, when
  there is one): residual autocorrelation and cross-correlation with each input, 99 % band
  (:func:`.figures.resid_figure`).
- ``parameters.png`` (Fig. 9, online mode only): the physical parameters over time.
- ``curve_<block>.png`` (Figs. 7 and 10): each learned curve y = sum_i v_i tanh(a_i x + b_i) over the range
  of the signal that feeds the block during the record (the range is shaded).

matplotlib is an optional extra (``pip install flowchart2sdnn[plots]``). No pyplot and no global backend:
each figure is rendered by its own Agg canvas to bytes and written with
:func:`~flowchart2sdnn.atomic.atomic_write_bytes`, so a reader never sees half a PNG.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import SdnnError
from ..identify import columns_of, compare_fit, record_theta, signal_units
from .canvas import new_figure, require_matplotlib, save_png
from .figures import axis_label, write_compare, write_resid
from .linear import residual_lags

__all__ = ["write_plots", "curve_input_range", "curve_figure", "resid_inputs"]

# resolving a signal through gains and sums: charts nest only a few levels; the limit guards cycles
_MAX_DEPTH = 32


def _figure(rows: int, width: float = 9.0, height: float = 2.4):
    fig, axes = new_figure(rows, 1, width, height)
    return fig, axes[:, 0]


def _save(fig, path: Path) -> Path:
    return save_png(fig, path)


def _times(outcome) -> np.ndarray:
    problem = outcome.problem
    first = 1 if problem.alignment == "zoh" else 0  # zoh: the fitted rows start at row 1
    return (np.arange(len(problem.targets)) + first) * float(problem.network.sample_time)


def _signal_values(name: str, sign: int, outcome, signals: dict, params: dict, depth: int = 0):
    """The values of chart signal `name` (times `sign`) over the record, or None when it cannot be resolved.

    Neuron signals come straight from the network; gains and sums are folded into weights by the compiler,
    so they are rebuilt from their inputs.
    """
    problem = outcome.problem
    if depth > _MAX_DEPTH:
        return None
    if name in signals:
        return sign * signals[name]
    inputs = [i.name for i in problem.network.inputs]
    if name in inputs:
        return sign * problem.inputs[:, inputs.index(name)]
    block = next((b for b in outcome.diagram.blocks if b.name == name), None)
    if block is None:
        return None
    if block.kind == "nonlinear":
        weights = outcome.curves.get(name)
        parts = [signals.get(f"{name}[{i}]") for i in range(block.neurons or 0)]
        if weights is None or any(p is None for p in parts):
            return None
        return sign * sum(v * p for v, p in zip(weights.v, parts, strict=True))
    if block.kind == "gain" and block.k is not None:
        x = _signal_values(block.inputs[0].signal, block.inputs[0].sign, outcome, signals, params, depth + 1)
        try:
            k = float(block.k.evaluate(params))
        except (ValueError, ArithmeticError):
            return None
        return None if x is None else sign * k * x
    if block.kind == "sum":
        total = 0.0
        for term in block.inputs:
            x = _signal_values(term.signal, term.sign, outcome, signals, params, depth + 1)
            if x is None:
                return None
            total = total + x
        return sign * total if not np.isscalar(total) else None
    return None


def curve_input_range(outcome, block: str) -> tuple[float, float] | None:
    """(min, max) of the signal feeding nonlinear `block` in a free run over the training record, or None."""
    problem = outcome.problem
    b = next(b for b in outcome.diagram.blocks if b.name == block)
    theta = record_theta(outcome, 0)  # the training record's own values, as its fit
    with np.errstate(all="ignore"):
        signals = problem.compiled.signals(theta, problem.inputs, problem.init)
    params, _ = problem.compiled.values(theta)
    term = b.inputs[0]
    x = _signal_values(term.signal, term.sign, outcome, signals, params)
    if x is None:
        return None
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return (float(x.min()), float(x.max())) if x.size else None


def _curve(weights, x: np.ndarray) -> np.ndarray:
    a = np.asarray(weights.a, dtype=float)
    v = np.asarray(weights.v, dtype=float)
    b = np.asarray(weights.b or np.zeros_like(a), dtype=float)
    return np.tanh(np.outer(x, a) + b) @ v


def _plot_output(outcome, t, y, yhat, names, directory: Path) -> Path:
    fig, axes = _figure(len(names) + 1)
    for i, name in enumerate(names):
        ax = axes[i]
        ax.plot(t, y[:, i], color="0.45", lw=0.8, label=f"{name} measured")
        ax.plot(t, yhat[:, i], color="tab:red", lw=0.8, ls="--", label=f"{name} model")
        ax.set_ylabel(name)
        ax.legend(loc="upper right", fontsize="small")
        ax.grid(alpha=0.3)
    axes[len(names) - 1].set_xlabel("time in s")
    ax = axes[-1]
    online = outcome.online
    if online and online.cost:
        ax.plot(online.cost_time, online.cost, color="tab:blue", lw=0.9)
        ax.set_xlabel("time in s")
        ax.set_ylabel("window cost E")
    else:
        history = (outcome.optimizer.cost_history if outcome.optimizer else None) or [outcome.fit.train.cost or 0.0]
        ax.plot(np.arange(len(history)), history, color="tab:blue", marker=".", lw=0.9)
        ax.set_xlabel("LM iteration")
        ax.set_ylabel("cost E")
    if all(c is not None and c > 0 for c in ax.get_lines()[0].get_ydata()):
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    fig.suptitle(f"{outcome.diagram.name}: measured and model output, cost ({outcome.status})")
    return _save(fig, directory / "output.png")


def _plot_residual(t, y, yhat, names, directory: Path) -> Path:
    fig, axes = _figure(len(names))
    for i, name in enumerate(names):
        e = y[:, i] - yhat[:, i]
        axes[i].plot(t, e, color="tab:purple", lw=0.6)
        axes[i].axhline(0.0, color="0.3", lw=0.6)
        rms = float(np.sqrt(np.mean(e**2))) if np.all(np.isfinite(e)) and e.size else float("nan")
        axes[i].set_ylabel(f"{name} residual")
        axes[i].set_title(f"{name}: measured - model, RMS {rms:.4g}", fontsize="medium")
        axes[i].grid(alpha=0.3)
    axes[-1].set_xlabel("time in s")
    return _save(fig, directory / "residual.png")


def _plot_parameters(outcome, directory: Path) -> Path | None:
    online = outcome.online
    physical = [p.name for p in outcome.problem.network.parameters]
    traj = online.trajectories if online else {}
    names = [n for n in physical if n in traj]
    if not names or not online.trajectory_time:
        return None
    fig, axes = _figure(len(names), height=2.0)
    params = outcome.parameters
    for ax, name in zip(axes, names, strict=True):
        ax.plot(online.trajectory_time, traj[name], color="tab:green", lw=0.9)
        ax.axhline(params[name].value, color="0.3", lw=0.6, ls=":", label=f"mean {params[name].value:.5g}")
        unit = params[name].unit
        ax.set_ylabel(f"{name}" + (f" in {unit}" if unit else ""))
        ax.legend(loc="upper right", fontsize="small")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time in s")
    fig.suptitle("parameters during quasi-online identification")
    return _save(fig, directory / "parameters.png")


def curve_figure(outcome, block: str, weights):
    """The learned curve of `block` over the range of the signal feeding it in the training record (shaded)."""
    span = curve_input_range(outcome, block)
    if span is None or not span[1] > span[0]:
        # unknown or constant input: show where the neurons bend (|a x + b| <= 3)
        a = np.abs(np.asarray(weights.a, dtype=float))
        half = 3.0 / max(float(np.min(a[a > 0])) if np.any(a > 0) else 1.0, 1e-12)
        centre = 0.0 if span is None else span[0]
        lo, hi = centre - half, centre + half
    else:
        lo, hi = span
    pad = 0.1 * (hi - lo)
    x = np.linspace(lo - pad, hi + pad, 801)
    fig, axes = _figure(1, width=7.0, height=4.0)
    ax = axes[0]
    ax.plot(x, _curve(weights, x), color="tab:red", lw=1.2)
    if span is not None and span[1] > span[0]:
        ax.axvspan(span[0], span[1], color="tab:blue", alpha=0.08, label="range seen in the record")
        ax.legend(loc="best", fontsize="small")
    b = next(b for b in outcome.diagram.blocks if b.name == block)
    source = str(b.inputs[0])
    units = {**{x.name: x.unit for x in outcome.diagram.blocks}, **signal_units(outcome.diagram)}
    ax.set_xlabel(axis_label(source, units.get(b.inputs[0].signal)))
    ax.set_ylabel(axis_label(block, b.unit))
    ax.grid(alpha=0.3)
    state = "fixed" if weights.fixed else "identified"
    ax.set_title(f"{block} = f({source}), {len(weights.a)} tanh neurons ({state})", fontsize="medium")
    return fig


def _plot_curve(outcome, block: str, weights, directory: Path) -> Path:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", block)
    return _save(curve_figure(outcome, block, weights), directory / f"curve_{safe}.png")


def resid_inputs(data, names, rows: int, alignment: str) -> np.ndarray:
    """The inputs acting on the last `rows` rows of `data` (zoh: input k-1 acts on row k)."""
    u = columns_of(data, names)
    shift = 1 if alignment == "zoh" else 0
    return u[data.n_rows - rows - shift:data.n_rows - shift]


def write_plots(outcome, directory: str | Path, records=(), validation=(), lags: int | None = None) -> list[Path]:
    """Draw the figures of an identification into `directory` (created if needed); return the files written.

    Parameters
    ----------
    outcome : Identification
        What :func:`flowchart2sdnn.identify.offline.run.identify` returned.
    directory : str or Path
        Existing PNGs of the same names are replaced (atomically).
    records, validation : sequences of (label, Dataset, score_from), optional
        The training and validation records to compare the model with in ``compare.png`` (rows before
        `score_from` are run but not shown: a validation after a split). Without them no compare.png.
    lags : int, optional
        Lags of the residual analysis; default spanning the slowest mode of the linearised chart, as the page.

    Returns
    -------
    list of Path
        ``output.png``, ``residual.png``, ``compare.png`` (every record, see :mod:`.figures`),
        ``resid_<output>.png`` (residual analysis on the training record) and
        ``resid_validation_<output>.png`` (on the first validation record, when there is one),
        ``parameters.png`` (online mode), one ``curve_<block>.png`` per learned curve.

    Raises
    ------
    SdnnError
        PLOT001 when matplotlib is missing, PLOT002 when the directory cannot be created.
    """
    require_matplotlib()
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SdnnError.at("PLOT002", f"cannot create the plot directory: {exc.strerror or exc}",
                           str(directory)) from None
    problem = outcome.problem
    names = list(problem.compiled.output_names)
    with np.errstate(all="ignore"):  # the first training record with its own per-record values, as the table
        yhat = problem.compiled.simulate(record_theta(outcome, 0), problem.inputs, problem.init)
    y = problem.targets
    t = _times(outcome)
    written = [_plot_output(outcome, t, y, yhat, names, directory), _plot_residual(t, y, yhat, names, directory)]
    inputs = list(problem.compiled.input_names)
    units = signal_units(outcome.diagram)
    lags, _ = residual_lags(outcome, len(y), lags)
    step = outcome.diagram.sample_time
    written += write_resid(y - yhat, problem.inputs, names, inputs, directory, "training", units, max_lag=lags,
                           sample_time=step)
    every = [*records, *validation]
    if every:
        comparison = compare_fit(outcome, records, validation)
        written.append(write_compare(comparison, directory / "compare.png", outcome.diagram.name))
        if validation:
            rec, (label, data, _) = comparison.records[len(records)], validation[0]
            e = np.column_stack([rec.measured[n] - rec.model[n] for n in names])
            u = resid_inputs(data, inputs, rec.rows, problem.alignment)
            written += write_resid(e, u, names, inputs, directory, label, units, prefix="resid_validation",
                                   max_lag=lags, sample_time=step)
    params_png = _plot_parameters(outcome, directory)
    if params_png is not None:
        written.append(params_png)
    for block, weights in outcome.curves.items():
        written.append(_plot_curve(outcome, block, weights, directory))
    return written

"""Measured against model output, record by record: the numbers behind `sdnn compare` and ``--plots``.

Free run: the identified network driven by the record's inputs from its initial state, as the fit scores it.

k-step-ahead prediction (``horizon = k``): the network's steps over the record are cut into consecutive
segments of k steps. The first segment starts from the model's initial state, as the free run does. Every
later segment restarts from the model's own state at the end of the previous segment, except that the value
of every output neuron is replaced by the measured output of that row; then it runs free for k steps. A
sample j steps after a restart is therefore a j-step-ahead prediction (j = 1..k), and every row is predicted
at most k steps ahead. With outputs that are integrator states (the speeds of a drive) this resets the
measured states; states that are not measured (the twist of a shaft) are carried on by the model, never
estimated from data (there is no observer). ``horizon=1`` predicts each row from the measured row before it;
a horizon as long as the record is the free run. With delays of more than one sample in the chart, the older
samples of a restart's history repeat its last one (the network's history before a run is one vector).

Fit % is 100 (1 - ||y - yhat|| / ||y - mean(y)||) and RMS the root mean square of y - yhat over the scored
rows: the numbers of ``identify``'s fit table (:func:`flowchart2sdnn.identify.offline.problem.metrics`), which they
equal for the free run. :func:`compare_fit` compares a fit's own records as its table scored them (each
training record with its own per-record values, a validation record from its fitted initial state), so a
figure drawn from it shows the table's numbers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..network.alignment import fitted_rows, history_outputs, network_inputs, run_aligned
from ..network.kernels import simulate_kernel
from ..network.runtime import CompiledNetwork
from ..strictjson import finite_or_none
from .offline.initstate import estimate_initial_state
from .offline.problem import columns_of, data_init, network_input_names

__all__ = ["RecordComparison", "Comparison", "predict", "compare_records", "compare_fit", "record_theta",
           "signal_units"]


@dataclass(frozen=True, eq=False)
class RecordComparison:
    """One record: the scored rows' time, measured and model outputs, and RMS / fit % / largest error per output.

    ``model`` holds NaN where the simulation diverged (then the metrics are None).
    """

    label: str
    path: str
    rows: int
    time: np.ndarray
    measured: Mapping[str, np.ndarray]
    model: Mapping[str, np.ndarray]
    rms: Mapping[str, float | None]
    fit_percent: Mapping[str, float | None]
    max_error: Mapping[str, float | None]


@dataclass(frozen=True, eq=False)
class Comparison:
    """Every record compared; ``horizon`` None for the free run; ``units`` output (and input) name -> unit."""

    records: tuple[RecordComparison, ...]
    horizon: int | None
    outputs: tuple[str, ...]
    units: Mapping[str, str | None]

    def table(self) -> list[dict]:
        """One row per record and output: label, output, fit %, RMS, largest |error|, unit, rows."""
        return [{"record": r.label, "output": name, "fit_percent": r.fit_percent[name], "rms": r.rms[name],
                 "max_error": r.max_error[name], "unit": self.units.get(name), "rows": r.rows}
                for r in self.records for name in self.outputs]

    def frame(self):
        """:meth:`table` as a pandas DataFrame when pandas is installed (else the same list of dicts)."""
        from ..tables import frame

        return frame(self.table(), ("record", "output", "fit_percent", "rms", "max_error", "unit", "rows"))

    def __repr__(self) -> str:
        # the records hold whole traces: a notebook cell shows the fit, not the samples
        how = "free run" if self.horizon is None else f"{self.horizon}-step-ahead prediction"
        fits = "; ".join(f"{r['record']} {r['output']} {r['fit_percent']:.4g} %" if r["fit_percent"] is not None
                         else f"{r['record']} {r['output']} diverged" for r in self.table()[:6])
        more = f"; +{len(self.table()) - 6} more (.table())" if len(self.table()) > 6 else ""
        return f"<Comparison, {how}, {len(self.records)} records: fit {fits}{more}>"


def signal_units(diagram: Diagram | None) -> dict[str, str | None]:
    """Unit of every measured signal: the one declared under inputs/outputs, else the block's own."""
    if diagram is None:
        return {}
    blocks = {b.name: b.unit for b in diagram.blocks}
    return {s.name: s.unit or blocks.get(s.name) for s in (*diagram.inputs, *diagram.outputs)}


def predict(compiled: CompiledNetwork, theta: np.ndarray, data: Dataset, alignment: str = "zoh",
            horizon: int | None = None, history: np.ndarray | None = None) -> np.ndarray:
    """Model outputs for every row of `data` (Q, n_outputs): the free run, or the `horizon`-step-ahead
    prediction of the module docstring. Row order and alignment as :func:`~flowchart2sdnn.network.alignment.
    run_aligned` (with zoh, row 0 is the initial state). `history` (every neuron's value before the first step)
    replaces the initial state of a free run."""
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer))
                                or horizon < 1):
        raise ValueError(f"horizon must be a whole number of samples >= 1, not {horizon!r}")
    net = compiled.net
    u = columns_of(data, network_input_names(net))
    init = data_init(net, data)
    p = network_inputs(u, alignment)
    if horizon is None or horizon >= len(p):
        with np.errstate(all="ignore"):
            return run_aligned(compiled, theta, u, alignment, init, history=history)
    if history is not None:
        raise ValueError("a fitted initial state (history) is for the free run, not a k-step prediction")
    y = columns_of(data, compiled.output_names)
    flat = compiled.flat
    with np.errstate(all="ignore"):
        conn, _ = compiled.connection_values(theta)
    every = np.arange(flat.n_neurons, dtype=np.int64)
    first = fitted_rows(data.n_rows, alignment).start  # network step t produces row t + first
    out = np.empty((len(p), compiled.n_outputs))
    hist = last = compiled.initial_history(init, theta)
    with np.errstate(all="ignore"):
        for s in range(0, len(p), horizon):
            if s > 0:
                hist = last.copy()  # the model's state at the end of the previous segment
                hist[flat.output_index] = y[s - 1 + first]
            a = simulate_kernel(np.ascontiguousarray(p[s:s + horizon]), flat.conn_ptr, flat.conn_kind,
                                flat.conn_src, flat.conn_delay, conn, flat.transfer, hist, flat.ring, every)
            out[s:s + len(a)] = a[:, flat.output_index]
            last = a[-1]
    if alignment == "zoh":
        out = np.vstack([history_outputs(net, init)[None, :], out])
    return out


def require_columns(data, names: Sequence[str]) -> None:
    """SdnnError unless `data` is a record (a Dataset) holding every column named: CMP001 naming the record, the
    columns missing and the ones it has (a bare KeyError said only the first name)."""
    if not isinstance(data, Dataset):
        raise SdnnError.at("CMP003", f"a {type(data).__name__} is not a record (Dataset)",
                           hint="make one with read_csv(path) or dataset_from_frame(frame, time=...)")
    missing = [n for n in names if n not in data.columns]
    if missing:
        raise SdnnError.at("CMP001", f"record lacks column(s) {', '.join(missing)} that the chart needs (columns: "
                           f"{', '.join(data.columns) or 'none'})", data.path)


def _one(compiled, theta, label: str, data: Dataset, alignment: str, horizon: int | None,
         score_from: int, history: np.ndarray | None = None) -> RecordComparison:
    require_columns(data, (*network_input_names(compiled.net), *compiled.output_names))
    names = compiled.output_names
    yhat = predict(compiled, theta, data, alignment, horizon, history)
    start = max(score_from, fitted_rows(data.n_rows, alignment).start)
    if start >= data.n_rows:
        raise SdnnError.at("CMP002", f"nothing to score: the record has {data.n_rows} rows, scoring starts at "
                           f"row {start}", data.path)
    rows = np.arange(start, data.n_rows)
    time = (np.asarray(data.time)[rows] if data.time is not None
            else rows * float(data.sample_time or compiled.net.sample_time))
    measured, model, rms, fit, worst = {}, {}, {}, {}, {}
    with np.errstate(all="ignore"):
        for i, name in enumerate(names):
            y = np.asarray(data.columns[name], dtype=float)[start:]
            m = np.where(np.isfinite(yhat[start:, i]), yhat[start:, i], np.nan)
            e = y - m
            measured[name], model[name] = y, m
            finite = bool(np.all(np.isfinite(e)))
            spread = float(np.linalg.norm(y - y.mean()))
            rms[name] = finite_or_none(np.sqrt(np.mean(e**2))) if finite else None
            fit[name] = (finite_or_none(100.0 * (1.0 - np.linalg.norm(e) / spread))
                         if finite and spread > 0 else None)
            worst[name] = finite_or_none(np.max(np.abs(e))) if finite else None
    return RecordComparison(label, data.path, len(rows), time, measured, model, rms, fit, worst)


def compare_records(compiled: CompiledNetwork, theta: np.ndarray,
                    records: Sequence[tuple[str, Dataset, int]], alignment: str = "zoh",
                    horizon: int | None = None, diagram: Diagram | None = None) -> Comparison:
    """Compare the network at `theta` with each record ``(label, data, score_from)``; rows before
    `score_from` are simulated but not scored or shown (a validation after a split)."""
    out = tuple(_one(compiled, theta, label, data, alignment, horizon, score_from)
                for label, data, score_from in records)
    return Comparison(out, horizon, tuple(compiled.output_names), signal_units(diagram))


def record_theta(ident, k: int) -> np.ndarray:
    """The theta training record k (0-based) of the fit `ident` ran with: the identified values, with its own
    values of the per-record parameters (``ident.x`` holds their mean, the identified chart's)."""
    theta = np.array(ident.x, dtype=float)
    names = list(ident.problem.compiled.names)
    for name, rows in (ident.extra.get("parameters_per_record") or {}).items():
        if k < len(rows):
            theta[names.index(name)] = rows[k]["value"]
    return theta


def compare_fit(ident, records: Sequence[tuple[str, Dataset, int]],
                validation: Sequence[tuple[str, Dataset, int]] = (), init_window: int | None = None,
                record_params: Sequence[str] | None = None) -> Comparison:
    """The records of the fit `ident` compared as its fit table scored them (a figure beside the table must
    show the table's numbers).

    `records` are the training records in the order they were fitted, ``(label, Dataset, score_from)``:
    record k runs with :func:`record_theta` (its own per-record values). A `validation` record runs with the
    identified chart (per-record parameters at their mean), or, when the fit had ``init_window`` n, from the
    initial state and per-record values fitted on its first n rows (as identify fitted them: the same
    deterministic fit) and is scored from row n. A caller that scored the validation records itself says how:
    `init_window` (default the fit's own, none after a split) and the per-record parameters fitted on the
    window with the states (`record_params`, default all of them; diagnose fits none).
    """
    problem, settings = ident.problem, ident.settings
    compiled, alignment = problem.compiled, settings.alignment
    out = [_one(compiled, record_theta(ident, k), label, data, alignment, None, score_from)
           for k, (label, data, score_from) in enumerate(records)]
    window = (settings.init_window if settings.split is None else 0) if init_window is None else init_window
    params = problem.record_params if record_params is None else tuple(record_params)
    for label, data, score_from in validation:
        theta, history = ident.x, None
        if window:
            state = estimate_initial_state(compiled, ident.x, data, alignment, window,
                                           data_init(problem.network, data), params=params)
            theta, history, score_from = state.theta, state.history, max(score_from, window)
        out.append(_one(compiled, theta, label, data, alignment, None, score_from, history))
    return Comparison(tuple(out), None, tuple(compiled.output_names), signal_units(ident.chart))

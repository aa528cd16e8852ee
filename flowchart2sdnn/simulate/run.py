"""Run a chart on recorded inputs: as its compiled network (what identification fits) or, with a fine-step ODE
solver, as the chart itself. The library side of `sdnn simulate`.

This module sits above both the chart oracle (:mod:`.continuous`) and the compiler; the oracle itself needs
nothing but the chart.
"""

from __future__ import annotations

import numpy as np

from ..data.csvdata import Dataset
from ..diagram.model import Diagram

__all__ = ["simulation_columns", "simulate_chart"]


def simulation_columns(diagram: Diagram) -> list[str]:
    """The data columns a simulation of `diagram` reads.

    Parameters
    ----------
    diagram : Diagram
        The chart.

    Returns
    -------
    list of str
        Every chart input, then the output of every integrator with ``init: data`` (its first sample is the
        initial state).
    """
    return list(diagram.input_names) + _data_init_outputs(diagram)


def _data_init_outputs(diagram: Diagram) -> list[str]:
    columns = [b.data_column for b in diagram.blocks if b.data_column is not None]
    return list(dict.fromkeys(columns))  # two integrators may start from one output (`measured_by`)


def simulate_chart(diagram: Diagram, data: Dataset, alignment: str = "zoh", continuous: bool = False,
                   all_signals: bool = False) -> dict[str, np.ndarray]:
    """Simulate `diagram` on the inputs in `data` from the chart's values.

    Parameters
    ----------
    diagram : Diagram
        The chart, with the values to simulate (apply a RESULT.json first with
        :func:`flowchart2sdnn.identify.document.apply_result_file` to simulate identified values).
    data : Dataset
        Holds the columns :func:`simulation_columns` names; its time column, if any, is passed through.
    alignment : {"zoh", "direct"}
        zoh: input sample k acts on [t_k, t_k+1) (logged data); direct: output k uses input k. Only for the
        network; the continuous solver always holds each input sample over its interval.
    continuous : bool
        Simulate the chart itself with a fine-step ODE solver instead of its compiled network.
    all_signals : bool
        Return every signal of the chart (network: of every neuron but the output copies), not only the
        outputs. The inputs are not repeated.

    Returns
    -------
    dict of str to ndarray
        ``"time"`` (from `data`, else ``k * sample_time``) first, then the outputs in chart order, then (with
        `all_signals`) the other signals; each of ``data.n_rows`` values. With zoh, row 0 of an internal network
        signal is its initial state, as for the outputs.
    """
    inits = _data_init_outputs(diagram)
    u = np.column_stack([data.columns[n] for n in diagram.input_names])
    init = {n: float(data.columns[n][0]) for n in inits}  # the network's: by data column
    time = data.time if data.time is not None else np.arange(data.n_rows) * diagram.sample_time
    if continuous:
        from .continuous import simulate_continuous

        by_block = {b.name: init[b.data_column] for b in diagram.blocks if b.data_column is not None}
        result = simulate_continuous(diagram, u, init=by_block, signals=all_signals)
        if all_signals:
            return {"time": time, **{k: np.asarray(v) for k, v in result.items() if k not in diagram.input_names}}
        return {"time": time, **{n: result[:, i] for i, n in enumerate(diagram.output_names)}}

    from ..compiler import compile_diagram
    from ..network.alignment import run_aligned
    from ..network.runtime import CompiledNetwork

    net = compile_diagram(diagram).network
    compiled = CompiledNetwork(net)
    theta = compiled.theta0()
    y = run_aligned(compiled, theta, u, alignment, init)
    columns = {"time": time, **{n: y[:, i] for i, n in enumerate(compiled.output_names)}}
    if all_signals:
        from ..network.alignment import network_inputs
        from ..network.flat import flatten, signal_names

        p = network_inputs(u, alignment)
        names = signal_names(net)
        sig = compiled.signals(theta, p, init) if len(p) else {n: np.empty(0) for n in names}
        # zoh: row 0 is the initial state of every neuron (its history), as for the outputs
        history = dict(zip(names, flatten(net).history_with(init), strict=True))
        for name, values in sig.items():
            if name.endswith("__out") or name in columns:
                continue
            columns[name] = np.concatenate([[history[name]], values]) if alignment == "zoh" else values
    return columns

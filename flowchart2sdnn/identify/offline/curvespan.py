"""Where a tanh-basis curve's fixed slopes go: over the range its input covers in the data.

A curve of a measured signal takes that signal's range from the records; any other curve takes it from a free
run of the chart at its `init` with every basis curve flat (v = 0, c = 0: the run does not depend on the
slopes being chosen). The range is the largest |x|: the basis must bend somewhere inside all of the data, or
a part of the curve would be only a straight line.

Layer: identify (below it: compiler, network, diagram).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ...compiler import compile_diagram
from ...data.csvdata import Dataset
from ...diagram.curves import basis_weights, needs_span
from ...diagram.model import Diagram
from ...errors import SdnnError
from ...network.alignment import network_inputs
from ...network.runtime import CompiledNetwork
from .arrays import columns_of, data_init, network_input_names

__all__ = ["with_spans", "input_span"]


def _largest(values) -> float | None:
    v = np.asarray(values, dtype=float)
    v = np.abs(v[np.isfinite(v)])
    return float(v.max()) if v.size and v.max() > 0 else None


def _free_run(diagram: Diagram, data: Dataset, alignment: str) -> dict[str, np.ndarray]:
    network = compile_diagram(diagram).network
    compiled = CompiledNetwork(network)
    u = columns_of(data, network_input_names(network))
    with np.errstate(all="ignore"):
        return compiled.signals(compiled.theta0(), network_inputs(u, alignment), data_init(network, data))


def input_span(diagram: Diagram, signal: str, records: Sequence[Dataset], run: dict | None) -> float | None:
    """The largest |signal| over the records (measured) or the free run `run` (a neuron, or gains of one)."""
    measured = [r.columns[signal] for r in records if signal in r.columns]
    if measured:
        return _largest(np.concatenate([np.asarray(m, dtype=float) for m in measured]))
    if run is None:
        return None
    blocks = {b.name: b for b in diagram.blocks}
    env = diagram.parameter_values()
    env.setdefault("T", float(diagram.sample_time))
    factor = 1.0
    for _ in range(len(blocks) + 1):  # through folded gains to the neuron that carries the signal
        if signal in run:
            return _largest(factor * run[signal])
        b = blocks.get(signal)
        if b is None or b.kind not in ("gain", "delay") or len(b.inputs) != 1:
            return None
        if b.kind == "gain":
            factor *= float(b.k.evaluate(env))
        signal = b.inputs[0].signal
    return None


def with_spans(diagram: Diagram, records: Sequence[Dataset], alignment: str = "zoh") -> tuple[Diagram, dict]:
    """The chart with every tanh-basis curve that lacks slopes set over its input's range; (chart, {block: span})."""
    todo = [b for b in diagram.blocks if b.kind == "nonlinear" and needs_span(b)]
    if not todo or not records:
        return diagram, {}
    flat = {b.name: basis_weights(diagram, b, 1.0) for b in todo}  # v = 0: the run does not see the slopes
    run = None
    if any(not any(b.inputs[0].signal in r.columns for r in records) for b in todo):
        chart = replace(diagram, blocks=tuple(replace(b, weights=flat[b.name]) if b.name in flat else b
                                              for b in diagram.blocks))
        try:
            run = _free_run(chart, records[0], alignment)
        except (ValueError, KeyError, FloatingPointError, SdnnError):  # the fit's own compile will say why
            run = None
    spans, blocks = {}, []
    for b in diagram.blocks:
        if b.name in flat:
            span = input_span(diagram, b.inputs[0].signal, records, run) or 1.0
            spans[b.name] = span
            b = replace(b, weights=basis_weights(diagram, b, span))
        blocks.append(b)
    return replace(diagram, blocks=tuple(blocks)), spans

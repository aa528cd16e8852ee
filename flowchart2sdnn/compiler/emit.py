"""Emit the network file: order neuron blocks into layers and write every connection as a weight."""

from __future__ import annotations

import math

import networkx as nx

from ..analysis.loops import LoopReport
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..expr import MAX_DEPTH, Expr, ExprError, parse_expr
from ..network.model import (
    DelayedEdge,
    FreeWeightSpec,
    InitialState,
    InputSpec,
    LayerSpec,
    Network,
    NeuronSpec,
    OutputSpec,
    ParameterSpec,
    WeightSpec,
)
from .discretize import DiscreteChart, NeuronBlock

__all__ = ["emit_network", "layer_order"]

_MAX_SHORT = MAX_DEPTH  # coefficient texts this short are within every limit of the expression reader


def layer_order(chart: DiscreteChart, loops: LoopReport) -> list[NeuronBlock]:
    """Delay-free topological order of the neuron blocks; ties broken by the loop analysis' search order."""
    rank = {name: i for i, name in enumerate(loops.order)}
    by_name = {nb.name: nb for nb in chart.neuron_blocks}
    g = nx.DiGraph()
    g.add_nodes_from(by_name)
    for nb in chart.neuron_blocks:
        for conns in nb.inputs:
            for c in conns:
                if c.source.kind == "neuron" and c.delay == 0 and c.source.name != nb.name:
                    g.add_edge(c.source.name, nb.name)

    def key(name: str):
        base = name[: -len("__out")] if name.endswith("__out") else name
        return (rank.get(base, len(rank)), name.endswith("__out"), name)

    return [by_name[n] for n in nx.lexicographical_topological_sort(g, key=key)]


def emit_network(diagram: Diagram, chart: DiscreteChart, loops: LoopReport, seed: int = 0,
                 substeps: int = 1) -> Network:
    ordered = layer_order(chart, loops)
    layer_of = {nb.name: m for m, nb in enumerate(ordered)}
    input_index = {s.name: i for i, s in enumerate(diagram.inputs)}
    layers = []
    weights = []
    coefs: list[Expr] = []  # the expression of each weight, for the value check without re-parsing
    initial = []
    for m, nb in enumerate(ordered):
        size = len(nb.transfers)
        names = [nb.name] if size == 1 else [f"{nb.name}[{i + 1}]" for i in range(size)]
        block = nb.name[: -len("__out")] if nb.kind == "readout" else nb.name
        layers.append(LayerSpec(nb.name, tuple(NeuronSpec(n, t, nb.net_input)
                                               for n, t in zip(names, nb.transfers, strict=True)), block, nb.kind))
        for k, conns in enumerate(nb.inputs):
            for c in conns:
                coefs.append(c.coef)
                common = {"layer": m, "row": k, "coef": str(c.coef), "free": c.free,
                          "origin": " -> ".join(c.origin)}
                if c.source.kind == "neuron":
                    weights.append(WeightSpec("LW", source=layer_of[c.source.name], col=c.source.index,
                                              delay=c.delay, **common))
                elif c.source.kind == "input":
                    weights.append(WeightSpec("IW", source=input_index[c.source.name], col=0, delay=c.delay,
                                              **common))
                else:
                    weights.append(WeightSpec("b", source=-1, col=0, delay=0, **common))
        if nb.init is not None:
            for k, value in enumerate(nb.init):
                if value == "data":  # the first sample of the output that measures it (its own, or measured_by)
                    initial.append(InitialState(m, k, 0.0, diagram.block(nb.name).data_column or nb.name))
                elif isinstance(value, str):  # a parameter's name: the start is that parameter
                    initial.append(InitialState(m, k, float(diagram.parameter(value).init), parameter=value))
                elif value:
                    initial.append(InitialState(m, k, float(value)))
    units = {s.name: s.unit for s in diagram.outputs}
    outputs = tuple(OutputSpec(name, layer_of[nb], idx, units.get(name)) for name, nb, idx in chart.outputs)
    parameters = tuple(ParameterSpec(p.name, p.init, p.unit, p.min, p.max, p.fixed) for p in diagram.parameters)
    free = tuple(FreeWeightSpec(name, init, block, role, fixed) for name, block, role, init, fixed in chart.free_weights)
    delayed = tuple(DelayedEdge(u, v, 1, loop) for u, v, loop in loops.delayed_edges)
    net = Network(
        name=diagram.name,
        sample_time=diagram.sample_time,
        inputs=tuple(InputSpec(s.name, s.unit, s.intersample, s.delay) for s in diagram.inputs),
        layers=tuple(layers),
        weights=tuple(weights),
        outputs=outputs,
        parameters=parameters,
        free_weights=free,
        initial_states=tuple(initial),
        delayed_edges=delayed,
        substeps=substeps,
        source={
            "chart": diagram.name,
            "file": diagram.file,
            "sha256": diagram.source_sha256,
            "seed": seed,
            "layer_of_block": {nb.name: m for m, nb in enumerate(ordered)},
        },
    )
    net.verify()
    _check_values(diagram, net, coefs)
    return net


def _check_values(diagram: Diagram, net: Network, coefs: list[Expr]) -> None:
    """Every weight must be a finite number at the initial values, and its text must read back.

    Lint checks each gain; a folded chain of gains (1e200 * 1e200) can still overflow, which is caught here.
    A text of at most MAX_SHORT characters cannot break the reader's limits (each level of nesting and each
    node takes a character), so only longer ones are parsed again: re-parsing all costs a quarter of the
    compile time of a 1000-mass chart.
    """
    env, free = net.parameter_values(), net.free_weight_values()
    for w, expr in zip(net.weights, coefs, strict=True):
        try:
            if len(w.coef) > _MAX_SHORT:
                parse_expr(w.coef)
            value = expr.evaluate(env) * (free[w.free] if w.free is not None else 1.0)
            problem = None if math.isfinite(value) else f"is {value}"
        except ExprError as exc:
            problem = f"cannot be evaluated ({_short(exc.message)})"
        if problem is None:
            continue
        block = net.layers[w.layer].block
        location = diagram.block(block).location if block in diagram.block_names else None
        raise SdnnError.at("COMPILE002", f"the weight along {_short(w.origin)} = {_short(w.coef)} {problem} at "
                           "the parameters' initial values", diagram.file, location.line if location else None,
                           block=block, hint="check the gains and parameter values along this path")


def _short(text: str | None, limit: int = 80) -> str:
    text = text or ""
    return text if len(text) <= limit else text[: limit // 2 - 2] + " ... " + text[-(limit // 2 - 3):]

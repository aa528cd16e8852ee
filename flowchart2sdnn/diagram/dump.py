"""The chart writer beside its reader: a Diagram back to format-1 YAML, and a Diagram with new values.

Layer: diagram (imports only the expression language and errors below it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import yaml

from .blocks import block_type
from .curves import basis_of
from .model import Block, Diagram, NonlinearWeights

__all__ = ["dump_diagram", "with_values"]


def _yaml_number(x: float) -> float | int:
    return int(x) if float(x).is_integer() and abs(x) < 1e15 else float(x)


def _block_dict(b: Block) -> dict:
    d: dict = {"type": b.kind}
    bt = block_type(b.kind)
    operands, keys = bt.operands, bt.keys  # each key written where a kind names it (diagram.blocks)
    if operands != "none":
        terms = [str(t) for t in b.inputs]
        d["in"] = terms if operands == "many" else terms[0]
    if b.k is not None:
        d["k"] = _yaml_number(b.k.evaluate({})) if b.k.is_constant else str(b.k)
    if "init" in keys and b.init not in (None, 0.0):
        d["init"] = b.init if isinstance(b.init, str) else _yaml_number(b.init)
    if "measured_by" in keys and b.measured_by is not None:
        d["measured_by"] = b.measured_by
    if "n" in keys and b.n not in (None, 1):
        d["n"] = b.n
    if "f" in keys:
        d["f"] = b.f
    if "eps" in keys and b.eps is not None:
        d["eps"] = _yaml_number(b.eps)
    if "neurons" in keys:
        d["neurons"] = b.neurons
        d["basis"] = basis_of(b)
        if b.linear is not None:
            d["linear"] = bool(b.linear)
        if b.span is not None:
            d["span"] = _yaml_number(b.span)
        if b.bias:
            d["bias"] = True
        if b.init_range not in (None, (-0.5, 0.5)):
            d["init_range"] = [_yaml_number(x) for x in b.init_range]
        if b.fixed:
            d["fixed"] = True
        if b.weights is not None:
            w = {"a": [float(x) for x in b.weights.a], "v": [float(x) for x in b.weights.v]}
            if b.weights.b is not None and b.bias:
                w["b"] = [float(x) for x in b.weights.b]
            if b.weights.c is not None:
                w["c"] = float(b.weights.c)
            d["weights"] = w
    if b.unit:
        d["unit"] = b.unit
    if b.description:
        d["description"] = b.description
    return d


def dump_diagram(diagram: Diagram, identified: Mapping | None = None) -> str:
    """The chart as format-1 YAML (what `load_diagram` reads back to an equal Diagram)."""
    doc: dict = {"sdnn": 1, "name": diagram.name}
    if diagram.description:
        doc["description"] = diagram.description
    doc["sample_time"] = _yaml_number(diagram.sample_time)
    if diagram.substeps is not None:
        doc["substeps"] = diagram.substeps
    if diagram.delays is not None:
        doc["delays"] = diagram.delays

    def signals(items):
        out = {}
        for s in items:
            spec = {}
            if s.unit:
                spec["unit"] = s.unit
            if s.description:
                spec["description"] = s.description
            if s.intersample != "hold":
                spec["intersample"] = s.intersample
            if s.delay is not None:
                spec["delay"] = s.delay if not _is_number_text(s.delay) else _yaml_number(float(s.delay))
            out[s.name] = spec
        return out

    doc["inputs"] = signals(diagram.inputs)
    doc["outputs"] = signals(diagram.outputs)
    params = {}
    for p in diagram.parameters:
        spec: dict = {"init": _yaml_number(p.init)}
        for key in ("unit", "min", "max"):
            value = getattr(p, key)
            if value is not None:
                spec[key] = _yaml_number(value) if isinstance(value, float) else value
        if p.fixed:
            spec["fixed"] = True
        if p.per_record:
            spec["per_record"] = True
        if p.description:
            spec["description"] = p.description
        params[p.name] = spec
    doc["parameters"] = params
    doc["blocks"] = {b.name: _block_dict(b) for b in diagram.blocks}
    if identified:
        doc["identified"] = dict(identified)
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120, allow_unicode=True)


def with_values(diagram: Diagram, parameters: Mapping[str, float], nonlinear: Mapping[str, Mapping],
                fix: bool = False) -> Diagram:
    """A new chart whose parameter inits and nonlinear weights are the given values (fixed when `fix`)."""
    params = []
    for p in diagram.parameters:
        if p.name in parameters:
            value = float(parameters[p.name])
            lo = p.min if p.min is None or value >= p.min else value
            hi = p.max if p.max is None or value <= p.max else value
            p = replace(p, init=value, min=lo, max=hi, fixed=p.fixed or fix)
        params.append(p)
    blocks = []
    for b in diagram.blocks:
        if b.kind == "nonlinear" and b.name in nonlinear:
            w = nonlinear[b.name]
            b = replace(b, weights=NonlinearWeights(tuple(w["a"]), tuple(w["v"]),
                                                    tuple(w["b"]) if w.get("b") is not None else None,
                                                    None if w.get("c") is None else float(w["c"])),
                        fixed=bool(b.fixed or fix))
        blocks.append(b)
    return replace(diagram, parameters=tuple(params), blocks=tuple(blocks))


def _is_number_text(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True

"""Charts in and out of identification: write a chart back as YAML, apply or fix values from a result file."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import yaml

from ..diagram.model import Block, Diagram, NonlinearWeights
from ..errors import SdnnError

__all__ = ["dump_diagram", "with_values", "load_result", "apply_result_file", "fix_from_result", "RESULT_FORMAT"]

RESULT_FORMAT = "sdnn-result"


def _num(x: float) -> float | int:
    return int(x) if float(x).is_integer() and abs(x) < 1e15 else float(x)


def _block_dict(b: Block) -> dict:
    d: dict = {"type": b.kind}
    if b.kind != "constant":
        terms = [str(t) for t in b.inputs]
        d["in"] = terms if b.kind == "sum" else terms[0]
    if b.k is not None:
        d["k"] = _num(b.k.evaluate({})) if b.k.is_constant else str(b.k)
    if b.kind == "integrator" and b.init not in (None, 0.0):
        d["init"] = b.init if b.init == "data" else _num(b.init)
    if b.kind == "delay" and b.n not in (None, 1):
        d["n"] = b.n
    if b.kind == "function":
        d["f"] = b.f
        if b.eps is not None:
            d["eps"] = _num(b.eps)
    if b.kind == "nonlinear":
        d["neurons"] = b.neurons
        if b.bias:
            d["bias"] = True
        if b.init_range not in (None, (-0.5, 0.5)):
            d["init_range"] = [_num(x) for x in b.init_range]
        if b.fixed:
            d["fixed"] = True
        if b.weights is not None:
            w = {"a": [float(x) for x in b.weights.a], "v": [float(x) for x in b.weights.v]}
            if b.weights.b is not None and b.bias:
                w["b"] = [float(x) for x in b.weights.b]
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
    doc["sample_time"] = _num(diagram.sample_time)

    def signals(items):
        out = {}
        for s in items:
            spec = {}
            if s.unit:
                spec["unit"] = s.unit
            if s.description:
                spec["description"] = s.description
            out[s.name] = spec
        return out

    doc["inputs"] = signals(diagram.inputs)
    doc["outputs"] = signals(diagram.outputs)
    params = {}
    for p in diagram.parameters:
        spec: dict = {"init": _num(p.init)}
        for key in ("unit", "min", "max"):
            value = getattr(p, key)
            if value is not None:
                spec[key] = _num(value) if isinstance(value, float) else value
        if p.fixed:
            spec["fixed"] = True
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
                                                    tuple(w["b"]) if w.get("b") is not None else None),
                        fixed=bool(b.fixed or fix))
        blocks.append(b)
    return replace(diagram, parameters=tuple(params), blocks=tuple(blocks))


def load_result(path: str | Path) -> dict:
    """Read a RESULT.json written by `sdnn identify`; SdnnError naming the file when it is not one."""
    name = str(path)
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SdnnError.at("RES001", "no such file", name) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SdnnError.at("RES001", f"cannot read: {exc}", name) from None
    except json.JSONDecodeError as exc:
        raise SdnnError.at("RES002", f"not JSON: {exc.msg}", name, exc.lineno, exc.colno) from None
    if not isinstance(data, dict) or data.get("format") != RESULT_FORMAT:
        raise SdnnError.at("RES003", f"not an sdnn result file (expected \"format\": \"{RESULT_FORMAT}\")", name)
    params = data.get("parameters")
    nonlinear = data.get("nonlinear", {})
    if not isinstance(params, dict) or not isinstance(nonlinear, dict):
        raise SdnnError.at("RES003", "result file lacks 'parameters' or 'nonlinear' mappings", name)
    for pname, spec in params.items():
        value = spec.get("value") if isinstance(spec, dict) else None
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            raise SdnnError.at("RES003", f"parameter '{pname}' has no finite 'value'", name)
    for bname, w in nonlinear.items():
        if not isinstance(w, dict) or not all(isinstance(w.get(k), list) for k in ("a", "v")):
            raise SdnnError.at("RES003", f"nonlinear block '{bname}' needs weight lists 'a' and 'v'", name)
    return data


def _values(data: dict) -> tuple[dict[str, float], dict[str, dict]]:
    return ({k: float(v["value"]) for k, v in data["parameters"].items()}, dict(data.get("nonlinear", {})))


def apply_result_file(diagram: Diagram, path: str | Path) -> Diagram:
    """The chart with the identified values of a result file (matching names; others unchanged)."""
    params, nonlinear = _values(load_result(path))
    nonlinear = _matching_curves(diagram, nonlinear, str(path))
    return with_values(diagram, params, nonlinear)


def fix_from_result(diagram: Diagram, path: str | Path) -> tuple[Diagram, list[str]]:
    """Take matching parameters and nonlinear blocks from an earlier result and fix them (the paper's stages)."""
    params, nonlinear = _values(load_result(path))
    names = set(diagram.parameter_names)
    params = {k: v for k, v in params.items() if k in names}
    nonlinear = _matching_curves(diagram, nonlinear, str(path))
    if not params and not nonlinear:
        raise SdnnError.at("RES004", "no parameter or nonlinear block name matches the chart", str(path),
                           hint=f"the chart has parameters {', '.join(sorted(names)) or 'none'}")
    return with_values(diagram, params, nonlinear, fix=True), sorted(params) + sorted(nonlinear)


def _matching_curves(diagram: Diagram, nonlinear: dict, path: str) -> dict:
    out = {}
    for b in diagram.blocks:
        if b.kind != "nonlinear" or b.name not in nonlinear:
            continue
        w = nonlinear[b.name]
        if len(w["a"]) != b.neurons or len(w["v"]) != b.neurons:
            raise SdnnError.at("RES005", f"nonlinear block '{b.name}' has {b.neurons} neurons in the chart but "
                               f"{len(w['a'])} in the result", path, block=b.name)
        if b.bias and w.get("b") is None:
            w = {**w, "b": [0.0] * b.neurons}
        if not b.bias:
            w = {k: v for k, v in w.items() if k != "b"}
        out[b.name] = w
    return out

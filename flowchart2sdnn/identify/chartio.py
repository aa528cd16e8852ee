"""Values from a result file into a chart: read RESULT.json, apply or fix its values (the paper's stages)."""

from __future__ import annotations

import json
import math
from pathlib import Path

from ..diagram.dump import with_values
from ..diagram.model import Diagram
from ..errors import SdnnError

__all__ = ["load_result", "apply_result_file", "fix_from_result", "RESULT_FORMAT"]

RESULT_FORMAT = "sdnn-result"


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

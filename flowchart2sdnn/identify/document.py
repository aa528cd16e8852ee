"""RESULT.json: the only writer and reader of the result file format, and values from it into a chart.

:func:`to_document` (written in :mod:`.serialize`, re-exported here) turns an :class:`~flowchart2sdnn.identify.result.Identification` into the document (keys as
they have always been: users' scripts read them), :func:`from_document` reads one back, :func:`dumps` writes it
as strict JSON. :func:`load_result` checks a file, :func:`apply_result_file` and :func:`fix_from_result` put its
values into a chart (``simulate --params``, the paper's stages with ``--fix-from``).

Layer: identify.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from ..atomic import read_json
from ..diagram.dump import with_values
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..notices import Notice
from .result import (
    ChartSource,
    Curve,
    DataInfo,
    Estimate,
    Fit,
    Identification,
    Metrics,
    MultistartSummary,
    OnlineTrace,
    OptimizerTrace,
    RecordInfo,
    Uncertainty,
)
from .serialize import NON_FINITE, RESULT_FORMAT, RESULT_VERSION, dumps, to_document
from .settings import IdentifySettings

__all__ = ["to_document", "from_document", "dumps", "read_result", "load_result", "apply_result_file",
           "fix_from_result", "read_model", "RESULT_FORMAT", "RESULT_VERSION"]

# ------------------------------------------------------------------------------------------------ reading
_KNOWN = {"format", "version", "status", "message", "interrupted", "converged", "parameters", "nonlinear", "fit", "warnings",
          "notices", "settings", "seed", "chart", "data", "versions", "optimizer", "multistart", "uncertainty", "online"}


def _nan(x):
    return math.nan if x is None else x


def _tuple(x):
    return None if x is None else tuple(x)


def _read_metrics(d: dict) -> Metrics:
    records = d.get("records")
    return Metrics(rows=d["rows"], cost=d["cost"], rms=dict(d["rms"]), fit_percent=dict(d["fit_percent"]),
                   records=None if records is None else tuple(_read_metrics(r) for r in records), note=d.get("note"))


def _read_record(d: dict | None) -> RecordInfo | None:
    return None if d is None else RecordInfo(d["file"], d["sha256"], d["rows"], d["max_step_deviation"])


def from_document(doc: dict, chart: Diagram | None = None) -> Identification:
    """An :class:`Identification` from a RESULT.json body (``to_document`` of it gives the body back).

    ``chart`` is the identified chart when it was read too (the ``.chart.yaml`` beside the result).
    """
    s = dict(doc["settings"])
    s["fixed_from"] = tuple(s.get("fixed_from", ()))
    s.setdefault("curve_start", "random")  # a result written before the key existed started from random curves
    s.setdefault("lm_damping", "trainlm")  # ... and one written before lm_damping used trainlm's schedule
    s.setdefault("lm_bounds", "transform")  # ... and one written before lm_bounds kept its bounds by the transform
    settings = IdentifySettings(**s)
    fit = doc["fit"]
    ms = doc.get("multistart")
    unc = doc.get("uncertainty")
    onl = doc.get("online")
    opt = doc.get("optimizer")
    data = doc["data"]
    return Identification(
        status=doc["status"], message=doc["message"], interrupted=doc["interrupted"],
        converged=doc.get("converged"),
        parameters={n: Estimate(_nan(p["value"]), _nan(p["init"]), p["stderr"], _tuple(p["ci95"]), p["unit"],
                                p["fixed"], _tuple(p.get("ci95_noise", p["ci95"])))  # older files: noise only
                    for n, p in doc["parameters"].items()},
        curves={b: Curve(tuple(map(_nan, c["a"])), tuple(map(_nan, c["v"])),
                         None if c.get("b") is None else tuple(map(_nan, c["b"])), c["fixed"],
                         None if c.get("c") is None else _nan(c["c"]))
                for b, c in doc["nonlinear"].items()},
        fit=Fit(_read_metrics(fit["train"]), None if fit["validation"] is None else _read_metrics(fit["validation"])),
        warnings=tuple(w for w in doc["warnings"] if not w.startswith(NON_FINITE)),
        notices=tuple(Notice.from_dict(n) for n in doc.get("notices") or ()),  # older files: uncoded records
        settings=settings, chart=chart,
        source=ChartSource(doc["chart"]["name"], doc["chart"]["file"], doc["chart"]["sha256"]),
        data=DataInfo(_read_record(data["train"]), tuple(_read_record(r) for r in data["train_records"]),
                      _read_record(data["validation"])),
        versions=dict(doc["versions"]),
        optimizer=None if opt is None else OptimizerTrace(
            opt["iterations"], tuple(map(_nan, opt["cost_history"])), opt["nfev"], opt["njev"],
            opt["rejected"]["cost"], opt["rejected"]["diverged"], opt["rejected"]["chatter"]),
        multistart=None if ms is None else MultistartSummary(
            ms["n"], ms["best_index"], tuple(ms["costs"]), tuple(ms["near_best"]), tuple(ms["local_minima"]),
            tuple(ms["diverged"]), tuple(tuple(map(_nan, r)) for r in ms["starts"]), ms["message"],
            _tuple(ms.get("names")), ms.get("cost")),
        uncertainty=None if unc is None else Uncertainty(
            tuple(unc["names"]), tuple(tuple(r) for r in unc["correlation"]), unc["condition_number"],
            tuple(tuple(g) for g in unc["unidentifiable"]), _nan(unc["sigma2"]), unc["residual_lag1"],
            _nan(unc["interval_inflation"]), unc["note"]),
        online=None if onl is None else OnlineTrace(
            onl["window"], onl["average"], onl["every"], onl["steps"], _nan(onl["mean_cost"]),
            {n: _nan(v) for n, v in onl["final"].items()}, tuple(map(_nan, onl["trajectory_time"])),
            {n: tuple(map(_nan, v)) for n, v in onl["trajectories"].items()}, tuple(map(_nan, onl["cost_time"])),
            tuple(map(_nan, onl["cost"]))),
        extra={k: v for k, v in doc.items() if k not in _KNOWN},
    )


def read_result(path: str | Path, chart: Diagram | str | Path | None = None) -> Identification:
    """Read a RESULT.json written by `sdnn identify` as an :class:`Identification`.

    Its ``chart`` (what ``simulate``, ``compare`` and ``linearize`` run) is `chart` when given (a Diagram or a
    chart file), else the identified chart written beside the result (``RESULT.chart.yaml``, or the file its
    ``identified_chart`` key names), else None.
    """
    from ..diagram.validate import load_diagram

    data = load_result(path)
    if chart is None:
        chart = _chart_beside(path, data)
    elif not isinstance(chart, Diagram):
        chart = load_diagram(chart)
    return from_document(data, chart)


def _chart_beside(path: str | Path, data: dict) -> Diagram | None:
    """The identified chart a result names, or the one written beside it (RESULT.chart.yaml), or None."""
    from ..diagram.validate import load_diagram

    # beside the result first: the key holds the path as given on the command line, from wherever that ran
    candidates = [Path(path).with_name(Path(path).stem + ".chart.yaml")]
    named = data.get("identified_chart")
    if isinstance(named, str) and named:
        candidates += [Path(path).parent / Path(named).name, Path(named)]
    for candidate in candidates:
        if candidate.is_file():
            return load_diagram(candidate)
    return None


def read_model(path: str | Path, chart: str | Path | None = None) -> tuple[Diagram, Identification | None]:
    """The identified chart of a RESULT.json (with the result), or a chart file as it is (and None).

    A result's chart is the identified chart written beside it (``RESULT.chart.yaml``, or the file its
    ``identified_chart`` key names); with `chart` given, that chart with the result's values instead.
    """
    from ..diagram.validate import load_diagram

    name = str(path)
    if Path(name).suffix.lower() != ".json":
        return load_diagram(name), None
    data = load_result(name)
    if chart is not None:
        diagram = apply_result_file(load_diagram(chart), name)
    else:
        diagram = _chart_beside(name, data)
        if diagram is None:
            raise SdnnError.at("RES006", "the identified chart beside this result is missing (expected "
                               f"{Path(name).stem}.chart.yaml next to it)", name,
                               hint="give the chart with --diagram, or pass RESULT.chart.yaml itself")
    return diagram, from_document(data, diagram)


def load_result(path: str | Path) -> dict:
    """Read a RESULT.json written by `sdnn identify`; SdnnError naming the file when it is not one."""
    name = str(path)
    data = read_json(path, "RES001", "RES002")
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
    """The chart with the identified values of a result file (matching names; others unchanged), on the network
    they were fitted on where the chart leaves its sub-steps (auto) or delays open."""
    data = load_result(path)
    params, nonlinear = _values(data)
    nonlinear = _matching_curves(diagram, nonlinear, str(path))
    chart = with_values(diagram, params, nonlinear)
    disc = data.get("discretization") if isinstance(data.get("discretization"), dict) else {}
    if chart.substeps in (None, "auto") and isinstance(disc.get("substeps"), int):
        chart = replace(chart, substeps=disc["substeps"])
    if chart.delays is None and isinstance(disc.get("delays"), str):
        chart = replace(chart, delays=disc["delays"])
    return chart


def fix_from_result(diagram: Diagram, source: str | Path | Identification) -> tuple[Diagram, list[str]]:
    """Take matching parameters and nonlinear blocks from an earlier result (a RESULT.json file or an
    :class:`Identification`) and fix them (the paper's stages); also the names taken."""
    if isinstance(source, Identification):
        where = f"the result of chart '{source.source.name}'"
        params = source.values
        nonlinear = {b: {"a": list(c.a), "v": list(c.v), **({"b": list(c.b)} if c.b is not None else {}),
                         **({"c": c.c} if c.c is not None else {})} for b, c in source.curves.items()}
    else:
        where = str(source)
        params, nonlinear = _values(load_result(source))
    names = set(diagram.parameter_names)
    params = {k: v for k, v in params.items() if k in names}
    nonlinear = _matching_curves(diagram, nonlinear, where)
    if not params and not nonlinear:
        raise SdnnError.at("RES004", "no parameter or nonlinear block name matches the chart", where,
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

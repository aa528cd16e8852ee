"""The pieces of identify()'s typed answer made from the raw runs: the fit table's metrics, the learned
curves' weights, the optimizer's and the quasi-online run's traces, RESULT.json's `discretization` and
`shooting`, the records' and the software's identities.

Layer: identify (below it: analysis, data, fit).
"""

from __future__ import annotations

import platform
from dataclasses import replace

import numpy as np

from ..._version import __version__
from ...analysis.loops import delay_rule
from ...data.csvdata import Dataset
from ...fit.lm import LMResult
from ..result import Fit, Metrics, OnlineTrace, OptimizerTrace, RecordInfo
from ..settings import IdentifySettings
from ..shooting.multiple import kept_stage
from .initstate import estimate_initial_state
from .problem import Problem, combined_metrics, data_init, metrics

__all__ = ["discretization", "shooting_extra", "resolved_chart", "fit_of", "curves_of", "optimizer_trace",
           "online_trace", "detail", "record_info", "versions"]


def discretization(diagram, network) -> dict:
    """RESULT.json's `discretization`: the sub-steps asked for and used, the step, the delay rule (identify adds
    `floor`, the network against the continuous chart: :mod:`flowchart2sdnn.identify.assess.floor`)."""
    return {"substeps": network.substeps, "requested": diagram.substeps, "sample_time": network.sample_time,
            "step": network.step, "delays": delay_rule(diagram)}


def shooting_extra(settings: IdentifySettings, lm: LMResult | None, auto=None) -> dict:
    """RESULT.json's `shooting`: the segment length used (`auto`: what the rule chose and why), the best start's
    stages, and which stage's fit is the result (`final_length`; `predictable` false when a merge was refused:
    a chaotic record, validated on short horizons only; identify.shooting.multiple)."""
    stages = [{k: None if isinstance(v, float) and not np.isfinite(v) else v for k, v in s.items()}
              for s in lm.stages] if lm is not None else []  # a diverged stage's cost is inf: JSON has no inf
    out = {"length": settings.shooting, "requested": "auto" if auto is not None else settings.shooting,
           "starts": settings.shooting_starts,
           **({"auto": auto.to_dict()} if auto is not None else {}), "stages": stages,
           "method": "multiple shooting, segments merged x4, continuity weight x10 per stage, then single "
                     "shooting over whole records (the result, unless it costs more than 1.44x per sample than "
                     "the last accepted stage while that stage is within 2x the noise: then that stage; a "
                     "stage refused so is passed over)"}
    kept = kept_stage(stages)
    if kept is not None:
        out["final_length"] = kept["length"]
        out["predictable"] = kept is stages[-1]
        if not out["predictable"]:
            out["note"] = (f"multiple shooting: a free run of the fitted chart does not follow the whole records "
                           f"(merging segments of {kept['length']} samples raised the cost per sample "
                           f"{_rise(stages[-1], kept)}); the parameters come "
                           f"from the stage with segments of {kept['length']} samples, and the fit is "
                           f"validated on horizons of up to {kept['length']} samples only (the training and "
                           f"validation RMS of whole-record free runs are not its measure)")
    return out


def _rise(stage: dict, kept: dict) -> str:
    """How much costlier per sample the whole-record stage was than the kept one (for the note)."""
    a, b = stage.get("cost_per_sample"), kept.get("cost_per_sample")
    return f"{a / b:.3g}x" if a is not None and b else "beyond floating point: it diverged"


def resolved_chart(chart, network):
    """The identified chart naming the network it was fitted with: `substeps: auto` (given or by default)
    replaced by the N used (auto depends on the parameter values) and the delay rule written out (a default may
    change; the identified values belong to this network)."""
    if chart.substeps in (None, "auto"):
        chart = replace(chart, substeps=network.substeps)
    return chart if chart.delays is not None else replace(chart, delays=delay_rule(chart))


def fit_of(problem: Problem, x, settings: IdentifySettings, train: Dataset, more: list[Dataset], full: Dataset,
         validation: Dataset | None):
    """(Fit, the validation record's fitted initial state or None). `x` holds each training record's own
    values of the per-record parameters; a validation record runs with their mean, or with its own values
    fitted on its initial-state window."""
    xs, x = x, problem.mean_x(x)
    train_m = metrics(problem.compiled, problem.record_x(xs, 0), train, settings.alignment)
    if more:
        per_record = [train_m] + [metrics(problem.compiled, problem.record_x(xs, k), d, settings.alignment)
                                  for k, d in enumerate(more, start=1)]
        train_m = combined_metrics(per_record, problem, xs, [train] + more, settings.alignment)
    val = None
    if settings.split is not None:
        val = metrics(problem.compiled, x, full, settings.alignment, score_from=train.n_rows)
        val["note"] = "free run over the whole record, scored after the split"
    elif validation is not None and settings.init_window:
        state = estimate_initial_state(problem.compiled, x, validation, settings.alignment, settings.init_window,
                                       data_init(problem.network, validation), params=problem.record_params)
        val = metrics(problem.compiled, state.theta, validation, settings.alignment, score_from=settings.init_window,
                      history=state.history)
        val["note"] = (f"free run from the initial state fitted on the first {settings.init_window} samples, "
                       f"scored from row {settings.init_window}")
        return Fit(_metrics(train_m), _metrics(val)), state
    elif validation is not None:
        val = metrics(problem.compiled, x, validation, settings.alignment)
    return Fit(_metrics(train_m), None if val is None else _metrics(val)), None


def _metrics(d: dict) -> Metrics:
    records = d.get("records")
    return Metrics(d["rows"], d["cost"], d["rms"], d["fit_percent"],
                   None if records is None else tuple(_metrics(r) for r in records), d.get("note"))


def curves_of(problem: Problem, x: np.ndarray) -> dict[str, dict]:
    """Learned curve weights per block, as the chart writer takes them: {"a": [...], "v": [...], "b"?: [...]}."""
    _, free = problem.compiled.values(x)
    out: dict[str, dict] = {}
    for fw in problem.network.free_weights:
        if fw.block is None or fw.role is None:
            continue
        entry = out.setdefault(fw.block, {"a": [], "v": [], "b": [], "fixed": True})
        entry["fixed"] = entry["fixed"] and fw.fixed  # a basis's fixed slopes leave the curve learned
        if fw.role == "c":
            entry["c"] = float(free[fw.name])
        else:
            entry[fw.role].append(float(free[fw.name]))
    for entry in out.values():
        if not entry["b"]:
            del entry["b"]
    return out


def optimizer_trace(lm: LMResult) -> OptimizerTrace:
    return OptimizerTrace(lm.iterations, tuple(lm.cost_history), lm.nfev, lm.njev, lm.rejected_cost,
                          lm.rejected_diverged, lm.rejected_guard)


def online_trace(run, names, settings: IdentifySettings) -> OnlineTrace:
    return OnlineTrace(
        window=settings.window, average=settings.average, every=settings.every, steps=int(run.steps),
        mean_cost=float(run.mean_cost), final={n: float(v) for n, v in zip(names, run.theta_final, strict=True)},
        trajectory_time=tuple(float(t) for t in run.trajectory_time),
        trajectories={n: tuple(float(v) for v in run.trajectory[:, i]) for i, n in enumerate(names)},
        cost_time=tuple(float(t) for t in run.cost_time), cost=tuple(float(c) for c in run.cost))


def detail(message: str) -> str:
    """The parenthesised details of a trainer message ("... (iteration 3, cost 1.2, mu 0.1)")."""
    at = message.find(" (")
    return message[at:] if at >= 0 else ""


def record_info(ds: Dataset) -> RecordInfo:
    return RecordInfo(ds.path, ds.sha256, ds.n_rows, ds.max_step_deviation)


def versions() -> dict:
    import networkx
    import numba
    import scipy

    return {"sdnn": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__, "networkx": networkx.__version__}

"""The discretization floor of a fitted chart: how far its network is from the continuous chart it stands for.

The network is the chart discretized (implicit Euler forward, a one-step delay in every loop, step h = T/N).
Its own error against the continuous chart, with the *identified* values, is a floor under every residual: a
fit cannot tell it from the machine and bends the parameters to absorb it (two-mass bench at N = 1: d −25 %).
The floor is measured with the independent oracle (:func:`~flowchart2sdnn.simulate.continuous.simulate_continuous`,
RK4 at fine steps, reading only the chart) on the same inputs, from the same initial states, on the rows the
fit scores, and reported per output beside the residual RMS.

Layer: identify (below it: simulate's oracle, network, data, diagram).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ... import rules
from ...analysis.loops import delay_rule
from ...data.csvdata import Dataset
from ...diagram.model import Diagram
from ...network.alignment import fitted_rows, run_aligned
from ...notices import Notice
from ..offline.problem import columns_of, data_init, network_input_names

__all__ = ["FLOOR_WARN", "oracle_steps", "oracle_rows", "oracle_runs", "measure_floor", "floor_warnings",
           "pooled_floor"]

#: Warn when the floor on an output exceeds this fraction of its residual RMS: from there on the network's own
#: error is a visible part of what the fit calls model error (at 20 % of the RMS it is 4 % of the squared
#: residual the parameters are fitted to).
FLOOR_WARN = rules.value("floor_warn")
#: RK4 steps of the oracle per network step (at least 20 per sample, as `simulate --continuous`): RK4's error
#: falls as h^4, so on any mode the network resolves (omega*h <= 0.01 with `auto`) it is 1e-8 of the signal.
_ORACLE_PER_STEP = rules.value("oracle_per_step")
_ORACLE_MIN = rules.value("oracle_min")


def oracle_steps(substeps: int) -> int:
    """RK4 steps per sample of the oracle for a network of `substeps` steps per sample."""
    return max(_ORACLE_MIN, _ORACLE_PER_STEP * int(substeps))


def _oracle_init(chart: Diagram, data: Dataset) -> dict[str, float]:
    """`init: data` integrators start at the record's first sample of their output's column (as `sdnn simulate`)."""
    return {b.name: float(data.columns[b.data_column][0]) for b in chart.blocks if b.data_column is not None}


def oracle_rows(chart: Diagram, data: Dataset, alignment: str, steps: int, names: Sequence[str]) -> np.ndarray:
    """The oracle's outputs `names` on every row of `data`, row k where the network's row k stands (Q, len(names))."""
    from ...simulate.continuous import simulate_continuous

    u = columns_of(data, chart.input_names)
    if alignment == "zoh":  # row k of both is the chart at t_k, input k held over [t_k, t_k+1)
        y_or = simulate_continuous(chart, u, init=_oracle_init(chart, data), substeps=steps)
    else:  # direct: the network's row k has seen input k for one sample, the oracle's row k + 1
        y_or = simulate_continuous(chart, np.vstack([u, u[-1:]]), init=_oracle_init(chart, data), substeps=steps)[1:]
    return y_or[:, [chart.output_names.index(n) for n in names]]


def oracle_runs(chart: Diagram, records: Sequence[Dataset], alignment: str, compiled) -> list[np.ndarray]:
    """The oracle's run of `chart` on every record (:func:`oracle_rows` at the network's steps, its output
    order): computed once where the floor and the bias (identify.assess.floorbias) both need it."""
    steps = oracle_steps(compiled.net.substeps)
    return [oracle_rows(chart, d, alignment, steps, compiled.output_names) for d in records]


def _one(chart: Diagram, compiled, x, data: Dataset, alignment: str, score_from: int, steps: int,
         y_or: np.ndarray | None = None) -> np.ndarray:
    """Network minus oracle on one record's scored rows, (rows, n_outputs) in the network's output order."""
    u_net = columns_of(data, network_input_names(compiled.net))
    y_net = run_aligned(compiled, x, u_net, alignment, data_init(compiled.net, data))
    if y_or is None:
        y_or = oracle_rows(chart, data, alignment, steps, compiled.output_names)
    start = max(score_from, fitted_rows(data.n_rows, alignment).start)
    return y_net[start:] - y_or[start:]


def measure_floor(chart: Diagram, compiled, x, records: Sequence[tuple[Dataset, int]], alignment: str,
                  oracle: Sequence[np.ndarray] | None = None) -> dict:
    """The floor on `records` ((record, first scored row)): ``{"rms": {output: RMS}, "rows", "records",
    "oracle"}``, or ``{"rms": None, "skipped": why}`` where the oracle cannot run the chart or a run diverges.

    `chart` is the chart with the values `x` stands for (the identified chart); `compiled` its network;
    `oracle` the oracle's runs on the records when already computed (:func:`oracle_runs`).
    """
    steps = oracle_steps(compiled.net.substeps)
    runs = oracle if oracle is not None else [None] * len(records)
    try:
        diffs = [_one(chart, compiled, x, d, alignment, s, steps, y) for (d, s), y in zip(records, runs, strict=True)]
    except (ValueError, KeyError) as exc:  # the oracle's refusals (e.g. a blow-up) are ValueErrors
        return {"rms": None, "skipped": f"the continuous oracle cannot run this chart: {exc}"}
    e = np.vstack(diffs)
    if not np.all(np.isfinite(e)):
        return {"rms": None, "skipped": "the network diverges on these records"}
    if not len(e):
        return {"rms": None, "skipped": "no scored rows"}
    with np.errstate(over="ignore", invalid="ignore"):
        rms = np.sqrt(np.mean(e**2, axis=0))
    if not np.all(np.isfinite(rms)):  # RESULT.json is strict JSON: no inf from a square that overflows
        return {"rms": None, "skipped": "the difference is too large to square (a run near overflow)"}
    return {"rms": {n: float(v) for n, v in zip(compiled.output_names, rms, strict=True)}, "rows": int(len(e)),
            "records": len(records),
            "oracle": f"simulate_continuous of the identified chart, RK4 with {steps} steps per sample"}


def pooled_floor(floor: dict) -> float | None:
    """The floor over all outputs at once (the RMS of every difference), as diagnose pools its validation RMS."""
    rms = floor.get("rms")
    if not rms:
        return None
    return math.sqrt(sum(v * v for v in rms.values()) / len(rms))


def floor_warnings(floor: dict, residual_rms, chart: Diagram | None, network) -> list[Notice]:
    """A warning per output whose floor exceeds FLOOR_WARN of its residual RMS, with what to change."""
    rms = floor.get("rms")
    if not rms:
        return []
    over, worst, shares = [], 0.0, {}
    for name, f in rms.items():
        r = residual_rms.get(name)
        if r is None or not math.isfinite(r):
            continue
        if f > FLOOR_WARN * r:
            over.append(f"{name} {f:.3g} ({'inf' if r == 0 else f'{100 * f / r:.0f}'} % of its residual RMS {r:.3g})")
            worst = max(worst, f / r if r > 0 else math.inf)
            shares[name] = {"floor": f, "residual_rms": r, "share": f / r if r > 0 else math.inf}
    if not over:
        return []
    n = network.substeps
    # the schemes are first order: the floor falls about as 1/N; aim at half the warning level, a power of two
    # (`auto` is no answer here: it reads the modes at the chart's init, and a fit can end far faster, e.g. a
    # learned friction curve that became steep at zero speed)
    need = n * worst / (FLOOR_WARN / 2) if math.isfinite(worst) else 2 * n
    suggest = max(2 * n, 2 ** math.ceil(math.log2(max(need, 1.0))))
    advice = [f"`substeps: {suggest}` in the chart (or --substeps {suggest}; the floor falls about as 1/N)"]
    if chart is None or delay_rule(chart) not in ("torques", "midpoint"):
        advice.append("`delays: torques`")
    use = ' and '.join(advice)
    return [Notice("FLOOR001", f"the discretization floor (the network against the continuous chart, identified "
                   f"values, training input) is more than {100 * FLOOR_WARN:.0f} % of the residual on "
                   f"{'; '.join(over)}: that part of the residual is the network's own step error, and the "
                   f"parameters absorb it; use {use}",
                   {"warn_at": FLOOR_WARN, "outputs": shares, "substeps": n, "suggested_substeps": suggest},
                   f"use {use}")]

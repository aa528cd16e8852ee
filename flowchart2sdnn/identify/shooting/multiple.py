"""Multiple shooting (``--shooting L``): the training records cut into segments, merged until single shooting.

The simulation-error cost of a lightly damped or chaotic drive grows exponentially rougher with the horizon
(Ribeiro et al., Automatica 2020): from a rough start, a free run over a long record follows the data only
for a while, and LM lands in one of many local minima. Short segments, each started from the data, keep every
simulation close to the record, and the cost over them is smooth.

Each record is cut into segments of L samples. A segment's initial state is the value before its first step
of every integrator neuron (identify.offline.initstate.state_neurons): measured ones from the data at that sample,
unmeasured ones (a shaft twist, the speed of an unmeasured mass) free quantities fitted with the parameters.
A record's first segment starts from the record's own initial state, as in single shooting. Other delayed
neurons (a friction read one step late) keep the chart's initial value at every segment start; the free
states absorb that one-step inconsistency, and it vanishes with the last stage.

The residual is the outputs' error on every segment followed by, for each free state and each segment
boundary, ``weight * (end of the segment - start of the next)``. Stages: at lengths L, 4L, 16L, ... (while
shorter than the longest record) one LM fit each, the continuity weight 10 times larger at each stage; the
free starts of the merged segments are taken over from the previous stage. The last stage is the ordinary
simulation error over whole records (Problem.fun), and its fit is the result.

Chaotic records (backlash, cogging): a free run of the fitted chart may not follow a long record at all, and
the longer stages then climb far above the shorter ones' cost. A merge is refused when both

* the merged stage's output cost per sample (continuity rows left out) exceeds MERGE_RISE times the stage
  before's: MERGE_RISE = 1.44 is a rise of the residual RMS by 20 %, what the long-record acceptance calls
  failing (validation within 1.2 times the noise, issue 14), and
* the stage before is at the noise floor: its residual RMS is at most NOISE_MARGIN times the noise estimated
  from the records' high-frequency content (:func:`noise_level`). This tells unpredictability from model
  error: a chart that lacks an effect (one-mass friction bench, diagnose's chart as given) already misses the
  short segments by more than the noise, and its cost grows with the horizon too; merging it must go on to
  single shooting, where the missing effect shows, as before this rule.

A refused stage is passed over: the next length starts again from the last accepted stage (its parameters
and free starts), so one stage whose fit went astray (cogging bench, auto's L = 1421: the 5684-sample stage
ended at its 100-iteration limit 175 times costlier, yet single shooting from the 1421 stage follows the
whole record) does not end the merging. When single shooting too is refused, the last accepted stage is the
result: its parameters, its segment length reported. A smooth,
correct chart's stages all end near the noise floor and later stages cost the same or less (cogging bench,
30 s, L = 200: 6.5, 5.0, 4.1, 4.4 then 3.1 for single shooting), so nothing is refused. The result then says so (its stages' `kept`, RESULT.json `shooting.final_length`
and a warning): validation of such a fit is meaningful on horizons up to that length only.

Layer: identify (below it: fit, network). The segmented problem of a stage is :mod:`.segmented`'s, the
noise floor :mod:`flowchart2sdnn.identify.assess.noise`'s.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import sparse

from ... import rules
from ...fit.lm import LMOptions, LMResult, levenberg_marquardt
from ..assess.noise import NOISE_MARGIN, noise_cost
from ..offline.problem import Problem
from .segmented import Segmented

__all__ = ["shooting_fit", "stage_lengths", "kept_stage", "GROWTH", "WEIGHT_GROWTH", "STAGE_MAX_ITER", "MERGE_RISE",
           "RESEAT_RATIO", "RESEAT_ROUNDS", "reseat"]

#: Segment length factor from one stage to the next (boundaries of a stage are boundaries of the one before,
#: so its free starts carry over).
GROWTH = rules.value("segment_growth")
#: Continuity weight factor from one stage to the next.
WEIGHT_GROWTH = rules.value("weight_growth")
#: LM iterations of a multiple-shooting stage at most (and max_iter): a stage only warms the next one up, and on
#: the Coulomb bench a stage of 2 segments crawled 604 iterations for a 0.01 % lower cost.
STAGE_MAX_ITER = rules.value("stage_max_iter")
#: A segment whose outputs' mean squared error exceeds this many times the stage's median segment's (its RMS
#: twice the median's) has its free start reseated from the segment before (:func:`reseat`) ...
RESEAT_RATIO = rules.value("reseat_ratio")
#: ... and the stage refitted, at most this many times (while that lowers its cost).
RESEAT_ROUNDS = rules.value("reseat_rounds")
#: A merge is refused when it raises the output cost per sample more than this (RMS +20 %; module docstring),
#: from a stage at the noise floor (NOISE_MARGIN of :mod:`flowchart2sdnn.identify.assess.noise`).
MERGE_RISE = rules.value("merge_rise")


def stage_lengths(length: int, longest: int) -> list[int]:
    """The multiple-shooting segment lengths: L, 4L, ... while shorter than the longest record."""
    out = []
    while length < longest:
        out.append(length)
        length *= GROWTH
    return out



def _dense(a) -> np.ndarray:
    return a.toarray() if sparse.issparse(a) else np.array(a)



def _state_scale(problem: Problem, theta: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Each free state's RMS over the records' free runs at theta (1 where that says nothing)."""
    if not len(free):
        return np.ones(0)
    with np.errstate(all="ignore"):
        runs = [problem.compiled.simulate(theta, s.inputs, s.init, states=free)[:, problem.compiled.n_outputs:]
                for s in problem.segments]
        rms = np.sqrt(np.mean(np.vstack(runs) ** 2, axis=0))
    return np.where(np.isfinite(rms) & (rms > 0), rms, 1.0)


def shooting_fit(problem: Problem, start: np.ndarray, lower, upper, options: LMOptions, length: int,
                 callback=None, guard=None, threads: int = 1, starts: str = "data") -> LMResult:
    """Multiple-shooting stages from `start`, then single shooting (problem.fun) from their result.

    Returns the last accepted stage's LMResult (the result: single shooting unless a merge was refused, see the
    module docstring) with a summary of every stage in its `stages` (RESULT.json `shooting`), the result's
    marked ``kept``.
    """
    longest = max(len(s.inputs) for s in problem.segments)
    lengths = stage_lengths(length, longest)
    theta = np.asarray(start, dtype=float)
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    carried, stages, scale = None, [], None
    m = sum(s.targets.size for s in problem.segments)
    before = None  # (output cost per sample, the stage's result in theta's terms) of the last accepted stage
    floor = noise_cost(problem, NOISE_MARGIN)  # a stage's cost per sample at the noise floor
    for i, L in enumerate(lengths):
        seg = Segmented(problem, L, WEIGHT_GROWTH ** i, scale, threads, starts)
        if scale is None:  # the states' sizes at the start, kept over the stages (the weights grow alone)
            scale = seg.scale = _state_scale(problem, theta, seg.free)
            seg.row_weight = seg.weight * np.sqrt(seg.length) / scale
        x0 = seg.start(theta, carried)
        free = seg.n_x - seg.n_theta
        opts = replace(options, scale_groups=seg.scale_groups(options.scale_groups),
                       max_iter=min(options.max_iter, STAGE_MAX_ITER),
                       stall_decrease=options.stall_decrease * problem.n_residuals / max(1, m + free),
                       crawl_decrease=0.0)  # the crawl rule reads the whole records' cost: the last stage's
        bounds = (np.concatenate([lower, np.full(free, -np.inf)]), np.concatenate([upper, np.full(free, np.inf)]))

        def fit(x, seg=seg, opts=opts, bounds=bounds):
            return levenberg_marquardt(seg.fun, x, seg.names, *bounds, opts, callback=callback,
                                       guard=None if guard is None else (lambda x, n=seg.n_theta: guard(x[:n])),
                                       residual=seg.residual)
        r, reseated = _fit_reseating(seg, fit, x0)
        per = seg.output_cost(r.x) / max(1, m)
        stages.append({"length": L, "segments": len(seg.pieces), "free_states": int(free),
                       "weight": seg.weight, "iterations": r.iterations, "cost": r.cost, "status": r.status,
                       "cost_per_sample": per if np.isfinite(per) else None, "reseated": reseated})
        own = replace(r, x=np.array(r.x[:seg.n_theta]), names=tuple(problem.names),
                      jac=_dense(r.jac[:, :seg.n_theta]))
        if r.interrupted or r.status in ("callback_stop", "diverged_at_start"):
            if r.status == "diverged_at_start":
                break
            return replace(own, stages=tuple(stages))
        if _refuse(before, per, floor):  # the next stage starts again from the accepted one
            stages[-1]["refused"] = True
            continue
        before = (per, (own, i))
        theta, carried = np.array(r.x[:seg.n_theta]), seg.starts_of(np.asarray(r.x))
    final = levenberg_marquardt(problem.fun, theta, problem.names, lower, upper, options, callback=callback,
                                guard=guard, residual=problem.residual)
    per = final.cost / max(1, m)
    stages.append({"length": longest, "segments": len(problem.segments), "free_states": 0, "weight": None,
                   "iterations": final.iterations, "cost": final.cost, "status": final.status,
                   "cost_per_sample": per if np.isfinite(per) else None})
    if not final.interrupted and _refuse(before, per, floor):
        stages[-1]["refused"] = True
        result, index = before[1]
        stages[index]["kept"] = True
        return replace(result, stages=tuple(stages))
    stages[-1]["kept"] = True
    return replace(final, stages=tuple(stages))


def _fit_reseating(seg: Segmented, fit, x0: np.ndarray):
    """(the stage's LMResult, segments reseated): `fit` from x0, then up to RESEAT_ROUNDS times from the same
    point with the outlying segments' starts reseated (:func:`reseat`), kept while that lowers the cost."""
    r = fit(x0)
    total, iterations = 0, r.iterations
    for _ in range(RESEAT_ROUNDS):
        if r.interrupted or r.status in ("callback_stop", "diverged_at_start") or not np.isfinite(r.cost):
            break
        x, count = reseat(seg, np.asarray(r.x, dtype=float))
        if not count:
            break
        again = fit(x)
        iterations += again.iterations
        if again.interrupted or not again.cost < r.cost:
            r = again if again.interrupted else r
            break
        r, total = again, total + count
    return replace(r, iterations=iterations), total


def reseat(seg: Segmented, x: np.ndarray) -> tuple[np.ndarray, int]:
    """(x with each outlying segment's free start set to the previous segment's end state, how many).

    A segment is outlying when its outputs' mean squared error exceeds RESEAT_RATIO times the median segment's
    while the segment before it (same record) does not: its free start settled in a local minimum of its own
    (the backlash bench: 7 of 255 segments of 118 samples at 4-66x the median with the shaft twist on the
    wrong side of the gap), which the continuity rows' small weight of the early stages does not pull it out
    of. The good neighbour's end state is where the record passes at that boundary."""
    n_out = seg.problem.compiled.n_outputs
    runs = list(seg._runs(x, False))
    ms = np.array([float(np.mean((seg.problem.segments[p.record].targets[p.a:p.b] - y[:, :n_out]) ** 2))
                   for p, y, _ in runs])
    if not np.all(np.isfinite(ms)) or len(ms) < 3:
        return x, 0
    high = ms > RESEAT_RATIO * np.median(ms)
    out, count, S = np.array(x, dtype=float), 0, len(seg.free)
    for i, (p, _y, _) in enumerate(runs):
        if p.column >= 0 and high[i] and not high[i - 1] and runs[i - 1][0].record == p.record:
            out[p.column:p.column + S] = runs[i - 1][1][-1, n_out:]
            count += 1
    return out, count


def _refuse(before: tuple | None, per: float, floor: float) -> bool:
    """Whether a stage of output cost per sample `per` is refused after the accepted stage `before`."""
    return before is not None and before[0] <= floor and not per <= MERGE_RISE * before[0]


def kept_stage(stages) -> dict | None:
    """The stage whose fit is the result (None for a plain fit)."""
    return next((s for s in stages if s.get("kept")), None)

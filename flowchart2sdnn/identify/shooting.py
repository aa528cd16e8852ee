"""Multiple shooting (``--shooting L``): the training records cut into segments, merged until single shooting.

The simulation-error cost of a lightly damped or chaotic drive grows exponentially rougher with the horizon
(Ribeiro et al., Automatica 2020): from a rough start, a free run over a long record follows the data only
for a while, and LM lands in one of many local minima. Short segments, each started from the data, keep every
simulation close to the record, and the cost over them is smooth.

Each record is cut into segments of L samples. A segment's initial state is the value before its first step
of every integrator neuron (identify.initstate.state_neurons): measured ones from the data at that sample,
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

Sensitivities: exact, by the RTRL kernel with the history's own sensitivities (kernels.jacobian_kernel's
`s_init`): the free starts are extra columns of theta whose initial sensitivity is the identity. Each segment
is simulated from its own start, the segments of a record in one kernel call (one per thread,
CompiledNetwork.run_pieces); the Jacobian has segments x free states extra columns, sparse, and the number of
segments is capped (MAX_SEGMENTS).

Layer: identify (below it: fit, network).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ..errors import SdnnError
from ..fit.lm import LMOptions, LMResult, levenberg_marquardt
from .initstate import state_neurons
from .problem import Problem, _interruptible

__all__ = ["Segmented", "shooting_fit", "stage_lengths", "kept_stage", "MAX_SEGMENTS", "GROWTH", "WEIGHT_GROWTH",
           "STAGE_MAX_ITER", "MERGE_RISE", "RESEAT_RATIO", "RESEAT_ROUNDS", "reseat", "NOISE_MARGIN", "noise_level"]

#: Segments of one stage at most: the Jacobian has (free states x segments) extra dense columns.
MAX_SEGMENTS = 256
#: Segment length factor from one stage to the next (boundaries of a stage are boundaries of the one before,
#: so its free starts carry over).
GROWTH = 4
#: Continuity weight factor from one stage to the next.
WEIGHT_GROWTH = 10.0
#: The Jacobian is handed to the trainer dense when a row's nonzeros (theta's and one start's) are at least
#: this fraction of its columns (benchmarks/bench_shooting_iteration.py).
DENSE_FRACTION = 0.25
#: LM iterations of a multiple-shooting stage at most (and max_iter): a stage only warms the next one up, and on
#: the Coulomb bench a stage of 2 segments crawled 604 iterations for a 0.01 % lower cost.
STAGE_MAX_ITER = 100
#: A segment whose outputs' mean squared error exceeds this many times the stage's median segment's (its RMS
#: twice the median's) has its free start reseated from the segment before (:func:`reseat`) ...
RESEAT_RATIO = 4.0
#: ... and the stage refitted, at most this many times (while that lowers its cost).
RESEAT_ROUNDS = 3
#: A merge is refused when it raises the output cost per sample more than this (RMS +20 %; module docstring) ...
MERGE_RISE = 1.44
#: ... from a stage whose residual RMS is at most this many times the noise estimate (module docstring).
NOISE_MARGIN = 2.0


def stage_lengths(length: int, longest: int) -> list[int]:
    """The multiple-shooting segment lengths: L, 4L, ... while shorter than the longest record."""
    out = []
    while length < longest:
        out.append(length)
        length *= GROWTH
    return out


@dataclass(frozen=True, eq=False)
class _Piece:
    record: int
    a: int  # first network step (row of the record's inputs/targets)
    b: int
    column: int  # first column of its free start in x, -1 for a record's first segment (fixed start)


class Segmented:
    """The multiple-shooting residual of `problem` at segment length `length` and continuity weight `weight`.

    x = (theta, then the free states of every segment that does not start a record, segment by segment).
    ``fun``/``residual`` follow Problem's (e = y - yhat, J = d yhat / d x).
    """

    def __init__(self, problem: Problem, length: int, weight: float, scale: np.ndarray | None = None,
                 threads: int = 1, starts: str = "data"):
        self.problem = problem
        self.threads = max(1, int(threads))
        compiled = problem.compiled
        if compiled.estimates_starts:  # the first segment's history would have to carry theta's sensitivity
            raise SdnnError.at("FIT006", "multiple shooting cannot be combined with estimated initial states "
                               "(init: estimate, or init: <parameter>) yet", hint="give --shooting off")
        if problem.record_params:  # theta would differ per record: not wired into the segments yet
            raise SdnnError.at("FIT006", "multiple shooting cannot be combined with per-record parameters "
                               f"({', '.join(problem.record_params)}) yet", hint="give --shooting off")
        self.n_theta = compiled.n_theta
        measured = {int(k): i for i, k in enumerate(compiled.flat.output_index)}
        states = state_neurons(compiled)
        if starts == "free":  # measured states too: a noisy sample is a poor start (see SHOOTING_STARTS)
            measured, self.data_starts = {}, [(j, measured[k]) for j, (k, _) in enumerate(states) if k in measured]
        else:
            self.data_starts = []
        self.free = np.array([k for k, _ in states if k not in measured], dtype=np.int64)
        self.free_names = tuple(name for k, name in states if k not in measured)
        self.measured = [(k, measured[k]) for k, _ in states if k in measured]
        self.length, self.weight = int(length), float(weight)
        pieces, column = [], self.n_theta
        for r, seg in enumerate(problem.segments):
            q = len(seg.inputs)
            for a in range(0, q, self.length):
                first = a == 0
                pieces.append(_Piece(r, a, min(a + self.length, q), -1 if first or not len(self.free) else column))
                if not first:
                    column += len(self.free)
        if len(pieces) > MAX_SEGMENTS:
            raise SdnnError.at("FIT005", f"multiple shooting with segments of {self.length} samples needs "
                            f"{len(pieces)} segments, at most {MAX_SEGMENTS} are allowed",
                            hint=f"give --shooting {self._shortest(MAX_SEGMENTS)} or more")
        self.pieces = pieces
        self.n_x = column
        self.bases = [compiled.initial_history(seg.init) for seg in problem.segments]
        # continuity rows measured in each state's own typical size (see shooting_fit): sqrt(L) makes one
        # boundary count like the L output samples of a segment
        self.scale = np.ones(len(self.free)) if scale is None else np.asarray(scale, dtype=float)
        self.row_weight = self.weight * np.sqrt(self.length) / self.scale
        self._csr = None
        self._groups = None
        self._records = problem.segments  # built anew at each access of the property

    def _shortest(self, n: int) -> int:
        total = sum(-(-len(s.inputs) // n) for s in self.problem.segments)
        return max(2, total)

    @property
    def names(self) -> tuple[str, ...]:
        out = list(self.problem.names)
        for p in self.pieces:
            if p.column >= 0:
                out += [f"{n}@{p.record}:{p.a}" for n in self.free_names]
        return tuple(out)

    def scale_groups(self, groups: tuple[int, ...]) -> tuple[int, ...]:
        """The theta's groups, then one group per free start (ids past theta's)."""
        if not groups:
            return ()
        return tuple(groups) + tuple(range(self.n_theta, self.n_x))

    def history(self, x: np.ndarray, p: _Piece) -> np.ndarray:
        h = self.bases[p.record].copy()
        if p.a > 0:
            targets = self._records[p.record].targets
            for k, o in self.measured:
                h[k] = targets[p.a - 1, o]
            if p.column >= 0:
                h[self.free] = x[p.column:p.column + len(self.free)]
        return h

    def _chunks(self) -> list[list[int]]:
        """The pieces' indices grouped into one kernel call each: consecutive pieces of one record, split in
        `threads` parts per record."""
        if self._groups is None:
            groups = []
            for r in range(len(self._records)):
                own = [i for i, p in enumerate(self.pieces) if p.record == r]
                parts = min(self.threads, len(own))
                groups += [list(a) for a in np.array_split(own, parts) if len(a)]
            self._groups = groups
        return self._groups

    def _histories(self, x: np.ndarray, chunk: list[int]) -> np.ndarray:
        """:meth:`history` of each piece in `chunk`, as rows."""
        return np.stack([self.history(x, self.pieces[i]) for i in chunk])

    def _runs(self, x: np.ndarray, with_jac: bool):
        """(piece, outputs and end states, their sensitivities or None) of every segment, in order; one kernel
        call per chunk (:meth:`_chunks`), the chunks on `threads` threads (the kernels release the GIL; each
        segment's run is independent of the others')."""
        theta = x[:self.n_theta]
        states = self.free if len(self.free) else None
        compiled = self.problem.compiled
        compiled.connection_values(theta, with_jac)  # evaluated once, before the threads share it
        segments = self._records

        def run(chunk: list[int]):
            pieces = [self.pieces[i] for i in chunk]
            y, dy = compiled.run_pieces(theta, segments[pieces[0].record].inputs, [p.a for p in pieces],
                                        [p.b for p in pieces], self._histories(x, chunk), states, with_jac)
            out, row = [], 0
            for p in pieces:
                n = p.b - p.a
                out.append((p, y[row:row + n], None if dy is None else dy[row:row + n]))
                row += n
            return out

        with _interruptible():
            chunks = self._chunks()
            if self.threads == 1 or len(chunks) == 1:
                for chunk in chunks:
                    yield from run(chunk)
                return
            with ThreadPoolExecutor(self.threads) as pool:
                for out in pool.map(run, chunks):
                    yield from out

    def residual(self, x: np.ndarray):
        x = np.asarray(x, dtype=float)
        n_out = self.problem.compiled.n_outputs
        es, prev = [], None
        for p, y, _ in self._runs(x, False):
            if not np.all(np.isfinite(y)):
                return None
            es.append((self._records[p.record].targets[p.a:p.b] - y[:, :n_out]).ravel())
            if p.column >= 0:
                es.append(-self.row_weight * (prev - x[p.column:p.column + len(self.free)]))
            prev = y[-1, n_out:]
        return np.concatenate(es)

    def fun(self, x: np.ndarray):
        """(e, J) with J sparse (CSR): a segment's rows have nonzeros in theta's columns and its own start's;
        a continuity row in theta's, the previous start's and its own. The nonzero pattern is fixed by the
        pieces (:meth:`_pattern`), so each call only writes the values: building the pattern per call cost 40 %
        of an iteration at L = 100 (benchmarks/bench_shooting_iteration.py)."""
        x = np.asarray(x, dtype=float)
        n_out, P, S = self.problem.compiled.n_outputs, self.n_theta, len(self.free)
        starts, indices, indptr = self._pattern()
        data = np.empty(len(indices))
        es, prev = [], None
        for (p, y, dy), (at, link_at) in zip(self._runs(x, True), starts, strict=True):
            m = (p.b - p.a) * n_out
            es.append((self._records[p.record].targets[p.a:p.b] - y[:, :n_out]).ravel())
            block = dy[:, :n_out, :P + (S if p.column >= 0 else 0)]
            data[at:at + block.size] = block.reshape(m, -1).ravel()
            if p.column >= 0:
                # continuity: weight * (end of the previous segment - this start), its Jacobian
                end, dend, column = prev
                es.append(-self.row_weight * (end - x[p.column:p.column + S]))
                link = np.concatenate([dend[:, :P + (S if column >= 0 else 0)], -np.eye(S)], axis=1)
                data[link_at:link_at + link.size] = (link * self.row_weight[:, None]).ravel()
            if S:
                prev = (y[-1, n_out:], dy[-1, n_out:, :], p.column)
        e = np.concatenate(es)
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(data))):
            return None
        J = sparse.csr_matrix((data, indices, indptr), shape=(len(indptr) - 1, self.n_x))
        # few segments: J is mostly nonzero, and BLAS on the dense matrix beats sparse products (JᵀJ of 10
        # segments: 1.4 ms dense, 16 ms sparse)
        return e, (J.toarray() if P + S >= DENSE_FRACTION * self.n_x else J)

    def _pattern(self) -> tuple[list[tuple[int, int]], np.ndarray, np.ndarray]:
        """fun's CSR pattern: per piece the offsets of its output rows' and continuity rows' values in the
        data array (-1: none), then the column indices and the row pointers (columns ascending in each row)."""
        if self._csr is not None:
            return self._csr
        n_out, P, S = self.problem.compiled.n_outputs, self.n_theta, len(self.free)
        theta_cols = np.arange(P)
        starts, indices, widths, at, before = [], [], [], 0, -1
        for p in self.pieces:
            own = np.arange(p.column, p.column + S) if p.column >= 0 else np.zeros(0, dtype=np.int64)
            m = (p.b - p.a) * n_out
            cols = np.concatenate([theta_cols, own])
            indices.append(np.tile(cols, m))
            widths.append(np.full(m, len(cols)))
            out_at, at, link_at = at, at + m * len(cols), -1
            if p.column >= 0:
                prior = np.arange(before, before + S) if before >= 0 else np.zeros(0, dtype=np.int64)
                cols = np.concatenate([theta_cols, prior, own])
                indices.append(np.tile(cols, S))
                widths.append(np.full(S, len(cols)))
                link_at, at = at, at + S * len(cols)
            starts.append((out_at, link_at))
            before = p.column
        widths = np.concatenate(widths)
        # 32-bit indices where they fit, as scipy keeps them: it downcast 64-bit ones at every call (0.5 ms)
        index = np.int32 if int(np.sum(widths)) < 2**31 else np.int64
        indptr = np.concatenate([[0], np.cumsum(widths)]).astype(index)
        self._csr = (starts, np.concatenate(indices).astype(index), indptr)
        return self._csr

    def output_cost(self, x: np.ndarray) -> float:
        """0.5 * sum of the outputs' squared errors over every segment (the continuity rows left out)."""
        n_out = self.problem.compiled.n_outputs
        total = 0.0
        for p, y, _ in self._runs(np.asarray(x, dtype=float), False):
            total += 0.5 * float(np.sum((self._records[p.record].targets[p.a:p.b] - y[:, :n_out]) ** 2))
        return total if np.isfinite(total) else float("inf")

    def start(self, theta: np.ndarray, carried: dict | None = None) -> np.ndarray:
        """x at `theta`: free starts taken from `carried` ({(record, a): states}, an earlier stage), else from
        a run of each record in segments, each restarted from the data where measured (the states it passes)."""
        x = np.zeros(self.n_x)
        x[:self.n_theta] = theta
        n_out = self.problem.compiled.n_outputs
        prev = None
        for p in self.pieces:
            if p.column >= 0:
                key = (p.record, p.a)
                x[p.column:p.column + len(self.free)] = carried[key] if carried and key in carried else prev
                if not (carried and key in carried):  # free measured states start from the data
                    for j, o in self.data_starts:
                        x[p.column + j] = self._records[p.record].targets[p.a - 1, o]
            if len(self.free):
                seg = self._records[p.record]
                with _interruptible():
                    y = self.problem.compiled.simulate(theta, seg.inputs[p.a:p.b], history=self.history(x, p),
                                                       states=self.free)
                prev = y[-1, n_out:] if np.all(np.isfinite(y[-1])) else self.bases[p.record][self.free]
        return x

    def starts_of(self, x: np.ndarray) -> dict:
        """{(record, a): free start} of x, to carry over to the next stage."""
        S = len(self.free)
        return {(p.record, p.a): np.array(x[p.column:p.column + S]) for p in self.pieces if p.column >= 0}


def _dense(a) -> np.ndarray:
    return a.toarray() if sparse.issparse(a) else np.array(a)


def noise_level(problem: Problem) -> float:
    """The measurement noise's variance, averaged over the outputs, from the records' second differences.

    For a signal sampled fast against its own changes the second difference is the noise's, of variance
    6 sigma^2; its median absolute deviation (times 1.4826) is robust against the few large second differences
    of the signal itself (a torque step). Returns sigma^2 averaged over the outputs (0 when nothing is known).
    """
    out, count = 0.0, 0
    for s in problem.segments:
        if len(s.targets) < 5:
            continue
        d2 = np.diff(s.targets, n=2, axis=0)
        mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
        sigma2 = (1.4826 * mad) ** 2 / 6.0
        out += float(np.sum(sigma2)) * len(d2)
        count += d2.shape[1] * len(d2)
    return out / count if count else 0.0


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
    floor = 0.5 * NOISE_MARGIN ** 2 * noise_level(problem)  # a stage's cost per sample at the noise floor
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

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

Sensitivities: exact, by the RTRL kernel with the history's own sensitivities (kernels.jacobian_kernel's
`s_init`): the free starts are extra columns of theta whose initial sensitivity is the identity. Each segment
is simulated from its own start, the segments of a record in one kernel call (one per thread,
CompiledNetwork.run_pieces); the Jacobian has segments x free states extra columns, sparse, and the number of
segments is capped (MAX_SEGMENTS). Its nonzero pattern is fixed by the segments: each call only copies the
kernels' results into place, by strided copies and index arrays built once per stage, and hands theta's columns
to the trainer dense as well (fit.lm.WideFirstCSR) for JᵀJ.

Layer: identify (below it: fit, network).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ... import rules
from ...errors import SdnnError
from ...fit.lm import LMOptions, LMResult, WideFirstCSR, levenberg_marquardt
from ..offline.initstate import state_neurons
from ..offline.problem import Problem, interruptible

__all__ = ["Segmented", "shooting_fit", "stage_lengths", "kept_stage", "MAX_SEGMENTS", "GROWTH", "WEIGHT_GROWTH",
           "STAGE_MAX_ITER", "MERGE_RISE", "RESEAT_RATIO", "RESEAT_ROUNDS", "reseat", "NOISE_MARGIN", "NOISE_ORDERS", "NOISE_BANDS", "noise_level", "noise_variance",
           "noise_cost"]

#: Segments of one stage at most: the Jacobian has (free states x segments) extra dense columns.
MAX_SEGMENTS = rules.value("max_segments")
#: Segment length factor from one stage to the next (boundaries of a stage are boundaries of the one before,
#: so its free starts carry over).
GROWTH = rules.value("segment_growth")
#: Continuity weight factor from one stage to the next.
WEIGHT_GROWTH = rules.value("weight_growth")
#: The Jacobian is handed to the trainer dense when a row's nonzeros (theta's and one start's) are at least
#: this fraction of its columns (benchmarks/bench_shooting_iteration.py).
DENSE_FRACTION = rules.value("dense_fraction")
#: LM iterations of a multiple-shooting stage at most (and max_iter): a stage only warms the next one up, and on
#: the Coulomb bench a stage of 2 segments crawled 604 iterations for a 0.01 % lower cost.
STAGE_MAX_ITER = rules.value("stage_max_iter")
#: A segment whose outputs' mean squared error exceeds this many times the stage's median segment's (its RMS
#: twice the median's) has its free start reseated from the segment before (:func:`reseat`) ...
RESEAT_RATIO = rules.value("reseat_ratio")
#: ... and the stage refitted, at most this many times (while that lowers its cost).
RESEAT_ROUNDS = rules.value("reseat_rounds")
#: A merge is refused when it raises the output cost per sample more than this (RMS +20 %; module docstring) ...
MERGE_RISE = rules.value("merge_rise")
#: ... from a stage whose residual RMS is at most this many times the noise estimate (module docstring).
NOISE_MARGIN = rules.value("noise_margin")


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


@dataclass(frozen=True, eq=False)
class _ChunkPlan:
    """Where one kernel call's results go (:meth:`Segmented._plan`): its record and samples ``a:b``; the places in
    e of its output errors; its pieces' output rows as runs of like pieces (``groups``: each run's place in J's
    data, first row of dy, pieces, samples per piece, columns, values per piece with its continuity rows), copied
    by one strided copy per run; the values of the continuity rows that read an end state it holds by flat
    indices into its dy (``link_src``) and their places in the data (``link_dst``), each times the row weight of
    its state ``link_state``; and its rows of those end states (``end_rows``)."""

    record: int
    a: int
    b: int
    e_dst: np.ndarray
    groups: tuple
    link_src: np.ndarray
    link_dst: np.ndarray
    link_state: np.ndarray
    end_rows: np.ndarray


@dataclass(frozen=True, eq=False)
class _Plan:
    """Segmented.fun's fixed CSR pattern (``indices``, ``indptr``; ``rows`` x n_x with ``nnz`` values), where each
    call's values go (``chunks``; the continuity rows' d(-weight * start)/d start: ``eye_*``; their rows in e and
    the start's columns in x: ``link_rows``, ``link_columns``, one row per boundary), whether J is handed over
    dense, and how its blocks for fit.lm's JᵀJ are written (theta's columns dense: the continuity rows' ``link_rows``
    from the data at ``link_wide_at``, the output rows by the chunks' groups; the other columns as CSR: the data at
    ``rest_at``, pattern ``rest_indices``, ``rest_indptr``); a dense J's places of the continuity rows' values:
    ``dense_link_at`` (one array per chunk, as its ``link_src``), ``dense_eye_at``."""

    rows: int
    nnz: int
    indices: np.ndarray
    indptr: np.ndarray
    chunks: list
    eye_dst: np.ndarray
    eye_state: np.ndarray
    eye_value: np.ndarray
    link_rows: np.ndarray
    link_columns: np.ndarray
    dense: bool
    link_wide_at: np.ndarray
    rest_at: np.ndarray
    rest_indices: np.ndarray
    rest_indptr: np.ndarray
    dense_link_at: list
    dense_eye_at: np.ndarray


def _cat(parts: list) -> np.ndarray:
    """Index arrays joined (empty: none)."""
    return np.concatenate(parts).astype(np.intp) if parts else np.zeros(0, dtype=np.intp)


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
        self._plan_cache = None
        self._history_rows = {}  # chunk -> (histories without the free starts, their rows, x's columns)
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
        """:meth:`history` of each piece in `chunk`, as rows: the parts that x does not set built once per chunk,
        then the free starts written in (one history at a time cost 0.5 ms a call at 250 segments)."""
        key = tuple(int(i) for i in chunk)
        if key not in self._history_rows:
            base = np.stack([self.history(np.zeros(self.n_x), self.pieces[i]) for i in chunk])
            rows = np.array([r for r, i in enumerate(chunk) if self.pieces[i].column >= 0], dtype=np.intp)
            columns = np.array([self.pieces[chunk[r]].column for r in rows], dtype=np.intp)
            self._history_rows[key] = (base, rows[:, None], columns[:, None] + np.arange(len(self.free)))
        base, rows, columns = self._history_rows[key]
        h = base.copy()
        h[rows, self.free] = x[columns]
        return h

    def _chunk_runs(self, x: np.ndarray, with_jac: bool):
        """(chunk index, outputs and end states, their sensitivities or None) of every chunk (:meth:`_chunks`), in
        order: one kernel call each, the chunks on `threads` threads (the kernels release the GIL; each segment's
        run is independent of the others'). A chunk's rows are its pieces' samples, one after the other."""
        theta = x[:self.n_theta]
        states = self.free if len(self.free) else None
        compiled = self.problem.compiled
        compiled.connection_values(theta, with_jac)  # evaluated once, before the threads share it
        segments = self._records
        chunks = self._chunks()

        def run(c: int):
            pieces = [self.pieces[i] for i in chunks[c]]
            y, dy = compiled.run_pieces(theta, segments[pieces[0].record].inputs, [p.a for p in pieces],
                                        [p.b for p in pieces], self._histories(x, chunks[c]), states, with_jac)
            return c, y, dy

        with interruptible():
            if self.threads == 1 or len(chunks) == 1:
                for c in range(len(chunks)):
                    yield run(c)
                return
            with ThreadPoolExecutor(self.threads) as pool:
                yield from pool.map(run, range(len(chunks)))

    def _runs(self, x: np.ndarray, with_jac: bool):
        """(piece, outputs and end states, their sensitivities or None) of every segment, in order
        (:meth:`_chunk_runs`, cut into its pieces)."""
        chunks = self._chunks()
        for c, y, dy in self._chunk_runs(x, with_jac):
            row = 0
            for i in chunks[c]:
                p = self.pieces[i]
                n = p.b - p.a
                yield p, y[row:row + n], None if dy is None else dy[row:row + n]
                row += n

    def residual(self, x: np.ndarray):
        """e of :meth:`fun` without the Jacobian."""
        x = np.asarray(x, dtype=float)
        plan = self._plan()
        e = np.empty(plan.rows)
        ends = []
        for c, y, _ in self._chunk_runs(x, False):
            if not np.all(np.isfinite(y)):
                return None
            ends.append(self._fill_outputs(plan, plan.chunks[c], y, e))
        self._fill_links(plan, x, ends, e)
        return e

    def fun(self, x: np.ndarray):
        """(e, J) with J sparse (CSR): a segment's rows have nonzeros in theta's columns and its own start's;
        a continuity row in theta's, the previous start's and its own. The nonzero pattern is fixed by the
        pieces (:meth:`_plan`), so each call only writes the values, by one strided copy per run of like segments
        and index arrays built once: building the pattern per call cost 40 % of an iteration at L = 100, writing
        it segment by segment in Python 4-6 ms a call, by index arrays over all the values 3-4 ms (cache misses
        on the indices), the strided copies 0.8 ms (benchmarks/bench_shooting_iteration.py). J is a
        fit.lm.WideFirstCSR: theta's columns, which begin every row, are written dense as well (``wide``), the
        others as their own CSR (``rest``), and the trainer forms JᵀJ from them without slicing J."""
        x = np.asarray(x, dtype=float)
        plan = self._plan()
        if plan.dense:
            return self._fun_dense(x, plan)
        e, data = np.empty(plan.rows), np.empty(plan.nnz)
        n_out, P = self.problem.compiled.n_outputs, self.n_theta
        K, C = n_out + len(self.free), P + len(self.free)
        wide = np.empty((plan.rows, P))  # theta's columns, for fit.lm's JᵀJ
        ends = []
        for c, y, dy in self._chunk_runs(x, True):
            chunk = plan.chunks[c]
            ends.append(self._fill_outputs(plan, chunk, y, e))
            for at, row, k, n, width, period, csr_row, rows_per, _ in chunk.groups:  # like pieces: strided copies
                block = dy[row:row + k * n].reshape(k, n, K, C)[:, :, :n_out]
                np.copyto(data[at:at + k * period].reshape(k, period)[:, :n * n_out * width].reshape(k, n, n_out, width),
                          block[..., :width])
                np.copyto(wide[csr_row:csr_row + k * rows_per].reshape(k, rows_per, P)[:, :n * n_out]
                          .reshape(k, n, n_out, P), block[..., :P])
            values = dy.ravel()
            # continuity: weight * (end of the previous segment - this start), its Jacobian (the ends' rows here)
            data[chunk.link_dst] = values[chunk.link_src] * self.row_weight[chunk.link_state]
        data[plan.eye_dst] = plan.eye_value * self.row_weight[plan.eye_state]  # d(- weight * start) / d start
        self._fill_links(plan, x, ends, e)
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(data))):
            return None
        J = WideFirstCSR((data, plan.indices, plan.indptr), shape=(plan.rows, self.n_x))
        wide[plan.link_rows.ravel()] = data[plan.link_wide_at]
        J.wide = wide
        J.rest = sparse.csr_matrix((data[plan.rest_at], plan.rest_indices, plan.rest_indptr),
                                   shape=(plan.rows, self.n_x - P))
        return e, J

    def _fun_dense(self, x: np.ndarray, plan: _Plan):
        """:meth:`fun` with J dense, written in place (few segments: J is mostly nonzero, and BLAS on the dense
        matrix beats sparse products, JᵀJ of 10 segments 1.4 ms dense, 16 ms sparse; the CSR matrix made dense
        cost 2-3 ms a call)."""
        n_out, P, S = self.problem.compiled.n_outputs, self.n_theta, len(self.free)
        K, C = n_out + S, P + S
        e, J = np.empty(plan.rows), np.zeros((plan.rows, self.n_x))
        flat = J.ravel()
        ends = []
        for c, y, dy in self._chunk_runs(x, True):
            chunk = plan.chunks[c]
            ends.append(self._fill_outputs(plan, chunk, y, e))
            for _, row, k, n, width, _, csr_row, rows_per, column in chunk.groups:
                block = dy[row:row + k * n].reshape(k, n, K, C)[:, :, :n_out]
                rows = J[csr_row:csr_row + k * rows_per].reshape(k, rows_per, self.n_x)[:, :n * n_out]
                rows = rows.reshape(k, n, n_out, self.n_x)
                rows[..., :P] = block[..., :P]
                for i in range(k if width > P else 0):  # each piece's own start's columns
                    rows[i, ..., column + i * S:column + (i + 1) * S] = block[i, ..., P:]
            flat[plan.dense_link_at[c]] = dy.ravel()[chunk.link_src] * self.row_weight[chunk.link_state]
        flat[plan.dense_eye_at] = plan.eye_value * self.row_weight[plan.eye_state]
        self._fill_links(plan, x, ends, e)
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(J))):
            return None
        return e, J

    def _fill_outputs(self, plan: _Plan, chunk: _ChunkPlan, y: np.ndarray, e: np.ndarray) -> np.ndarray:
        """The chunk's output errors into e; returns the end states of its pieces that a continuity row reads."""
        n_out = self.problem.compiled.n_outputs
        targets = self._records[chunk.record].targets[chunk.a:chunk.b]
        e[chunk.e_dst] = (targets - y[:, :n_out]).ravel()
        return y[chunk.end_rows, n_out:]

    def _fill_links(self, plan: _Plan, x: np.ndarray, ends: list[np.ndarray], e: np.ndarray) -> None:
        """The continuity rows of e: -weight * (end of the previous segment - this start), from every chunk's
        `ends` (:meth:`_fill_outputs`)."""
        if not plan.link_rows.size:
            return
        end = np.concatenate(ends) if len(ends) > 1 else ends[0]
        e[plan.link_rows] = -self.row_weight * (end - x[plan.link_columns])

    def _plan(self) -> _Plan:
        """fun's CSR pattern and the index arrays that write a call's values into it (:class:`_Plan`); built
        once (columns ascending in each row; theta's first)."""
        if self._plan_cache is not None:
            return self._plan_cache
        n_out, P, S = self.problem.compiled.n_outputs, self.n_theta, len(self.free)
        K, C = n_out + S, P + S  # a kernel row's recorded neurons and sensitivity columns
        theta_cols = np.arange(P)
        indices, widths, at, row, before = [], [], 0, 0, -1
        out_at, link_at, out_row, link_row = {}, {}, {}, {}
        for i, p in enumerate(self.pieces):
            own = np.arange(p.column, p.column + S) if p.column >= 0 else np.zeros(0, dtype=np.int64)
            m = (p.b - p.a) * n_out
            cols = np.concatenate([theta_cols, own])
            indices.append(np.tile(cols, m))
            widths.append(np.full(m, len(cols)))
            out_at[i], out_row[i], at, row = at, row, at + m * len(cols), row + m
            if p.column >= 0:
                prior = np.arange(before, before + S) if before >= 0 else np.zeros(0, dtype=np.int64)
                cols = np.concatenate([theta_cols, prior, own])
                indices.append(np.tile(cols, S))
                widths.append(np.full(S, len(cols)))
                link_at[i], link_row[i], at, row = at, row, at + S * len(cols), row + S
            before = p.column
        widths = np.concatenate(widths)
        # 32-bit indices where they fit, as scipy keeps them: it downcast 64-bit ones at every call (0.5 ms)
        index = np.int32 if int(np.sum(widths)) < 2**31 else np.int64
        indptr = np.concatenate([[0], np.cumsum(widths)]).astype(index)
        indices = np.concatenate(indices).astype(index)
        chunks = []
        for chunk in self._chunks():
            e_dst, groups, link_src, link_dst, link_state, end_rows, local = [], [], [], [], [], [], 0
            for i in chunk:
                p = self.pieces[i]
                n, width = p.b - p.a, P + (S if p.column >= 0 else 0)
                e_dst.append(out_row[i] + np.arange(n * n_out))
                # output rows: dy[local:local + n, :n_out, :width] -> data[out_at:], then its continuity rows
                prior = S if p.column >= 0 and self.pieces[i - 1].column >= 0 else 0
                period = n * n_out * width + (S * (width + prior) if p.column >= 0 else 0)
                last = groups[-1] if groups else None
                rows_per = n * n_out + (S if p.column >= 0 else 0)  # its output rows, then its continuity rows
                if last is not None and last[3:6] == (n, width, period) and last[0] + last[2] * period == out_at[i]:
                    groups[-1] = last[:2] + (last[2] + 1,) + last[3:]
                else:  # the pieces of a run have consecutive free starts: column + S * (piece in the run)
                    groups.append((out_at[i], local, 1, n, width, period, out_row[i], rows_per, p.column))
                after = i + 1
                if after < len(self.pieces) and self.pieces[after].column >= 0 \
                        and self.pieces[after].record == p.record:
                    # the next piece's continuity rows read this piece's end: dy[end, n_out + s, :width]
                    end = local + n - 1
                    end_rows.append(end)
                    span = width + S  # theta's, this piece's start's (if free), the next's
                    s, j = np.meshgrid(np.arange(S), np.arange(width), indexing="ij")
                    link_src.append(((end * K + n_out + s) * C + j).ravel())
                    link_dst.append((link_at[after] + s * span + j).ravel())
                    link_state.append(s.ravel())
                local += n
            first, last = self.pieces[chunk[0]], self.pieces[chunk[-1]]
            chunks.append(_ChunkPlan(first.record, first.a, last.b, _cat(e_dst), tuple(groups),
                                     _cat(link_src), _cat(link_dst), _cat(link_state), np.array(end_rows, dtype=np.intp)))
        eye_dst, eye_state, eye_value, link_rows, link_columns = [], [], [], [], []
        for i, p in enumerate(self.pieces):
            if p.column < 0:
                continue
            prior = S if self.pieces[i - 1].column >= 0 else 0
            span = P + prior + S
            s, j = np.meshgrid(np.arange(S), np.arange(S), indexing="ij")
            eye_dst.append((link_at[i] + s * span + P + prior + j).ravel())
            eye_state.append(s.ravel())
            eye_value.append(-np.eye(S).ravel())
            link_rows.append(link_row[i] + np.arange(S))
            link_columns.append(p.column + np.arange(S))
        rows = len(indptr) - 1
        # every row begins with theta's P columns (fit.lm.WideFirstCSR's dense block); the rest's CSR
        # the dense J's places of the continuity rows' values (row * n_x + column)
        dense = P + S >= DENSE_FRACTION * self.n_x
        entry_row = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr)) if dense else None
        dense_at = [entry_row[c.link_dst] * self.n_x + indices[c.link_dst] if dense else _cat([]) for c in chunks]
        eye_at = _cat(eye_dst)
        dense_eye_at = entry_row[eye_at] * self.n_x + indices[eye_at] if dense else _cat([])
        rest = np.ones(len(indices), dtype=bool)
        rest[(indptr[:-1, None].astype(np.intp) + np.arange(P)).ravel()] = False
        link_rows = _cat(link_rows).reshape(-1, S) if S else np.zeros((0, 0), dtype=np.intp)
        self._plan_cache = _Plan(rows, len(indices), indices, indptr, chunks, _cat(eye_dst), _cat(eye_state),
                                 np.concatenate(eye_value) if eye_value else np.zeros(0), link_rows,
                                 _cat(link_columns).reshape(-1, S) if S else np.zeros((0, 0), dtype=np.intp),
                                 dense,
                                 (indptr[link_rows.ravel()].astype(np.intp)[:, None] + np.arange(P)).astype(np.intp),
                                 np.flatnonzero(rest), (indices[rest] - P).astype(index),
                                 (indptr - P * np.arange(rows + 1)).astype(index),
                                 [a.astype(np.intp) for a in dense_at], dense_eye_at.astype(np.intp))
        return self._plan_cache

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
                with interruptible():
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


#: higher difference orders the noise is read from besides the second (see noise_variance)
NOISE_ORDERS = rules.value("noise_orders")
#: frequency bands of the spectral reading (see noise_variance)
NOISE_BANDS = rules.value("noise_bands")


def noise_variance(y: np.ndarray) -> np.ndarray:
    """Each column's white-noise variance, (Q, n) -> (n,) (0 when Q is too short to tell).

    The second difference of white noise of variance sigma^2 has variance 6 sigma^2; its median absolute
    deviation (times 1.4826, robust against the few large differences of a torque step) is the reading for a
    record sampled fast against its changes. A smooth record sampled a few times per period keeps its
    curvature there: with 10 samples per resonance period a signal of RMS 0.66 read as 0.15 of 'noise' where
    the truth was 0.00066 (tests/test_noise_estimate.py). Two other readings, each of which can only overstate
    the noise, are taken then:

    * higher differences (NOISE_ORDERS): the n-th has C(2n, n) sigma^2 of noise, while a signal at w rad per
      sample keeps |2 sin(w/2)|^n of itself, which falls with n below six samples per period;
    * the spectrum's floor: the median of the Hann-windowed periodogram over each of NOISE_BANDS equal
      frequency bands is ln 2 sigma^2 where the band holds only noise (lines of a multisine or harmonics fill
      few bins and leave the median); the lowest band is the reading.

    The smallest of them replaces the second difference's when it is under a quarter of it (half the RMS):
    on a record whose second difference is noise all readings agree within their scatter and nothing changes.
    """
    y = np.asarray(y, dtype=float)
    base = _difference_variance(y, 2)
    other = np.full(y.shape[1], np.inf)
    for n in NOISE_ORDERS:
        if len(y) >= 8 * n:
            other = np.minimum(other, _positive(_difference_variance(y, n)))
    if len(y) >= 32 * NOISE_BANDS:
        other = np.minimum(other, _positive(_spectral_floor(y)))
    return np.where(other < 0.25 * base, other, base)


def _positive(v: np.ndarray) -> np.ndarray:
    return np.where(v > 0, v, np.inf)


def _difference_variance(y: np.ndarray, n: int) -> np.ndarray:
    d = np.diff(y, n=n, axis=0)
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return (1.4826 * mad) ** 2 / math.comb(2 * n, n)


def _spectral_floor(y: np.ndarray) -> np.ndarray:
    """sigma^2 of white noise from the quietest band of the periodogram (E|X_f|^2 = sigma^2 sum w^2 for
    white noise under the window w; a bin is sigma^2 times an Exp(1) variable, of median ln 2)."""
    q = len(y)
    k = np.arange(q)
    trend = np.polynomial.polynomial.polyfit(k, y, 1)
    r = y - (trend[0] + np.outer(k, trend[1]))
    w = np.hanning(q)
    p = np.abs(np.fft.rfft(r * w[:, None], axis=0)) ** 2 / np.sum(w ** 2)
    p = p[2:-1]  # DC and its neighbour carry the window's leakage of the mean; the Nyquist bin is real-valued
    bands = np.array_split(p, NOISE_BANDS, axis=0)
    return np.min([np.median(b, axis=0) for b in bands], axis=0) / math.log(2)


def noise_level(problem: Problem) -> float:
    """The measurement noise's variance, averaged over the outputs and weighted by the records' lengths, read
    off the records' differences (:func:`noise_variance`). Returns sigma^2 (0 when nothing is known)."""
    out, count = 0.0, 0
    for s in problem.segments:
        if len(s.targets) < 8:
            continue
        sigma2 = noise_variance(s.targets)
        out += float(np.sum(sigma2)) * len(s.targets)
        count += s.targets.shape[1] * len(s.targets)
    return out / count if count else 0.0


def noise_cost(problem: Problem, ratio: float) -> float:
    """The cost per sample (E over the records' targets, E = SSE / 2) of a residual at `ratio` x the noise RMS
    (:func:`noise_level`): the one noise floor that multiple shooting, auto's second look, the crawl rule and
    diagnose compare costs with."""
    return 0.5 * ratio ** 2 * noise_level(problem)


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

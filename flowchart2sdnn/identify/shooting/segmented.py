"""The multiple-shooting problem of one stage (:mod:`.multiple` runs the stages): the training records cut
into segments of L samples, a segment's free starts extra columns of theta, and the residual and its Jacobian.

The residual is the outputs' error on every segment followed by, for each free state and each segment
boundary, ``weight * (end of the segment - start of the next)``. A segment's initial state is the value before
its first step of every integrator neuron (identify.offline.initstate.state_neurons): measured ones from the
data at that sample, unmeasured ones free quantities fitted with the parameters.


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

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ... import rules
from ...errors import SdnnError
from ...fit.lm import WideFirstCSR
from ..offline.initstate import state_neurons
from ..offline.problem import Problem, interruptible

__all__ = ["Segmented", "MAX_SEGMENTS", "DENSE_FRACTION"]

#: Segments of one stage at most: the Jacobian has (free states x segments) extra dense columns.
MAX_SEGMENTS = rules.value("max_segments")
#: The Jacobian is handed to the trainer dense when a row's nonzeros (theta's and one start's) are at least
#: this fraction of its columns (benchmarks/bench_shooting_iteration.py).
DENSE_FRACTION = rules.value("dense_fraction")


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


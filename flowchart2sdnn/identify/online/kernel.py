"""The numba kernel of the quasi-online Levenberg-Marquardt run (paper section 3.1).

One call of :func:`online_chunk` advances the run over samples ``[t0, t1)``; all state lives in arrays the
caller allocates once (:func:`new_state`) and the kernel mutates, so a run can be cut into chunks (progress,
Ctrl-C) without changing a single number. Two algorithms share the window and the model:

**Window mode** (``tries >= 1``, the default of :class:`flowchart2sdnn.identify.online.run.OnlineOptions`). The model
runs free with the accepted parameters u and RTRL; every sample's row (``J``, ``e``) enters the FIFO window of Q
rows together with the network state before that sample. Every ``block`` samples from ``start`` on (fewer
while the window fills: ``max(min_block, block * rows / Q)``, an iteration costs in proportion to the rows) one
LM iteration runs on the window, trainlm's: the step ``(A + mu I) du = J^T e`` from u; the window's samples are
simulated again at ``u + du`` from the stored state before the oldest row (past data only, nothing after the
current sample); the trial is accepted when its window cost is below the window cost at u, ``mu *= mu_dec``,
else refused, ``mu *= mu_inc`` and retried, up to ``tries`` trials per iteration. An accepted trial is
relinearised: the window's samples are simulated once more with RTRL at the new u (sensitivities zero before
the oldest row) and replace every row's Jacobian, error and stored state; the model continues from the state
and sensitivities after the newest sample. So every iteration is an exact LM iteration on the last Q samples,
and the rows never go stale. The first damping is scaled to the window: ``mu = max(mu0, tau * max diag(A))``
at the first iteration (as fit/lm.py's ``LMOptions.tau``); ``tau = 0`` keeps mu0. Cost: one simulation of the
window per trial and one RTRL pass per accepted trial.

Why (measured on the paper's experiment, docs/paper_experiment.md): the trial mode below keeps each row as it
was linearised, corrected to first order; the parameters move far within a window (J1 from 0.6 or 0.01 to 0.19,
c from 100 or 800 to 477), so the corrected rows mispredicted the window cost by 10-50x at the current point
(the window cost of the rows' linear model 2.7e5 against the actual 4.5e4 at t = 10 s from J1 = 0.6), each
accepted step only moved to the minimum of that stale model, and none of the four starts met the acceptance.

**Trial mode** (``tries = 0``, the previous algorithm, kept for comparison). Two copies of the network run free
alongside the record:

* the *model*, with the accepted internal parameters u: an RTRL step per sample (the offline Jacobian's
  :func:`flowchart2sdnn.network.kernels.rtrl_step`) gives its output and ``S(t) = d a(t) / d x``; the window
  row is ``J(t) = S_out(t) * dx/du`` with the a-priori error ``e(t) = y(t) - yhat(t)``;
* the *trial*, with ``u_trial = u + du``, the LM step from u computed on the current window
  (``(A + mu I) du = g``, Cholesky, a larger damping when rounding makes the matrix indefinite), recomputed
  every ``every`` samples as the window slides. The trial is only simulated.

Window (FIFO, ring buffer of Q rows). Row q was linearised at the accepted parameters of its time, u_q, so its
error at u is taken to first order, ``e_q(u) = c_q - J_q (u - u_ref)`` with ``c_q = e_q + J_q (u_q - u_ref)``
(this keeps g right after u moves: the stale a-priori errors alone would ask for the same correction again at
every sample). Running sums ``A = sum J^T J``, ``b = sum J^T c``, ``sum c^2``, ``sum e^2``: the new row is
added, the leaving row subtracted; every Q pushes they are recomputed from the ring (bounding rounding drift)
and ``u_ref`` moves to u. Then ``g = b - A (u - u_ref)`` and the window cost is ``E = 1/2 sum e_q^2``.

mu rule (trainlm's accept/reject, decided without re-simulating the window). From ``start`` on the samples
are cut into blocks of ``block`` samples; at each block start the trial restarts from the model's state and
parameters. Over the block, the trial's output change is compared with its first-order prediction
``J_blk du``, where ``J_blk`` are sensitivities of the model restarted at zero at the block start (the trial
differs from the model since the block start only, not since t = 0): with ``lin = J_blk du`` and
``miss = (y - yhat_trial) - (e - lin)`` summed as squares over the block, the trial is accepted when
``sum miss^2 <= LINEARITY_TOL * sum lin^2``, i.e. when the linear model on which the LM step rests held at
the trial point. This is the gain-ratio idea of LM/trust-region methods; the plain "did the cost go down"
test of trainlm does not carry over, because the step minimises the window's cost, not the block's: a good
window step may raise the cost of a short block, and a bad one may lower it by luck. Accepted: the model
takes the trial's parameters and state, ``mu *= mu_dec``; refused: ``mu *= mu_inc``; mu stays within
``[mu_min, mu_max]``. (Measured on the motor, a motor with a fixed tanh basis and the two-mass bench: the
plain block-cost test let the two-mass run drift to a model with errors of 10^5 rad/s, and "linear model held
and block cost not higher" stalled at mu_max far from the optimum; the test above converged on all three.)

Divergence: a non-finite (or overflowing) trial output refuses the trial at once (``mu *= mu_inc``); a
non-finite model output adopts the trial's parameters and state when they are finite, else restarts both from
the history with zero sensitivities; the sample's row is skipped and the event recorded. Nothing non-finite
ever enters the window.

Layout: this module holds the state, the per-sample loop and the trial mode; :mod:`.window` the window
numerics (FIFO sums, the damped step, the window mode's iteration). Both run the network with the offline
kernels' steps (:mod:`flowchart2sdnn.network.kernels`) and move mu by the offline trainer's schedule
(:mod:`flowchart2sdnn.fit.damping`). Float state ``fs`` and integer state ``its``: see the ``F_*`` and ``I_*``
constants of :mod:`.window`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ... import rules
from ...network.rowops import padded
from ...network.weight_program import WeightProgram, eval_weights, weight_program  # noqa: F401 - re-exported
from .window import (  # noqa: F401 - re-exported: the run's state layout and window numerics
    F_CC,
    F_CH,
    F_EE,
    F_MU,
    F_NL,
    I_ACCEPTED,
    I_BLOCK_POS,
    I_CHOL_FALLBACK,
    I_COUNT,
    I_DIVERGED,
    I_HEAD,
    I_N_DIV_T,
    I_NEXT,
    I_REJECTED,
    I_RESYNC,
    I_SINCE_RESYNC,
    I_SKIPPED,
    I_STEPS,
    N_FS,
    N_ITS,
    cholesky_solve,
    external,
    lm_step,
    mu_accepted,
    mu_refused,
    push_row,
    resync,
    rtrl,
    rtrl_sample,
    scaled_mu,
    simulate,
    simulate_sample,
    weights_at,
    window_iteration,
    window_rtrl,
    window_sim,
)

__all__ = [
    "WeightProgram",
    "weight_program",
    "OnlineState",
    "new_state",
    "online_chunk",
    "prepare",
    "eval_weights",
    "cholesky_solve",
    "scaled_mu",
    "window_sim",
    "window_rtrl",
    "external",
    "LINEARITY_TOL",
]

#: A trial is accepted when, over its block, the part of its output change that the first-order prediction
#: misses is at most this fraction of the predicted change (both as sums of squares).
LINEARITY_TOL = rules.value("linearity_tol")

STATUS_OK, STATUS_DIVERGED_BEFORE_START = 0, 1


# ------------------------------------------------------------------------------------------ state
@dataclass(frozen=True, eq=False)
class OnlineState:
    """Every array the kernel reads and mutates; sizes depend on Q, K, P and the network, never on the record.

    model:  u, x, dxdu (P,); conn_val (C,); dval (D,); a_buf (ring, N); s_buf, s_blk (ring, N, padded(P))
    trial:  u_tr, x_tr, dxdu_tr (P,); conn_tr (C,); dval_tr (D,); a_tr (ring, N)
    window: win_J (Q, n_out, P); win_c, win_e (Q, n_out); A (P, P) lower triangle; b, u_ref (P,)
    average over the last K LM steps: avg_x (K, P); avg_cost (K,)
    fs (N_FS,) float; its (N_ITS,) int; div_t (capacity,) int: samples of the first divergences
    replay (window mode; one row in trial mode): win_state, tr_state (Q, ring, N) the state before each row's
    sample (stored, trial); win_time (Q,) int its sample; e_tr (Q, n_out) the trial's errors
    """

    u: np.ndarray
    x: np.ndarray
    dxdu: np.ndarray
    conn_val: np.ndarray
    dval: np.ndarray
    a_buf: np.ndarray
    s_buf: np.ndarray
    s_blk: np.ndarray
    u_tr: np.ndarray
    x_tr: np.ndarray
    dxdu_tr: np.ndarray
    conn_tr: np.ndarray
    dval_tr: np.ndarray
    a_tr: np.ndarray
    history: np.ndarray
    win_J: np.ndarray
    win_c: np.ndarray
    win_e: np.ndarray
    A: np.ndarray
    b: np.ndarray
    u_ref: np.ndarray
    avg_x: np.ndarray
    avg_cost: np.ndarray
    fs: np.ndarray
    its: np.ndarray
    div_t: np.ndarray
    win_state: np.ndarray
    win_time: np.ndarray
    e_tr: np.ndarray
    tr_state: np.ndarray

    def model(self) -> tuple:
        return (self.u, self.x, self.dxdu, self.conn_val, self.dval, self.a_buf, self.s_buf, self.s_blk)

    def trial(self) -> tuple:
        return (self.u_tr, self.x_tr, self.dxdu_tr, self.conn_tr, self.dval_tr, self.a_tr, self.history)

    def window(self) -> tuple:
        return (self.win_J, self.win_c, self.win_e, self.A, self.b, self.u_ref)

    def replay(self) -> tuple:
        return (self.win_state, self.win_time, self.e_tr, self.tr_state)

    def nbytes(self) -> int:
        """Total bytes of the state arrays."""
        return sum(int(getattr(self, f).nbytes) for f in self.__dataclass_fields__)


def new_state(u0: np.ndarray, n_connections: int, n_slots: int, history: np.ndarray, ring: int, window: int,
              n_outputs: int, average: int, mu0: float, div_capacity: int = 1000,
              replay: bool = False) -> OnlineState:
    """Allocate the state of a run starting at internal parameters `u0` with the network at its history
    (`replay`: the stored states of the window mode, else one dummy row)."""
    p = u0.shape[0]
    n = history.shape[0]
    a_buf = np.empty((ring, n))
    a_buf[:] = history
    fs = np.zeros(N_FS)
    fs[F_MU] = mu0
    rows = window if replay else 1
    rows_s = (ring, n, padded(p))  # sensitivity rows padded for the RTRL step's vector operations
    return OnlineState(
        u=np.array(u0, dtype=float), x=np.zeros(p), dxdu=np.zeros(p), conn_val=np.zeros(n_connections),
        dval=np.zeros(n_slots), a_buf=a_buf, s_buf=np.zeros(rows_s), s_blk=np.zeros(rows_s),
        u_tr=np.array(u0, dtype=float), x_tr=np.zeros(p), dxdu_tr=np.zeros(p), conn_tr=np.zeros(n_connections),
        dval_tr=np.zeros(n_slots), a_tr=a_buf.copy(), history=np.array(history, dtype=float),
        win_J=np.zeros((window, n_outputs, p)), win_c=np.zeros((window, n_outputs)),
        win_e=np.zeros((window, n_outputs)), A=np.zeros((p, p)), b=np.zeros(p), u_ref=np.array(u0, dtype=float),
        avg_x=np.zeros((average, p)), avg_cost=np.zeros(average),
        fs=fs, its=np.zeros(N_ITS, dtype=np.int64), div_t=np.zeros(div_capacity, dtype=np.int64),
        win_state=np.zeros((rows, ring, n)), win_time=np.zeros(rows, dtype=np.int64),
        e_tr=np.zeros((rows, n_outputs)), tr_state=np.zeros((rows, ring, n)),
    )


@numba.njit(cache=True)
def prepare(st_model, st_trial, bnd, wp, stack):
    """Weights of the model and the trial at their start parameters; False when they are not finite."""
    u, x, dxdu, conn_val, dval = st_model[0], st_model[1], st_model[2], st_model[3], st_model[4]
    ok = weights_at(u, x, dxdu, conn_val, dval, bnd, wp, stack)
    u_tr, x_tr, dxdu_tr, conn_tr, dval_tr = st_trial[0], st_trial[1], st_trial[2], st_trial[3], st_trial[4]
    u_tr[:] = u
    weights_at(u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, bnd, wp, stack)
    return ok


@numba.njit(cache=True)
def _note_divergence(t, div_t, its):
    if its[I_N_DIV_T] < div_t.shape[0]:
        div_t[its[I_N_DIV_T]] = t
        its[I_N_DIV_T] += 1
    its[I_DIVERGED] += 1


# ------------------------------------------------------------------------------------------ trial mode
@numba.njit(cache=True)
def _new_block(stm, stt, bnd, wp, stack, fs, its):
    """The trial restarts from the model (parameters and state); block sums and sensitivities restart at 0."""
    u, a_buf, s_blk = stm[0], stm[5], stm[7]
    u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, a_tr = stt[0], stt[1], stt[2], stt[3], stt[4], stt[5]
    u_tr[:] = u
    weights_at(u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, bnd, wp, stack)
    a_tr[:, :] = a_buf
    s_blk[:, :, :] = 0.0
    fs[F_CH] = 0.0
    fs[F_NL] = 0.0
    its[I_BLOCK_POS] = 0


@numba.njit(cache=True)
def _adopt_trial(stm, stt, bnd, wp, stack):
    """The model takes the trial's parameters and state (its sensitivities are kept: first order)."""
    u, x, dxdu, conn_val, dval, a_buf = stm[0], stm[1], stm[2], stm[3], stm[4], stm[5]
    u[:] = stt[0]
    weights_at(u, x, dxdu, conn_val, dval, bnd, wp, stack)
    a_buf[:, :] = stt[5]


# ------------------------------------------------------------------------------------------ the kernel
@numba.njit(cache=True)
def online_chunk(t0, t1, inputs, targets, net, wp, bnd, fopt, iopt, stm, stt, wnd, rsm, avg, fs, its, div_t,
                 rec_x, rec_cost, rec_mu):
    """Advance the quasi-online run over samples ``[t0, t1)`` (global indices into `inputs`/`targets`).

    net  = (conn_ptr, conn_kind, conn_src, conn_delay, transfer, dptr, dtheta, output_index, substeps N);
           `inputs` has one row per network step (N per sample), `targets` one per sample
    wp   = :attr:`WeightProgram.exprs`;  bnd = (bound code (P,) int, lower (P,), upper (P,))
    fopt = [mu_inc, mu_dec, mu_min, mu_max, tau]
    iopt = [start, every, block, record_every, stack size, tries, min_block]  (tries 0: trial mode)
    stm, stt, wnd = :meth:`OnlineState.model`, ``.trial``, ``.window``;  avg = (avg_x, avg_cost)
    rsm  = :meth:`OnlineState.replay` (window mode: the state before each row's sample, its time, scratch)
    rec_x (n_rec, P), rec_cost, rec_mu (n_rec,): records at the samples ``t % record_every == 0``.

    Returns STATUS_OK, or STATUS_DIVERGED_BEFORE_START when the model diverged at its start parameters.
    """
    u, x, dxdu, conn_val, dval, a_buf, s_buf, s_blk = stm
    u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, a_tr, history = stt
    win_J, win_c, win_e, A, b, u_ref = wnd
    avg_x, avg_cost = avg
    output_index = net[7]
    mu_inc, mu_dec, mu_min, mu_max = fopt[0], fopt[1], fopt[2], fopt[3]
    start, every, block, record_every = iopt[0], iopt[1], iopt[2], iopt[3]
    tries, min_block = iopt[5], iopt[6]
    replay = tries > 0
    win_state, win_time = rsm[0], rsm[1]
    n_theta = u.shape[0]
    n_out = output_index.shape[0]
    ring = a_buf.shape[0]
    window = win_J.shape[0]
    stack = np.empty(iopt[4])
    slot_of = np.empty(ring, dtype=np.int64)
    dn = np.empty(s_buf.shape[2])
    dn2 = np.empty(s_buf.shape[2])
    e = np.empty(n_out)
    J = np.empty((n_out, n_theta))
    M = np.empty((n_theta, n_theta))
    L = np.empty((n_theta, n_theta))
    g = np.empty(n_theta)
    delta = np.empty(n_theta)
    u_save = np.empty(n_theta)
    before = np.empty_like(a_buf)
    for t in range(t0, t1):
        active = t >= start
        if t == start:
            _new_block(stm, stt, bnd, wp, stack, fs, its)
        if replay:
            before[:, :] = a_buf
        slot = rtrl_sample(t, inputs, net, conn_val, dval, a_buf, s_buf, s_blk, active and not replay, slot_of, dn,
                           dn2)
        sq = 0.0
        jj = 0.0
        for o in range(n_out):
            r = output_index[o]
            e[o] = targets[t, o] - a_buf[slot, r]
            sq += e[o] * e[o]
            for p in range(n_theta):
                J[o, p] = s_buf[slot, r, p] * dxdu[p]
                jj += J[o, p] * J[o, p]
        # a row whose square, summed Q times, overflows would wreck the window sums: a divergence too
        model_ok = math.isfinite(sq * window) and math.isfinite(jj * window)
        trial_ok = True
        nl = 0.0
        ch = 0.0
        if active and replay:
            trial_ok = False  # no trial runs alongside: a diverged model restarts from the history
        elif active:
            simulate_sample(t, inputs, net, conn_tr, a_tr, slot_of)  # its last step's slot is the model's
            st = 0.0
            for o in range(n_out):
                r = output_index[o]
                et = targets[t, o] - a_tr[slot, r]
                st += et * et
                lin = 0.0  # first-order change of the output from the block sensitivities
                for p in range(n_theta):
                    lin += s_blk[slot, r, p] * dxdu[p] * (u_tr[p] - u[p])
                ch += lin * lin
                nl += (et - (e[o] - lin)) ** 2
            trial_ok = math.isfinite(st * window) and math.isfinite(nl)
        if not model_ok:
            if not active:
                return STATUS_DIVERGED_BEFORE_START
            _note_divergence(t, div_t, its)
            if trial_ok:
                _adopt_trial(stm, stt, bnd, wp, stack)
            else:
                for s in range(ring):
                    a_buf[s, :] = history
            s_buf[:, :, :] = 0.0
            fs[F_MU] = mu_refused(fs[F_MU], mu_inc, mu_max)
            _new_block(stm, stt, bnd, wp, stack, fs, its)
        elif replay:
            h = its[I_HEAD]
            push_row(e, J, win_J, win_c, win_e, A, b, u_ref, u, fs, its)
            win_state[h] = before
            win_time[h] = t
            if active:
                its[I_BLOCK_POS] += 1
                # an iteration costs in proportion to the rows: iterate more often while the window fills
                if its[I_BLOCK_POS] >= max(min_block, (block * its[I_COUNT]) // window):
                    its[I_BLOCK_POS] = 0
                    window_iteration(inputs, targets, net, wp, bnd, fopt, tries, stm, stt, wnd, rsm, fs, its,
                                      stack, slot_of, M, L, g, delta, dn, dn2)
                k = its[I_STEPS] % avg_x.shape[0]  # window mode: every sample from `start` is a step
                avg_x[k, :] = x
                avg_cost[k] = 0.5 * max(fs[F_EE], 0.0)
                its[I_STEPS] += 1
        else:
            push_row(e, J, win_J, win_c, win_e, A, b, u_ref, u, fs, its)
            if active and not trial_ok:
                _note_divergence(t, div_t, its)
                its[I_REJECTED] += 1
                fs[F_MU] = mu_refused(fs[F_MU], mu_inc, mu_max)
                _new_block(stm, stt, bnd, wp, stack, fs, its)
            elif active:
                fs[F_CH] += ch
                fs[F_NL] += nl
                its[I_BLOCK_POS] += 1
                if its[I_BLOCK_POS] >= block:
                    if fs[F_NL] <= LINEARITY_TOL * fs[F_CH]:
                        _adopt_trial(stm, stt, bnd, wp, stack)
                        fs[F_MU] = mu_accepted(fs[F_MU], mu_dec, mu_min)
                        its[I_ACCEPTED] += 1
                    else:
                        fs[F_MU] = mu_refused(fs[F_MU], mu_inc, mu_max)
                        its[I_REJECTED] += 1
                    _new_block(stm, stt, bnd, wp, stack, fs, its)
                if (t - start) % every == 0:
                    if lm_step(A, b, u_ref, u, fs[F_MU], mu_inc, M, L, g, delta, its):
                        u_save[:] = u_tr
                        for p in range(n_theta):
                            u_tr[p] = u[p] + delta[p]
                        if not weights_at(u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, bnd, wp, stack):
                            u_tr[:] = u_save  # a gain such as 1/J2 failed there: keep the previous trial
                            weights_at(u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, bnd, wp, stack)
                            _note_divergence(t, div_t, its)
                    k = its[I_STEPS] % avg_x.shape[0]
                    avg_x[k, :] = x
                    avg_cost[k] = 0.5 * max(fs[F_EE], 0.0)
                    its[I_STEPS] += 1
        if t % record_every == 0:
            i = t // record_every
            rec_x[i, :] = x
            rec_cost[i] = 0.5 * max(fs[F_EE], 0.0)
            rec_mu[i] = fs[F_MU]
        its[I_NEXT] = t + 1
    return STATUS_OK

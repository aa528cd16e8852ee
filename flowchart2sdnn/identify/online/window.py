"""The window numerics of the quasi-online LM run (:mod:`.kernel` states the algorithm).

numba functions on the arrays of :class:`.kernel.OnlineState`: the bound transform and the weights at
a parameter point, the FIFO window's running sums of the normal equations, the damped LM step by Cholesky,
and the window mode's iteration (simulate the window's samples again at a trial, relinearise an accepted
one). The network steps are those of the offline kernels (:func:`flowchart2sdnn.network.kernels.rtrl_step`,
:func:`~flowchart2sdnn.network.kernels.simulate_step`), the damping schedule that of the offline trainer
(:mod:`flowchart2sdnn.fit.damping`), compiled here.

Layer: identify/, so it may build on both network/ (the steps) and fit/ (the schedule), which know nothing of
each other. Float state ``fs`` and integer state ``its``: see the ``F_*`` and ``I_*`` constants.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ...fit import damping
from ...network.kernels import ix, rtrl_step, simulate_step
from ...network.weight_program import eval_weights

F_MU, F_EE, F_CC, F_CH, F_NL = range(5)
(I_COUNT, I_HEAD, I_STEPS, I_BLOCK_POS, I_ACCEPTED, I_REJECTED, I_DIVERGED, I_CHOL_FALLBACK,
 I_SKIPPED, I_RESYNC, I_N_DIV_T, I_NEXT, I_SINCE_RESYNC) = range(13)
N_FS, N_ITS = 5, 13

mu_accepted = numba.njit(cache=True)(damping.mu_accepted)
mu_refused = numba.njit(cache=True)(damping.mu_refused)
_first_mu = numba.njit(cache=True)(damping.first_mu)


# ------------------------------------------------------------------------------------------ small numerics
@numba.njit(cache=True, inline="always")
def external(u, kind, lo, hi, x, dxdu):
    """x(u) and dx/du, the formulas of fit/transforms.py (result clipped into [lo, hi] for two bounds)."""
    for i in range(u.shape[0]):
        k = kind[i]
        ui = u[i]
        if k == 0:
            x[i] = ui
            dxdu[i] = 1.0
        elif k == 1 or k == 2:
            root = math.sqrt(ui * ui + 1.0)
            r = ui * ui / (root + 1.0)  # = sqrt(u^2+1) - 1 without cancellation
            if k == 1:
                x[i] = lo[i] + r
                dxdu[i] = ui / root
            else:
                x[i] = hi[i] - r
                dxdu[i] = -ui / root
        else:
            half = 0.5 * hi[i] - 0.5 * lo[i]
            centre = 0.5 * lo[i] + 0.5 * hi[i]
            x[i] = min(max(centre + half * math.sin(ui), lo[i]), hi[i])
            dxdu[i] = half * math.cos(ui)


@numba.njit(cache=True)
def cholesky_solve(M, rhs, L, out):
    """Solve M out = rhs for symmetric M (P, P) by Cholesky M = L L^T; False if M is not positive definite.

    Only the lower triangle of M is read. `L` (P, P) is scratch.
    """
    n = M.shape[0]
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0 or not math.isfinite(s):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
    for i in range(n):  # L z = rhs
        s = rhs[i]
        for k in range(i):
            s -= L[i, k] * out[k]
        out[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):  # L^T out = z
        s = out[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]
    for i in range(n):
        if not math.isfinite(out[i]):
            return False
    return True


@numba.njit(cache=True)
def weights_at(u, x, dxdu, conn_val, dval, bnd, wp, stack):
    """x, dx/du and the weights at u; False when a weight is not finite."""
    external(u, bnd[0], bnd[1], bnd[2], x, dxdu)
    return eval_weights(x, wp, conn_val, dval, stack)


# ------------------------------------------------------------------------------------------ network steps
# `net` = (conn_ptr, conn_kind, conn_src, conn_delay, transfer, dptr, dtheta, output_index, [substeps]) (the
# last an int64 array of one, so that the tuple stays uniform); the steps are inlined here, so the run keeps
# strict IEEE order (no fastmath) as before the steps were shared; these wrappers are inlined in turn into the
# per-sample and per-row loops (a call per sample passed ~100 arguments).
# Sub-steps (issue 13): a data sample is N = substeps network steps, the offline kernels' stride. `inputs` then
# holds one row per network step (each sample held over its N steps, OnlineRun.step_inputs), the step counter
# counts steps (ring slots ``step % ring``, delays in steps), and a sample's output is read at its last step.
@numba.njit(cache=True, inline="always")
def rtrl(t, inputs, net, conn_val, dval, a_buf, s_buf, s_blk, with_blk, slot_of, dn, dn2):
    """:func:`~flowchart2sdnn.network.kernels.rtrl_step` at network step t on the run's arrays."""
    conn_ptr, conn_kind, conn_src, conn_delay, transfer, dptr, dtheta, _, _ = net
    rtrl_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval, transfer,
              a_buf, s_buf, s_blk, with_blk, slot_of, dn, dn2)


@numba.njit(cache=True, inline="always")
def simulate(t, inputs, net, conn_val, a_buf, slot_of):
    """:func:`~flowchart2sdnn.network.kernels.simulate_step` at network step t on the run's arrays."""
    conn_ptr, conn_kind, conn_src, conn_delay, transfer, _, _, _, _ = net
    simulate_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, transfer, a_buf, slot_of)


@numba.njit(cache=True, inline="always")
def rtrl_sample(t, inputs, net, conn_val, dval, a_buf, s_buf, s_blk, with_blk, slot_of, dn, dn2):
    """:func:`rtrl` through the N steps of sample t; returns the ring slot of its last step (its output and
    sensitivities)."""
    n_sub = net[8][0]
    first = t * n_sub
    for step in range(first, first + n_sub):
        rtrl(step, inputs, net, conn_val, dval, a_buf, s_buf, s_blk, with_blk, slot_of, dn, dn2)
    return (first + n_sub - 1) % a_buf.shape[0]


@numba.njit(cache=True, inline="always")
def simulate_sample(t, inputs, net, conn_val, a_buf, slot_of):
    """:func:`simulate` through the N steps of sample t; returns the ring slot of its last step."""
    n_sub = net[8][0]
    first = t * n_sub
    for step in range(first, first + n_sub):
        simulate(step, inputs, net, conn_val, a_buf, slot_of)
    return (first + n_sub - 1) % a_buf.shape[0]


# ------------------------------------------------------------------------------------------ window
@numba.njit(cache=True)
def resync(win_J, win_c, win_e, A, b, u_ref, u, fs, its):
    """Recompute the window sums from the ring (valid rows ``head - count .. head - 1``), re-referenced to u."""
    window, n_out, n_theta = win_J.shape
    A[:, :] = 0.0
    b[:] = 0.0
    cc = 0.0
    ee = 0.0
    count = its[I_COUNT]
    q = (its[I_HEAD] - count + window) % window
    for _ in range(count):
        for o in range(n_out):
            jq = win_J[ix(q), ix(o)]
            shift = 0.0
            for p in range(n_theta):
                shift += jq[ix(p)] * (u[ix(p)] - u_ref[ix(p)])
            c = win_c[ix(q), ix(o)] - shift
            win_c[ix(q), ix(o)] = c
            cc += c * c
            ee += win_e[ix(q), ix(o)] * win_e[ix(q), ix(o)]
            for p in range(n_theta):
                jp = jq[ix(p)]
                for r in range(p + 1):
                    A[ix(p), ix(r)] += jp * jq[ix(r)]
                b[ix(p)] += jp * c
        q = q + 1 if q + 1 < window else 0
    u_ref[:] = u
    fs[F_CC] = cc
    fs[F_EE] = ee


@numba.njit(cache=True)
def push_row(e, J, win_J, win_c, win_e, A, b, u_ref, u, fs, its):
    """FIFO: drop the oldest row when the window is full, add (J, e); resync every Q pushes."""
    window, n_out, n_theta = win_J.shape
    h = its[I_HEAD]
    if its[I_COUNT] == window:  # full: the oldest row sits at the head
        for o in range(n_out):
            jo = win_J[h, o]
            co = win_c[h, o]
            fs[F_CC] -= co * co
            fs[F_EE] -= win_e[h, o] * win_e[h, o]
            for p in range(n_theta):
                for r in range(p + 1):
                    A[p, r] -= jo[p] * jo[r]
                b[p] -= jo[p] * co
    else:
        its[I_COUNT] += 1
    for o in range(n_out):
        c = e[o]
        for p in range(n_theta):
            c += J[o, p] * (u[p] - u_ref[p])
        win_c[h, o] = c
        win_e[h, o] = e[o]
        fs[F_CC] += c * c
        fs[F_EE] += e[o] * e[o]
        for p in range(n_theta):
            win_J[h, o, p] = J[o, p]
            for r in range(p + 1):
                A[p, r] += J[o, p] * J[o, r]
            b[p] += J[o, p] * c
    its[I_HEAD] = (h + 1) % window
    its[I_SINCE_RESYNC] += 1
    if its[I_SINCE_RESYNC] >= window:
        resync(win_J, win_c, win_e, A, b, u_ref, u, fs, its)
        its[I_SINCE_RESYNC] = 0
        its[I_RESYNC] += 1


@numba.njit(cache=True)
def lm_step(A, b, u_ref, u, mu, mu_inc, M, L, g, delta, its):
    """The LM step from u: (A + mu I) delta = g = b - A (u - u_ref) by Cholesky. When rounding makes the matrix
    indefinite the damping grows from 1e-14 max diag(A) (it is then a numerical regularisation, not mu).
    False when nothing works (no step)."""
    n = u.shape[0]
    diag_max = 0.0
    for p in range(n):
        diag_max = max(diag_max, A[p, p])
    for p in range(n):
        s = b[p]
        for r in range(n):
            s -= (A[p, r] if r <= p else A[r, p]) * (u[r] - u_ref[r])
        g[p] = s
    m = mu
    for attempt in range(64):
        for p in range(n):
            for r in range(p + 1):
                M[p, r] = A[p, r]
            M[p, p] += m
        if cholesky_solve(M, g, L, delta):
            if attempt > 0:
                its[I_CHOL_FALLBACK] += 1
            return True
        m = max(m * mu_inc, 1e-14 * diag_max)
        if m > max(1e300, diag_max):
            break
    its[I_SKIPPED] += 1
    return False


@numba.njit(cache=True)
def scaled_mu(A, mu0, tau, mu_max):
    """The first damping scaled to the window, :func:`flowchart2sdnn.fit.damping.first_mu` in the same
    internal coordinates; `A` holds JᵀJ in its lower triangle. A non-finite diagonal entry is passed over
    (a window sum, unlike the offline JᵀJ, is never left overflowed: such rows are refused)."""
    peak = 0.0
    for p in range(A.shape[0]):
        if math.isfinite(A[p, p]):
            peak = max(peak, A[p, p])
    return _first_mu(peak, mu0, tau, mu_max)


# ------------------------------------------------------------------------------------------ window mode
@numba.njit(cache=True, inline="always")
def _record_outputs(cost, tq, q, slot, output_index, targets, a, s, dxdu, e_out, c_out, J_out, with_sens):
    """Each output's error at sample `tq` (the network's outputs in ring slot `slot`) into row `q` of the replay,
    with `with_sens` its Jacobian row too; `cost` plus the squared errors, added in output order."""
    for o in range(output_index.shape[0]):
        r = ix(output_index[ix(o)])
        err = targets[ix(tq), ix(o)] - a[slot, r]
        e_out[ix(q), ix(o)] = err
        cost += err * err
        if with_sens:
            c_out[ix(q), ix(o)] = err
            for p in range(dxdu.shape[0]):
                J_out[ix(q), ix(o), ix(p)] = s[slot, r, ix(p)] * dxdu[ix(p)]
    return cost


@numba.njit(cache=True)
def _replay(inputs, targets, net, conn, dval, dxdu, a, s, s_blk, with_sens, win_state, win_time, its, states,
            e_out, c_out, J_out, limit, slot_of, dn, dn2):
    """Run the window's samples again, oldest first, from the stored state before the oldest row (a gap left
    by a skipped row restarts from that row's stored state, sensitivities from zero).

    Per row q: the state before its sample into ``states[q]``, its error into ``e_out[q]``; with `with_sens`
    (RTRL) also into ``c_out[q]`` and its Jacobian row into ``J_out[q]``. Returns 1/2 the sum of the squared
    errors; without `with_sens`, inf once that exceeds `limit` or is not finite."""
    window = win_time.shape[0]
    output_index = net[7]
    count = its[I_COUNT]
    head = its[I_HEAD]
    ring = a.shape[0]
    n_state = a.size
    states_flat = states.reshape(states.size)  # copied as one flat loop: the 2-D copy cost 0.1 us per row
    a_flat = a.reshape(n_state)
    cost = 0.0
    q = (head - count + window) % window
    i = 0
    while i < count:  # a run of consecutive samples, from its stored state (as its own loop: a restore
        a[:, :] = win_state[q]  # branch inside the per-row loop made that loop twice as slow)
        if with_sens:
            s[:, :, :] = 0.0
        prev = win_time[ix(q)] - 1
        while i < count and win_time[ix(q)] == prev + 1:
            tq = win_time[ix(q)]
            for j in range(n_state):
                states_flat[ix(q * n_state + j)] = a_flat[ix(j)]
            if with_sens:
                rtrl(tq, inputs, net, conn, dval, a, s, s_blk, False, slot_of, dn, dn2)
            else:
                simulate(tq, inputs, net, conn, a, slot_of)
            slot = ix(tq % ring)
            cost = _record_outputs(cost, tq, q, slot, output_index, targets, a, s, dxdu, e_out, c_out, J_out,
                                   with_sens)
            if not with_sens and (not 0.5 * cost <= limit or cost > 1e300):
                return math.inf
            prev = tq
            q = q + 1 if q + 1 < window else 0
            i += 1
    return 0.5 * cost


@numba.njit(cache=True)
def _replay_substeps(inputs, targets, net, conn, dval, dxdu, a, s, s_blk, with_sens, win_state, win_time, its, states,
            e_out, c_out, J_out, limit, slot_of, dn, dn2):
    """:func:`_replay` with N > 1 network steps per sample (the states stored and restored are those at sample
    boundaries). A copy rather than a branch in :func:`_replay`: a loop over sub-steps in that function made its
    one-step rows 2.5x slower (measured on the paper's motor stage; the same bits either way); here one step
    loop per branch (rather than :func:`rtrl_sample` / :func:`simulate_sample`) ran 23 % faster at N = 3."""
    window = win_time.shape[0]
    output_index = net[7]
    count = its[I_COUNT]
    head = its[I_HEAD]
    n_state = a.size
    ring = a.shape[0]
    n_sub = net[8][0]
    states_flat = states.reshape(states.size)  # copied as one flat loop: the 2-D copy cost 0.1 us per row
    a_flat = a.reshape(n_state)
    cost = 0.0
    q = (head - count + window) % window
    i = 0
    while i < count:  # a run of consecutive samples, from its stored state (as its own loop: a restore
        a[:, :] = win_state[q]  # branch inside the per-row loop made that loop twice as slow)
        if with_sens:
            s[:, :, :] = 0.0
        prev = win_time[ix(q)] - 1
        while i < count and win_time[ix(q)] == prev + 1:
            tq = win_time[ix(q)]
            for j in range(n_state):
                states_flat[ix(q * n_state + j)] = a_flat[ix(j)]
            first = tq * n_sub
            if with_sens:
                for step in range(first, first + n_sub):
                    rtrl(step, inputs, net, conn, dval, a, s, s_blk, False, slot_of, dn, dn2)
            else:
                for step in range(first, first + n_sub):
                    simulate(step, inputs, net, conn, a, slot_of)
            slot = ix((first + n_sub - 1) % ring)
            cost = _record_outputs(cost, tq, q, slot, output_index, targets, a, s, dxdu, e_out, c_out, J_out,
                                   with_sens)
            if not with_sens and (not 0.5 * cost <= limit or cost > 1e300):
                return math.inf
            prev = tq
            q = q + 1 if q + 1 < window else 0
            i += 1
    return 0.5 * cost


@numba.njit(cache=True)
def window_sim(inputs, targets, net, conn, win_state, win_time, its, a_tr, slot_of, e_tr, tr_state,
               limit=math.inf):
    """Simulate the window's samples again with the connection values `conn` (a trial), see :func:`_replay`.

    Writes each row's error to `e_tr` and the state before its sample to `tr_state` (indexed like the rows);
    `a_tr` ends as the state after the newest sample. Returns 1/2 the sum of the squared errors, inf when the
    run is not finite or as soon as that cost exceeds `limit` (a refused trial need not be run to its end)."""
    no_s = np.empty((1, 1, 1))
    no_p = np.empty(0)
    if net[8][0] == 1:
        return _replay(inputs, targets, net, conn, no_p, no_p, a_tr, no_s, no_s, False, win_state, win_time, its,
                       tr_state, e_tr, e_tr, no_s, limit, slot_of, no_p, no_p)
    return _replay_substeps(inputs, targets, net, conn, no_p, no_p, a_tr, no_s, no_s, False, win_state, win_time,
                            its, tr_state, e_tr, e_tr, no_s, limit, slot_of, no_p, no_p)


@numba.njit(cache=True)
def window_rtrl(inputs, targets, net, stm, wnd, win_state, win_time, its, slot_of, dn, dn2):
    """Relinearise the window at the model's parameters: simulate its samples again with RTRL (sensitivities
    zero before the oldest row and after a gap) and replace every row's Jacobian, error and stored state.

    The model ends with the state and sensitivities after the newest sample; the window sums are not touched
    (call :func:`resync`)."""
    dxdu, conn_val, dval, a_buf, s_buf, s_blk = stm[2], stm[3], stm[4], stm[5], stm[6], stm[7]
    win_J, win_c, win_e = wnd[0], wnd[1], wnd[2]
    if net[8][0] == 1:
        _replay(inputs, targets, net, conn_val, dval, dxdu, a_buf, s_buf, s_blk, True, win_state, win_time, its,
                win_state, win_e, win_c, win_J, math.inf, slot_of, dn, dn2)
    else:
        _replay_substeps(inputs, targets, net, conn_val, dval, dxdu, a_buf, s_buf, s_blk, True, win_state, win_time,
                         its, win_state, win_e, win_c, win_J, math.inf, slot_of, dn, dn2)


@numba.njit(cache=True)
def window_iteration(inputs, targets, net, wp, bnd, fopt, tries, stm, stt, wnd, rsm, fs, its, stack, slot_of,
                      M, L, g, delta, dn, dn2):
    """One LM iteration on the window (module docstring, window mode): up to `tries` trials, each judged by
    the window cost of a new simulation at the trial; the accepted one is relinearised."""
    mu_inc, mu_dec, mu_min, mu_max, tau = fopt[0], fopt[1], fopt[2], fopt[3], fopt[4]
    u, x, dxdu, conn_val, dval = stm[0], stm[1], stm[2], stm[3], stm[4]
    u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, a_tr = stt[0], stt[1], stt[2], stt[3], stt[4], stt[5]
    win_J, win_c, win_e, A, b, u_ref = wnd
    win_state, win_time, e_tr, tr_state = rsm
    cost_u = 0.5 * max(fs[F_EE], 0.0)  # the rows' errors are those of the run at u (relinearised or new)
    for _ in range(tries):
        if its[I_ACCEPTED] + its[I_REJECTED] == 0 and tau > 0.0:
            fs[F_MU] = scaled_mu(A, fs[F_MU], tau, mu_max)
        if not lm_step(A, b, u_ref, u, fs[F_MU], mu_inc, M, L, g, delta, its):
            break
        for p in range(u.shape[0]):
            u_tr[p] = u[p] + delta[p]
        cost = math.inf
        if weights_at(u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, bnd, wp, stack):
            cost = window_sim(inputs, targets, net, conn_tr, win_state, win_time, its, a_tr, slot_of, e_tr,
                              tr_state, cost_u)
        if cost < cost_u:
            u[:] = u_tr
            weights_at(u, x, dxdu, conn_val, dval, bnd, wp, stack)
            window_rtrl(inputs, targets, net, stm, wnd, win_state, win_time, its, slot_of, dn, dn2)
            u_ref[:] = u  # the rows are fresh at u: no first-order shift
            resync(win_J, win_c, win_e, A, b, u_ref, u, fs, its)
            fs[F_MU] = mu_accepted(fs[F_MU], mu_dec, mu_min)
            its[I_ACCEPTED] += 1
            break
        fs[F_MU] = mu_refused(fs[F_MU], mu_inc, mu_max)
        its[I_REJECTED] += 1
    u_tr[:] = u
    weights_at(u_tr, x_tr, dxdu_tr, conn_tr, dval_tr, bnd, wp, stack)

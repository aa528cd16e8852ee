"""Numba kernels: GDNN simulation (eq. 1-2 of the paper) and RTRL forward sensitivities.

Both kernels walk the flat arrays of :mod:`.flat`: at each time t, neurons in global order, each neuron over
its incoming connections. Past outputs live in a ring buffer of length ``ring = max delay + 1`` whose slots
start filled with the history, so ``a(t - d)`` for ``t - d < 0`` reads the initial state without a branch
(slot ``(t - d) mod ring`` is first written at time ``t - d + ring > t``). Inputs before t = 0 are held at
``p(0)``.

RTRL (Williams & Zipser 1989; De Jesús & Hagan 2007, written per neuron instead of per layer): with
``S_k(t) = d a_k(t) / d theta`` (a row of length P),

    dn_k/dtheta = sum_c w_c S_src(c)(t - d_c)            [neuron sources]
                + sum_c x_c(t - d_c) dw_c/dtheta         [sparse: only the theta a connection depends on]
    S_k(t)      = f'(n_k(t)) dn_k/dtheta

A product neuron (transfer code ``PRODUCT``, see :mod:`.flat`) has ``n_k = prod_c w_c x_c(t - d_c)``; its
sensitivity follows the product rule factor by factor (:func:`_product_rtrl`), without dividing by a factor
that may be zero.

The history does not depend on theta, so its sensitivities are zero. S is kept in a ring buffer too, so memory
does not grow with Q except for the (Q, n_out, P) result. The kernels never raise on non-finite values: they
propagate, and the caller checks ``np.isfinite``.

Speed (the offline trainer calls these kernels a few times per iteration at Q of 10^4 to 10^5; the networks are
small, so the cost is per-connection overhead, not flops): the rows of S are padded to a multiple of four
lanes and updated as vectors (:mod:`.rowops`); indices are cast to unsigned (:func:`ix`) so that numba
emits no negative-index wraparound per access; the accumulator ``dn`` is cleared by the vector store that
emits a neuron's row, not by a loop that LLVM turns into a ``memset`` call. The sums keep their sequential
order (no "reassoc"), so every result is the bits of the plain loops.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .rowops import axpy, emit, padded

__all__ = ["simulate_kernel", "jacobian_kernel", "simulate_pieces_kernel", "jacobian_pieces_kernel", "simulate_step",
           "rtrl_step", "padded", "ix"]

# Fused multiply-add. No "reassoc": with it LLVM vectorized the sum over a neuron's connections (gathers, from
# 8 connections on), which changed its rounding with the code around it; the loops over theta need no
# reassociation. No "nnan"/"ninf": a diverging simulation must still come back as NaN/inf for the trainer
# to reject it.
_FAST = {"contract", "nsz", "arcp"}
PRODUCT = 10  # flat.PRODUCT_CODE: a product net input with a linear transfer


@numba.njit(cache=True, inline="always")
def ix(i):
    """An index known to be >= 0, as uint64: numba then emits no negative-index wraparound for it."""
    return np.uint64(i)


@numba.njit(cache=True, inline="always")
def _transfer(code, n):
    if code == 0:
        return n
    if code == 1:
        return math.tanh(n)
    if code == 2:
        return math.sin(n)
    if code == 4:
        return min(1.0, max(-1.0, n))
    if code == 3:
        return math.cos(n)
    if code == 5:  # sqrt, odd and regularised on (-1, 1) (network.model.TRANSFERS)
        if n >= 1.0:
            return math.sqrt(n)
        if n <= -1.0:
            return -math.sqrt(-n)
        return (5.0 * n - n * n * n) * 0.25
    if code == 6:
        return abs(n)
    if code == 7:
        return math.exp(n)
    if code == 8:
        return n * n
    if code == 9:
        return n * abs(n)
    return n  # PRODUCT: linear


@numba.njit(cache=True, inline="always")
def _slope(code, n, a):
    """f'(n), given a = f(n)."""
    if code == 0:
        return 1.0
    if code == 1:
        return 1.0 - a * a
    if code == 2:
        return math.cos(n)
    if code == 4:
        return 1.0 if -1.0 < n < 1.0 else 0.0
    if code == 3:
        return -math.sin(n)
    if code == 5:  # finite at 0: 5/4
        if n >= 1.0 or n <= -1.0:
            return 0.5 / math.sqrt(abs(n))
        return (5.0 - 3.0 * n * n) * 0.25
    if code == 6:
        return 1.0 if n > 0.0 else (-1.0 if n < 0.0 else 0.0)
    if code == 7:
        return a
    if code == 8:
        return 2.0 * n
    if code == 9:
        return 2.0 * abs(n)
    return 1.0  # PRODUCT: linear


@numba.njit(cache=True, inline="always")
def _product_value(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_val, conn_delay, a_buf, slot_of):
    """Net input of the product neuron k: the product of its weighted inputs."""
    n = 1.0
    for c in range(conn_ptr[k], conn_ptr[k + 1]):
        kind = conn_kind[c]
        if kind == 0:
            x = a_buf[slot_of[conn_delay[c]], conn_src[c]]
        elif kind == 1:
            x = inputs[max(t - conn_delay[c], 0), conn_src[c]]
        else:
            x = 1.0
        n *= conn_val[c] * x
    return n


@numba.njit(cache=True, inline="always")
def _product_rtrl(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval, a_buf,
                  s_buf, slot_of, dn, hist_sens=False, in_theta=None, in_dval=None):
    """Net input of the product neuron k and its sensitivity (from the sensitivities `s_buf`) into `dn`, by the
    product rule one factor at a time: with P the product so far and dP its derivative, a factor f = w x gives
    d(P f) = dP f + P df, df = w S_src(t - d) + x dw/dtheta. Exact with zero factors (no division). Returns n."""
    n = 1.0
    for p in range(dn.shape[0]):
        dn[p] = 0.0
    for c in range(conn_ptr[k], conn_ptr[k + 1]):
        kind = conn_kind[c]
        d = conn_delay[c]
        w = conn_val[c]
        if kind == 0:
            x = a_buf[slot_of[d], conn_src[c]]
        elif kind == 1:
            x = inputs[max(t - d, 0), conn_src[c]]
        else:
            x = 1.0
        f = w * x
        for p in range(dn.shape[0]):
            dn[p] *= f
        if in_theta is not None and kind == 1 and in_theta[conn_src[c]] >= 0:  # an input with a fitted delay
            dn[in_theta[conn_src[c]]] += n * w * in_dval[max(t - d, 0), conn_src[c]]
        # before t = 0 the source is history, whose sensitivity is zero unless given (hist_sens)
        if kind == 0 and (t - d >= 0 or hist_sens):
            src_slot = slot_of[d]
            src = conn_src[c]
            nw = n * w
            for p in range(dn.shape[0]):
                dn[p] += nw * s_buf[src_slot, src, p]
        for e in range(dptr[c], dptr[c + 1]):
            dn[dtheta[e]] += n * x * dval[e]
        n *= f
    return n


@numba.njit(cache=True, inline="always")
def _slots(t, ring, slot_of):
    """Slot of ``a(t - d)`` into ``slot_of[d]`` for every d < ring (no modulo per connection); returns t's slot."""
    slot = t % ring
    s = slot
    for d in range(ring):
        slot_of[ix(d)] = s
        s = s - 1 if s > 0 else ring - 1
    return slot


@numba.njit(cache=True, inline="always")
def simulate_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, transfer, a_buf, slot_of):
    """Eq. (1)-(2) at time t: every neuron's output into slot ``t % ring`` of the ring buffer `a_buf`.

    `slot_of` (ring,) int64 is scratch. Inlined into each caller at numba-IR level, so it is lowered with the
    caller's fastmath flags: the offline kernels keep theirs, the quasi-online kernel its strict IEEE order.
    """
    ring = a_buf.shape[0]
    slot = _slots(t, ring, slot_of)
    for k in range(transfer.shape[0]):
        if transfer[k] == PRODUCT:
            a_buf[slot, k] = _product_value(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_val, conn_delay, a_buf,
                                            slot_of)
            continue
        n = 0.0
        for c in range(conn_ptr[ix(k)], conn_ptr[ix(k + 1)]):
            kind = conn_kind[ix(c)]
            d = conn_delay[ix(c)]
            if kind == 0:
                x = a_buf[ix(slot_of[ix(d)]), ix(conn_src[ix(c)])]
            elif kind == 1:
                x = inputs[ix(max(t - d, 0)), ix(conn_src[ix(c)])]
            else:
                x = 1.0
            n += conn_val[ix(c)] * x
        a_buf[ix(slot), ix(k)] = _transfer(transfer[ix(k)], n)


@numba.njit(cache=True, inline="always")
def rtrl_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval, transfer,
              a_buf, s_buf, s_blk, with_blk, slot_of, dn, dn2, hist_sens=False, in_theta=None, in_dval=None):
    """:func:`simulate_step` and the RTRL recursion of the module docstring: ``S(t)`` into slot ``t % ring``
    of `s_buf` (ring, N, n_pad).

    The rows of `s_buf`, `s_blk`, `dn` and `dn2` have the padded length ``n_pad = padded(P)`` (:mod:`.rowops`);
    nothing reads the padding lanes. With `with_blk`, a second set of sensitivities `s_blk` follows the same
    recursion (the quasi-online kernel's trial mode restarts it at zero at each block start); otherwise `s_blk`
    and `dn2` are not touched. `slot_of` (ring,) int64, `dn` and `dn2` (n_pad,) float64 are scratch.
    With `hist_sens` the slots of `s_buf` before t = 0 hold the history's own sensitivities (free initial states:
    identify.shooting.multiple) and are read like any other; otherwise they are skipped as zero (`s_blk` always is).
    `in_theta` (n_inputs,) int64 and `in_dval` (steps, n_inputs) float64, optional: input i depends on theta
    ``in_theta[i]`` (-1: on none) with derivative ``in_dval[t, i]`` at step t (a fitted dead time,
    network.inputsignal).
    """
    ring = a_buf.shape[0]
    slot = _slots(t, ring, slot_of)
    for p in range(dn.shape[0]):  # from here on each neuron's emit leaves the accumulators at zero
        dn[ix(p)] = 0.0
    if with_blk:
        for p in range(dn2.shape[0]):
            dn2[ix(p)] = 0.0
    for k in range(transfer.shape[0]):
        if transfer[k] == PRODUCT:  # linear transfer: S = dn
            a_buf[slot, k] = _product_rtrl(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr,
                                           dtheta, dval, a_buf, s_buf, slot_of, s_buf[slot, k], hist_sens, in_theta,
                                           in_dval)
            if with_blk:
                _product_rtrl(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval,
                              a_buf, s_blk, slot_of, s_blk[slot, k], False, in_theta, in_dval)
            continue
        n = 0.0
        for c in range(conn_ptr[ix(k)], conn_ptr[ix(k + 1)]):
            kind = conn_kind[ix(c)]
            d = conn_delay[ix(c)]
            w = conn_val[ix(c)]
            if kind == 0:
                src_slot = ix(slot_of[ix(d)])
                src = ix(conn_src[ix(c)])
                x = a_buf[src_slot, src]
                # before t = 0 the source is history, whose sensitivity is zero unless given (hist_sens)
                if (t - d >= 0 or hist_sens) and w != 0.0:
                    axpy(dn, w, s_buf[src_slot, src])
                if with_blk and t - d >= 0 and w != 0.0:
                    axpy(dn2, w, s_blk[src_slot, src])
            elif kind == 1:
                x = inputs[ix(max(t - d, 0)), ix(conn_src[ix(c)])]
                if in_theta is not None and in_theta[ix(conn_src[ix(c)])] >= 0:  # an input with a fitted delay
                    dx = w * in_dval[ix(max(t - d, 0)), ix(conn_src[ix(c)])]
                    dn[ix(in_theta[ix(conn_src[ix(c)])])] += dx
                    if with_blk:
                        dn2[ix(in_theta[ix(conn_src[ix(c)])])] += dx
            else:
                x = 1.0
            n += w * x
            for e in range(dptr[ix(c)], dptr[ix(c + 1)]):
                dn[ix(dtheta[ix(e)])] += x * dval[ix(e)]
                if with_blk:
                    dn2[ix(dtheta[ix(e)])] += x * dval[ix(e)]
        code = transfer[ix(k)]
        a = _transfer(code, n)
        a_buf[ix(slot), ix(k)] = a
        g = _slope(code, n, a)
        emit(s_buf[ix(slot), ix(k)], g, dn)
        if with_blk:
            emit(s_blk[ix(slot), ix(k)], g, dn2)


# nogil: multiple shooting runs its segments' kernels on threads (identify.shooting.multiple)
@numba.njit(cache=True, fastmath=_FAST, nogil=True)
def simulate_kernel(
    inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, transfer, history, ring, record, stride=1
):
    """Simulate the network; return the outputs of the neurons `record` at every `stride`-th step (the last
    of each group: sub-steps), shape (Q // stride, len(record)).

    inputs (Q, R) float64; conn_* and transfer int64 (see :class:`.flat.FlatNetwork`); conn_val (C,) float64;
    history (N,) float64; ring int; record (K,) int64 global neuron indices.
    """
    n_steps = inputs.shape[0]
    n_neurons = transfer.shape[0]
    out = np.empty((n_steps // stride, record.shape[0]))
    a_buf = np.empty((ring, n_neurons))
    for s in range(ring):
        for k in range(n_neurons):
            a_buf[s, k] = history[k]
    slot_of = np.empty(ring, dtype=np.int64)
    for t in range(n_steps):
        simulate_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, transfer, a_buf, slot_of)
        if (t + 1) % stride != 0:
            continue
        slot = ix(t % ring)
        row = ix(t // stride)
        for o in range(record.shape[0]):
            out[row, ix(o)] = a_buf[slot, ix(record[ix(o)])]
    return out


@numba.njit(cache=True, fastmath=_FAST, nogil=True)
def jacobian_kernel(
    inputs,
    conn_ptr,
    conn_kind,
    conn_src,
    conn_delay,
    conn_val,
    dptr,
    dtheta,
    dval,
    transfer,
    history,
    ring,
    record,
    n_theta,
    stride=1,
    s_init=None,
    in_theta=None,
    in_dval=None,
):
    """Outputs and their exact derivatives by RTRL, kept at every `stride`-th step as in :func:`simulate_kernel`.

    Extra arguments beyond :func:`simulate_kernel`: the sparse dw/dtheta of each connection in CSR form --
    entries ``dptr[c]:dptr[c + 1]`` of ``dtheta`` (theta index, int64) and ``dval`` (value, float64) -- and
    ``n_theta`` = P. `s_init` (N, P) float64, optional: d history / d theta, for theta that include initial
    states (multiple shooting's free segment starts); None: the history does not depend on theta.
    `in_theta`, `in_dval`: inputs that depend on theta (see :func:`rtrl_step`; None: none does).

    Returns
    -------
    y : (Q // stride, K) float64
    dy : (Q // stride, K, P) float64
    """
    n_steps = inputs.shape[0]
    n_neurons = transfer.shape[0]
    n_rec = record.shape[0]
    y = np.empty((n_steps // stride, n_rec))
    dy = np.empty((n_steps // stride, n_rec, n_theta))
    a_buf = np.empty((ring, n_neurons))
    for s in range(ring):
        for k in range(n_neurons):
            a_buf[s, k] = history[k]
    n_pad = padded(n_theta)
    s_buf = np.zeros((ring, n_neurons, n_pad))
    hist_sens = s_init is not None
    if s_init is not None:
        for s in range(ring):
            for k in range(n_neurons):
                for p in range(n_theta):
                    s_buf[s, k, p] = s_init[k, p]
    dn = np.empty(n_pad)
    slot_of = np.empty(ring, dtype=np.int64)
    for t in range(n_steps):
        rtrl_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval, transfer,
                  a_buf, s_buf, s_buf, False, slot_of, dn, dn, hist_sens, in_theta, in_dval)
        if (t + 1) % stride != 0:
            continue
        slot = ix(t % ring)
        row = ix(t // stride)
        for o in range(n_rec):
            r = ix(record[ix(o)])
            y[row, ix(o)] = a_buf[slot, r]
            for p in range(n_theta):
                dy[row, ix(o), ix(p)] = s_buf[slot, r, ix(p)]
    return y, dy


# One call for many segments of one record: the per-call Python work (checks, history, dispatch) cost as much
# as the kernel itself at multiple shooting's 250 segments of 100 samples (benchmarks/bench_shooting_iteration.py).
@numba.njit(cache=True, fastmath=_FAST, nogil=True)
def simulate_pieces_kernel(
    inputs, first, last, histories, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, transfer, ring, record,
    stride
):
    """:func:`simulate_kernel` on the samples ``first[i]:last[i]`` of `inputs` (network steps: times `stride`)
    from ``histories[i]``, for each i; the outputs stacked, shape (sum(last - first), K)."""
    total = 0
    for i in range(first.shape[0]):
        total += last[i] - first[i]
    out = np.empty((total, record.shape[0]))
    row = 0
    for i in range(first.shape[0]):
        y = simulate_kernel(inputs[first[i] * stride:last[i] * stride], conn_ptr, conn_kind, conn_src, conn_delay,
                            conn_val, transfer, histories[i], ring, record, stride)
        out[row:row + y.shape[0]] = y
        row += y.shape[0]
    return out


@numba.njit(cache=True, fastmath=_FAST, nogil=True)
def jacobian_pieces_kernel(
    inputs, first, last, histories, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval,
    transfer, ring, record, n_theta, stride, s_init, in_theta=None, in_dval=None
):
    """:func:`jacobian_kernel` on the pieces of :func:`simulate_pieces_kernel`, each from ``histories[i]`` with
    the history's sensitivities `s_init`; outputs and sensitivities stacked."""
    total = 0
    for i in range(first.shape[0]):
        total += last[i] - first[i]
    y_all = np.empty((total, record.shape[0]))
    dy_all = np.empty((total, record.shape[0], n_theta))
    row = 0
    for i in range(first.shape[0]):
        y, dy = jacobian_kernel(inputs[first[i] * stride:last[i] * stride], conn_ptr, conn_kind, conn_src,
                                conn_delay, conn_val, dptr, dtheta, dval, transfer, histories[i], ring, record,
                                n_theta, stride, s_init, in_theta,
                                None if in_dval is None else in_dval[first[i] * stride:last[i] * stride])
        y_all[row:row + y.shape[0]] = y
        dy_all[row:row + y.shape[0]] = dy
        row += y.shape[0]
    return y_all, dy_all

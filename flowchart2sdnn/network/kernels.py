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
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["simulate_kernel", "jacobian_kernel", "simulate_step", "rtrl_step"]

# Reassociation and fused multiply-add let LLVM vectorize the loops over theta. No "nnan"/"ninf": a diverging
# simulation must still come back as NaN/inf for the trainer to reject it.
_FAST = {"contract", "reassoc", "nsz", "arcp"}
PRODUCT = 10  # flat.PRODUCT_CODE: a product net input with a linear transfer


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
                  s_buf, slot_of, dn):
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
        if kind == 0 and t - d >= 0:  # before t = 0 the source is history, whose sensitivity is zero
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
def simulate_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, transfer, a_buf, slot_of):
    """Eq. (1)-(2) at time t: every neuron's output into slot ``t % ring`` of the ring buffer `a_buf`.

    `slot_of` (ring,) int64 is scratch. Inlined into each caller at numba-IR level, so it is lowered with the
    caller's fastmath flags: the offline kernels keep theirs, the quasi-online kernel its strict IEEE order.
    """
    ring = a_buf.shape[0]
    slot = t % ring
    for d in range(ring):  # slot of a(t - d), refreshed each step: no modulo per connection
        slot_of[d] = (t - d + ring) % ring
    for k in range(transfer.shape[0]):
        if transfer[k] == PRODUCT:
            a_buf[slot, k] = _product_value(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_val, conn_delay, a_buf,
                                            slot_of)
            continue
        n = 0.0
        for c in range(conn_ptr[k], conn_ptr[k + 1]):
            kind = conn_kind[c]
            d = conn_delay[c]
            if kind == 0:
                x = a_buf[slot_of[d], conn_src[c]]
            elif kind == 1:
                x = inputs[max(t - d, 0), conn_src[c]]
            else:
                x = 1.0
            n += conn_val[c] * x
        a_buf[slot, k] = _transfer(transfer[k], n)


@numba.njit(cache=True, inline="always")
def rtrl_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval, transfer,
              a_buf, s_buf, s_blk, with_blk, slot_of, dn, dn2):
    """:func:`simulate_step` and the RTRL recursion of the module docstring: ``S(t)`` into slot ``t % ring``
    of `s_buf` (ring, N, P).

    With `with_blk`, a second set of sensitivities `s_blk` follows the same recursion (the quasi-online
    kernel's trial mode restarts it at zero at each block start); otherwise `s_blk` is not touched.
    `slot_of` (ring,) int64, `dn` and `dn2` (P,) float64 are scratch.
    """
    ring = a_buf.shape[0]
    n_theta = s_buf.shape[2]
    slot = t % ring
    for d in range(ring):
        slot_of[d] = (t - d + ring) % ring
    for k in range(transfer.shape[0]):
        if transfer[k] == PRODUCT:  # linear transfer: S = dn
            a_buf[slot, k] = _product_rtrl(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr,
                                           dtheta, dval, a_buf, s_buf, slot_of, s_buf[slot, k])
            if with_blk:
                _product_rtrl(t, k, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval,
                              a_buf, s_blk, slot_of, s_blk[slot, k])
            continue
        n = 0.0
        for p in range(n_theta):
            dn[p] = 0.0
        if with_blk:
            for p in range(n_theta):
                dn2[p] = 0.0
        for c in range(conn_ptr[k], conn_ptr[k + 1]):
            kind = conn_kind[c]
            d = conn_delay[c]
            w = conn_val[c]
            if kind == 0:
                src_slot = slot_of[d]
                src = conn_src[c]
                x = a_buf[src_slot, src]
                # before t = 0 the source is history, whose sensitivity is zero
                if t - d >= 0 and w != 0.0:
                    for p in range(n_theta):
                        dn[p] += w * s_buf[src_slot, src, p]
                    if with_blk:
                        for p in range(n_theta):
                            dn2[p] += w * s_blk[src_slot, src, p]
            elif kind == 1:
                x = inputs[max(t - d, 0), conn_src[c]]
            else:
                x = 1.0
            n += w * x
            for e in range(dptr[c], dptr[c + 1]):
                dn[dtheta[e]] += x * dval[e]
                if with_blk:
                    dn2[dtheta[e]] += x * dval[e]
        code = transfer[k]
        a = _transfer(code, n)
        a_buf[slot, k] = a
        g = _slope(code, n, a)
        for p in range(n_theta):
            s_buf[slot, k, p] = g * dn[p]
        if with_blk:
            for p in range(n_theta):
                s_blk[slot, k, p] = g * dn2[p]


@numba.njit(cache=True, fastmath=_FAST)
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
        slot = t % ring
        for o in range(record.shape[0]):
            out[t // stride, o] = a_buf[slot, record[o]]
    return out


@numba.njit(cache=True, fastmath=_FAST)
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
):
    """Outputs and their exact derivatives by RTRL, kept at every `stride`-th step as in :func:`simulate_kernel`.

    Extra arguments beyond :func:`simulate_kernel`: the sparse dw/dtheta of each connection in CSR form --
    entries ``dptr[c]:dptr[c + 1]`` of ``dtheta`` (theta index, int64) and ``dval`` (value, float64) -- and
    ``n_theta`` = P.

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
    s_buf = np.zeros((ring, n_neurons, n_theta))
    dn = np.empty(n_theta)
    slot_of = np.empty(ring, dtype=np.int64)
    for t in range(n_steps):
        rtrl_step(t, inputs, conn_ptr, conn_kind, conn_src, conn_delay, conn_val, dptr, dtheta, dval, transfer,
                  a_buf, s_buf, s_buf, False, slot_of, dn, dn)
        if (t + 1) % stride != 0:
            continue
        slot = t % ring
        row = t // stride
        for o in range(n_rec):
            r = record[o]
            y[row, o] = a_buf[slot, r]
            for p in range(n_theta):
                dy[row, o, p] = s_buf[slot, r, p]
    return y, dy

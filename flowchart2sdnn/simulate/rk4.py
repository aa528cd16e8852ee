"""The oracle's compiled (numba) RK4 loop: it interprets the opcode tables that :mod:`.continuous` builds from a
chart, with ``substeps`` steps per sample interval, held or linear inputs, delays and the relay feedback.

The block kinds' opcodes (SUM ... PRODUCT) are the tables' `kind` column. The helpers are inlined into
:func:`run_rk4`: one compiled function, kept whole.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .functions import chart_function

__all__ = ["SUM", "GAIN", "INTEGRATOR", "DELAY", "CONSTANT", "NONLINEAR", "FUNCTION", "PRODUCT", "run_rk4"]

SUM, GAIN, INTEGRATOR, DELAY, CONSTANT, NONLINEAR, FUNCTION, PRODUCT = range(8)
_INIT, _SAMPLE, _CONT = 0, 1, 2  # evaluation modes: at t_0, at t_k (k >= 1), inside an interval

# Block table `ti` columns: 0 signal index, 1 kind, 2-3 operand range in src/sgn, 4-5 neuron range in nl,
# 6 aux (function code or delay index), 7 delay samples.  `tf` columns: 0 k, 1 eps.
# Index arrays are unsigned so that numba emits no negative-index wraparound in the hot loop (~30% faster).


@njit(cache=True, inline="always", error_model="numpy")
def _operand(sig, src, sgn, a, b):
    acc = 0.0
    for i in range(a, b):
        acc += sgn[i] * sig[src[i]]
    return acc


@njit(cache=True, inline="always", error_model="numpy")
def _product(sig, src, sgn, a, b):
    acc = 1.0
    for i in range(a, b):
        acc *= sgn[i] * sig[src[i]]
    return acc


@njit(cache=True, inline="always", error_model="numpy")
def _evaluate(sig, order, ti, tf, src, sgn, nl, buf, zero0, mode, k):
    for j in order:
        s = ti[j, 0]
        kind = ti[j, 1]
        if kind == DELAY:
            if mode == _CONT:
                continue  # held over the interval
            n = ti[j, 7]
            d = ti[j, 6]
            if n == 0 or (mode == _INIT and zero0[d] == 0):
                sig[s] = _operand(sig, src, sgn, ti[j, 2], ti[j, 3])
            elif mode == _INIT:
                sig[s] = 0.0
            else:
                sig[s] = buf[d, k % np.int64(n)]
            continue
        if kind == PRODUCT:
            sig[s] = tf[j, 0] * _product(sig, src, sgn, ti[j, 2], ti[j, 3])
            continue
        x = _operand(sig, src, sgn, ti[j, 2], ti[j, 3])
        if kind == SUM:
            y = x
        elif kind == GAIN:
            y = tf[j, 0] * x
        elif kind == CONSTANT:
            y = tf[j, 0]
        elif kind == NONLINEAR:
            y = tf[j, 0] * x  # the linear term c x (0 without one)
            for i in range(ti[j, 4], ti[j, 5]):
                y += nl[i, 2] * math.tanh(nl[i, 0] * x + nl[i, 1])
        else:
            y = chart_function(ti[j, 6], tf[j, 0] * x, tf[j, 1])
        sig[s] = y


@njit(cache=True, inline="always", error_model="numpy")
def _derivative(x, dx, sig, order, integ, ti, tf, src, sgn, nl, buf, zero0):
    for i in range(integ.size):
        sig[ti[integ[i], 0]] = x[i]
    _evaluate(sig, order, ti, tf, src, sgn, nl, buf, zero0, _CONT, 0)
    for i in range(integ.size):
        j = integ[i]
        dx[i] = _operand(sig, src, sgn, ti[j, 2], ti[j, 3])


@njit(cache=True, inline="always", error_model="numpy")
def _input_at(inputs, i, pos, linear):
    """Input i at `pos` samples after t_0: held (the row at or before it) or linear between rows; the first row
    before t_0; past the last row, held or continued along the last two rows."""
    q = inputs.shape[0]
    if pos <= 0.0:
        return inputs[0, i]
    j = int(math.floor(pos))
    if not linear:
        return inputs[min(j, q - 1), i]
    if q == 1:
        return inputs[0, i]
    j = min(j, q - 2)
    r = min(pos - j, 2.0)
    return inputs[j, i] + r * (inputs[j + 1, i] - inputs[j, i])


@njit(cache=True, inline="always", error_model="numpy")
def _held_mean(inputs, i, a, b):
    """The held input i's mean over [a, b] (samples, b - a <= 1): a jump inside an RK4 step costs O(h^2)."""
    j = math.floor(b)
    if a >= j or b <= 0.0:
        return _input_at(inputs, i, a, False)
    return ((j - a) * _input_at(inputs, i, a, False) + (b - j) * _input_at(inputs, i, b, False)) / (b - a)


@njit(cache=True, inline="always", error_model="numpy")
def _shape_inputs(sig, inputs, in_linear, in_shift, at, a, b, skip):
    """Set the shaped inputs: linear ones at position `at` (samples), held delayed ones to their mean over the
    RK4 step [a, b]."""
    for i in range(in_linear.size):
        if i == skip or (in_linear[i] == 0 and in_shift[i] == 0.0):
            continue
        if in_linear[i] == 1:
            sig[i] = _input_at(inputs, i, at - in_shift[i], True)
        elif b > a:
            sig[i] = _held_mean(inputs, i, a - in_shift[i], b - in_shift[i])
        else:
            sig[i] = _input_at(inputs, i, a - in_shift[i], False)


@njit(cache=True, error_model="numpy")
def run_rk4(inputs, x0, ti, tf, src, sgn, nl, order, order0, integ, delays, zero0, buf_len, substeps, h,
         ctrl_i, ctrl_f, noise, rec, in_linear, in_shift):
    """Fill `rec` (Q, n_sig); return (status, k): 0 ok, 1 non-finite signal at t_k, 2 non-finite state."""
    q, n_in = inputs.shape
    sig = np.zeros(rec.shape[1])
    buf = np.zeros((delays.size, buf_len))
    x = x0.copy()
    k1 = np.empty_like(x)
    k2 = np.empty_like(x)
    k3 = np.empty_like(x)
    k4 = np.empty_like(x)
    xs = np.empty_like(x)
    relay = ctrl_f[0]
    shaped = False
    for i in range(n_in):
        shaped = shaped or in_linear[i] == 1 or in_shift[i] != 0.0
    skip = ctrl_i[1] if ctrl_i[0] == 1 else -1
    for k in range(q):
        for i in range(n_in):
            sig[i] = inputs[k, i]
        if shaped:
            _shape_inputs(sig, inputs, in_linear, in_shift, float(k), float(k), float(k), skip)
        for i in range(integ.size):
            sig[ti[integ[i], 0]] = x[i]
        # held delays first: their consumers may precede them in the order (no edges out of them)
        for d in range(delays.size):
            j = delays[d]
            n = ti[j, 7]
            if n > 0 and (k > 0 or zero0[d] == 1):
                sig[ti[j, 0]] = buf[d, k % np.int64(n)] if k > 0 else 0.0
        mode = _INIT if k == 0 else _SAMPLE
        ordk = order0 if k == 0 else order
        _evaluate(sig, ordk, ti, tf, src, sgn, nl, buf, zero0, mode, k)
        if ctrl_i[0] == 1:
            y = sig[ctrl_i[2]] + noise[k]
            if y > ctrl_f[1]:
                relay = -ctrl_f[0]
            elif y < -ctrl_f[1]:
                relay = ctrl_f[0]
            r = relay * ctrl_f[3] if abs(y) < ctrl_f[2] else relay
            sig[ctrl_i[1]] = inputs[k, ctrl_i[1]] + r
            _evaluate(sig, ordk, ti, tf, src, sgn, nl, buf, zero0, mode, k)
        for i in range(sig.size):
            rec[k, i] = sig[i]
            if not math.isfinite(sig[i]):
                return 1, k
        for d in range(delays.size):
            j = delays[d]
            n = ti[j, 7]
            if n == 0:
                continue
            v = _operand(sig, src, sgn, ti[j, 2], ti[j, 3])
            if k == 0:
                fill = 0.0 if zero0[d] == 1 else v
                for i in range(n):
                    buf[d, i] = fill
            buf[d, k % np.int64(n)] = v
        if k == q - 1:
            break
        # inputs (sig[:n_in]) and delay outputs stay as set above for the whole interval
        for sub in range(substeps):
            a, b = k + sub / substeps, k + (sub + 1.0) / substeps
            mid = k + (sub + 0.5) / substeps
            if shaped:
                _shape_inputs(sig, inputs, in_linear, in_shift, a, a, b, skip)
            _derivative(x, k1, sig, order, integ, ti, tf, src, sgn, nl, buf, zero0)
            for i in range(x.size):
                xs[i] = x[i] + 0.5 * h * k1[i]
            if shaped:
                _shape_inputs(sig, inputs, in_linear, in_shift, mid, a, b, skip)
            _derivative(xs, k2, sig, order, integ, ti, tf, src, sgn, nl, buf, zero0)
            for i in range(x.size):
                xs[i] = x[i] + 0.5 * h * k2[i]
            _derivative(xs, k3, sig, order, integ, ti, tf, src, sgn, nl, buf, zero0)
            for i in range(x.size):
                xs[i] = x[i] + h * k3[i]
            if shaped:
                _shape_inputs(sig, inputs, in_linear, in_shift, b, a, b, skip)
            _derivative(xs, k4, sig, order, integ, ti, tf, src, sgn, nl, buf, zero0)
            for i in range(x.size):
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        for i in range(x.size):
            if not math.isfinite(x[i]):
                return 2, k + 1
    return 0, 0

"""The numba kernel of the quasi-online Levenberg-Marquardt run (paper section 3.1) and its weight program.

One call of :func:`online_chunk` advances the run over samples ``[t0, t1)``; all state lives in arrays the
caller allocates once (:func:`new_state`) and the kernel mutates, so a run can be split into chunks (progress,
Ctrl-C) without changing a single number. Per sample t:

1. RTRL step (as :func:`.kernels.jacobian_kernel`, one time step) with the *current* weights: the free-running
   model output ``yhat(t)`` and ``S(t) = d a(t) / d x`` in external coordinates; the window row is
   ``J_u(t) = S_out(t) * dx/du`` and the a-priori error ``e(t) = y(t) - yhat(t)``.
2. FIFO window of the last Q rows in a ring buffer. The rows were computed with earlier parameters, so the
   error of row q at the current internal parameters u is taken to first order,
   ``e_q(u) = c_q - J_q (u - u_ref)`` with ``c_q = e_q + J_q (u_q - u_ref)``. The running sums
   ``A = sum J_q^T J_q``, ``b = sum J_q^T c_q``, ``sum c_q^2`` and ``sum e_q^2`` get the new row added and the
   leaving row subtracted; every Q pushes they are recomputed from the ring (bounding rounding drift) and
   ``u_ref`` is moved to the current u (keeping ``c_q`` small).
3. Every ``every`` samples from ``start`` on, one LM step ``(A + mu I) du = g`` with
   ``g = b - A (u - u_ref) = sum J_q^T e_q(u)``, solved by Cholesky (a larger mu when not positive definite).
   Using the stale a-priori errors instead (``g = sum J_q^T e_q``) would re-apply the same correction at every
   sample, since the window changes by one row per step: with k = 1 the parameters would run away.
4. mu rule (trainlm's x mu_inc / x mu_dec, decided without re-simulating the window): the samples from
   ``start`` on are cut into blocks of ``block`` samples. A *shadow* copy of the model runs alongside with the
   parameters frozen at the block start (a simulation only, no sensitivities). At the block end the squared
   a-priori errors of the block are compared, both models having started the block from the same state: if the
   stepping model did at least as well, the block's steps are accepted (``mu *= mu_dec``, the shadow takes the
   current parameters and state); otherwise they are rejected as trainlm rejects a step: parameters and state
   return to the shadow's, and ``mu *= mu_inc``. mu stays within ``[mu_min, mu_max]``.
5. A non-finite output, error or sensitivity is a divergence: parameters and state return to the shadow's (to
   the initial history when the shadow diverged too), the sensitivities restart from 0, mu is raised, the
   sample is skipped and the event is recorded.

Float state ``fs``: mu, sum e^2, sum c^2, block cost of the model, block cost of the shadow.
Integer state ``its``: see the ``I_*`` constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ..diagram.expr import BinOp, Neg, Num, Var
from .runtime import CompiledNetwork

__all__ = [
    "WeightProgram",
    "weight_program",
    "OnlineState",
    "new_state",
    "online_chunk",
    "eval_weights",
    "cholesky_solve",
    "BOUND_CODES",
    "set_params",
]

OP_CONST, OP_VAR, OP_NEG, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW = range(8)
_BINARY = {"+": OP_ADD, "-": OP_SUB, "*": OP_MUL, "/": OP_DIV, "^": OP_POW}
#: Transform code per quantity: none, min only, max only, both (formulas of fit/transforms.py).
BOUND_CODES = {"none": 0, "min": 1, "max": 2, "both": 3}

F_MU, F_EE, F_CC, F_EM, F_ES = range(5)
(I_COUNT, I_HEAD, I_STEPS, I_BLOCK_POS, I_ACCEPTED, I_REJECTED, I_DIVERGED, I_CHOL_FALLBACK,
 I_SKIPPED, I_RESYNC, I_N_DIV_T, I_NEXT, I_BLOCK_ROWS, I_SINCE_RESYNC) = range(14)
N_FS, N_ITS = 5, 14
STATUS_OK, STATUS_DIVERGED_BEFORE_START = 0, 1


# ------------------------------------------------------------------------------------------ weight program
@dataclass(frozen=True, eq=False)
class WeightProgram:
    """The connection values and their theta-derivatives as postfix programs numba can evaluate.

    ``exprs`` is the tuple of numba arguments read by :func:`eval_weights`: (ops, iarg, farg, ptr,
    weight_expr, weight_free, weight_conn, term_slot, term_free, theta_is_param, theta_idx, pv0, fw0).
    Programs ``0 .. n_coef-1`` are the distinct coef expressions, then one per derivative term.
    """

    exprs: tuple
    n_connections: int
    n_slots: int
    stack: int


def _postfix(expr, index: dict[str, int], ops: list, iarg: list, farg: list) -> None:
    if isinstance(expr, Num):
        ops.append(OP_CONST), iarg.append(0), farg.append(expr.value)
    elif isinstance(expr, Var):
        ops.append(OP_VAR), iarg.append(index[expr.name]), farg.append(0.0)
    elif isinstance(expr, Neg):
        _postfix(expr.arg, index, ops, iarg, farg)
        ops.append(OP_NEG), iarg.append(0), farg.append(0.0)
    elif isinstance(expr, BinOp):
        _postfix(expr.left, index, ops, iarg, farg)
        _postfix(expr.right, index, ops, iarg, farg)
        ops.append(_BINARY[expr.op]), iarg.append(0), farg.append(0.0)
    else:  # pragma: no cover - the expression language has no other node
        raise TypeError(f"unknown expression node {type(expr).__name__}")


def weight_program(compiled: CompiledNetwork) -> WeightProgram:
    """Compile the weight expressions of `compiled` (its coefs and their derivatives) for :func:`eval_weights`.

    Reads the runtime's private tables (same package): the distinct coef expressions, the weight -> coef and
    weight -> free-weight maps, the derivative terms and their connection/theta slots.
    """
    net = compiled.net
    pindex = {p.name: i for i, p in enumerate(net.parameters)}
    findex = {f.name: i for i, f in enumerate(net.free_weights)}
    ops: list[int] = []
    iarg: list[int] = []
    farg: list[float] = []
    ptr = [0]
    programs = list(compiled._exprs) + [expr for _, _, expr, _ in compiled._terms]
    for expr in programs:
        _postfix(expr, pindex, ops, iarg, farg)
        ptr.append(len(ops))
    weight_free = [findex[f] if f is not None else -1 for f in compiled._weight_free]
    term_free = [findex[f] if f is not None else -1 for _, _, _, f in compiled._terms]
    theta_is_param = [1 if n in pindex and n in compiled._theta_param else 0 for n in compiled.names]
    theta_idx = [pindex[n] if flag else findex[n] for n, flag in zip(compiled.names, theta_is_param, strict=True)]
    i64 = np.int64
    exprs = (
        np.array(ops, dtype=i64),
        np.array(iarg, dtype=i64),
        np.array(farg, dtype=float),
        np.array(ptr, dtype=i64),
        np.ascontiguousarray(compiled._weight_expr, dtype=i64),
        np.array(weight_free, dtype=i64),
        np.ascontiguousarray(compiled._flat.weight_conn, dtype=i64),
        np.ascontiguousarray(compiled._term_slot, dtype=i64),
        np.array(term_free, dtype=i64),
        np.array(theta_is_param, dtype=i64),
        np.array(theta_idx, dtype=i64),
        np.array([float(p.init) for p in net.parameters], dtype=float),
        np.array([float(f.init) for f in net.free_weights], dtype=float),
    )
    longest = max([b - a for a, b in zip(ptr[:-1], ptr[1:], strict=True)] + [1])
    return WeightProgram(exprs, compiled._flat.n_connections, int(compiled._dtheta.shape[0]), longest)


@numba.njit(cache=True)
def _run_program(ops, iarg, farg, a, b, pv, stack):
    sp = 0
    for i in range(a, b):
        op = ops[i]
        if op == 0:
            stack[sp] = farg[i]
            sp += 1
        elif op == 1:
            stack[sp] = pv[iarg[i]]
            sp += 1
        elif op == 2:
            stack[sp - 1] = -stack[sp - 1]
        else:
            r = stack[sp - 1]
            left = stack[sp - 2]
            sp -= 1
            if op == 3:
                v = left + r
            elif op == 4:
                v = left - r
            elif op == 5:
                v = left * r
            elif op == 6:
                v = left / r if r != 0.0 else np.nan  # as the runtime: a failed gain is NaN, the step is refused
            else:
                v = math.pow(left, r)  # nan/inf where the language refuses (x^0.5 of x < 0, 0^-1)
            stack[sp - 1] = v
    return stack[0]


@numba.njit(cache=True)
def eval_weights(x, wp, conn_val, dval, stack):
    """Connection values (C,) and d(connection)/d(theta) values (D,) at external theta `x`, in place.

    `wp` is :attr:`WeightProgram.exprs`; `stack` a scratch array of length >= the longest program.
    Returns True when every value is finite.
    """
    (ops, iarg, farg, ptr, weight_expr, weight_free, weight_conn, term_slot, term_free,
     theta_is_param, theta_idx, pv0, fw0) = wp
    pv = pv0.copy()
    fw = fw0.copy()
    for i in range(x.shape[0]):
        if theta_is_param[i] == 1:
            pv[theta_idx[i]] = x[i]
        else:
            fw[theta_idx[i]] = x[i]
    n_terms = term_slot.shape[0]
    n_coef = ptr.shape[0] - 1 - n_terms
    cv = np.empty(n_coef)
    for e in range(n_coef):
        cv[e] = _run_program(ops, iarg, farg, ptr[e], ptr[e + 1], pv, stack)
    conn_val[:] = 0.0
    for j in range(weight_expr.shape[0]):
        w = cv[weight_expr[j]]
        if weight_free[j] >= 0:
            w *= fw[weight_free[j]]
        conn_val[weight_conn[j]] += w
    dval[:] = 0.0
    for i in range(n_terms):
        v = _run_program(ops, iarg, farg, ptr[n_coef + i], ptr[n_coef + i + 1], pv, stack)
        if term_free[i] >= 0:
            v *= fw[term_free[i]]
        dval[term_slot[i]] += v
    ok = True
    for c in range(conn_val.shape[0]):
        if not math.isfinite(conn_val[c]):
            ok = False
    for c in range(dval.shape[0]):
        if not math.isfinite(dval[c]):
            ok = False
    return ok


# ------------------------------------------------------------------------------------------ small numerics
@numba.njit(cache=True, inline="always")
def _external(u, kind, lo, hi, x, dxdu):
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


# ------------------------------------------------------------------------------------------ state
@dataclass(frozen=True, eq=False)
class OnlineState:
    """Every array the kernel reads and mutates (sizes depend on Q, K, P and the network, never on the record).

    model:  u, x, dxdu (P,); conn_val (C,); dval (D,); a_buf (ring, N); s_buf (ring, N, P)
    shadow: u_ck (P,); conn_ck (C,); dval_ck (D,); a_ck (ring, N); s_ck (ring, N, P)
    window: win_J (Q, n_out, P); win_c, win_e (Q, n_out); A (P, P) lower triangle; b, u_ref (P,)
    average ring over the last K steps: avg_x (K, P); avg_cost (K,)
    scalars: fs (N_FS,) float; its (N_ITS,) int; div_t (capacity of recorded divergence times,) int
    """

    u: np.ndarray
    x: np.ndarray
    dxdu: np.ndarray
    conn_val: np.ndarray
    dval: np.ndarray
    a_buf: np.ndarray
    s_buf: np.ndarray
    u_ck: np.ndarray
    conn_ck: np.ndarray
    dval_ck: np.ndarray
    a_ck: np.ndarray
    s_ck: np.ndarray
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
    history: np.ndarray

    def model(self) -> tuple:
        return (self.u, self.x, self.dxdu, self.conn_val, self.dval, self.a_buf, self.s_buf,
                self.u_ck, self.conn_ck, self.dval_ck, self.a_ck, self.s_ck, self.history)

    def window(self) -> tuple:
        return (self.win_J, self.win_c, self.win_e, self.A, self.b, self.u_ref)

    def nbytes(self) -> int:
        """Total bytes of the state arrays."""
        return sum(int(getattr(self, f).nbytes) for f in self.__dataclass_fields__)


def new_state(
    u0: np.ndarray,
    n_connections: int,
    n_slots: int,
    history: np.ndarray,
    ring: int,
    window: int,
    n_outputs: int,
    average: int,
    mu0: float,
    div_capacity: int = 1000,
) -> OnlineState:
    """Allocate the state of a run starting at internal parameters `u0` with the network at its history."""
    p = u0.shape[0]
    n = history.shape[0]
    a_buf = np.empty((ring, n))
    a_buf[:] = history
    fs = np.zeros(N_FS)
    fs[F_MU] = mu0
    return OnlineState(
        u=np.array(u0, dtype=float),
        x=np.zeros(p),
        dxdu=np.zeros(p),
        conn_val=np.zeros(n_connections),
        dval=np.zeros(n_slots),
        a_buf=a_buf,
        s_buf=np.zeros((ring, n, p)),
        u_ck=np.array(u0, dtype=float),
        conn_ck=np.zeros(n_connections),
        dval_ck=np.zeros(n_slots),
        a_ck=a_buf.copy(),
        s_ck=np.zeros((ring, n, p)),
        win_J=np.zeros((window, n_outputs, p)),
        win_c=np.zeros((window, n_outputs)),
        win_e=np.zeros((window, n_outputs)),
        A=np.zeros((p, p)),
        b=np.zeros(p),
        u_ref=np.array(u0, dtype=float),
        avg_x=np.zeros((average, p)),
        avg_cost=np.zeros(average),
        fs=fs,
        its=np.zeros(N_ITS, dtype=np.int64),
        div_t=np.zeros(div_capacity, dtype=np.int64),
        history=np.array(history, dtype=float),
    )


# ------------------------------------------------------------------------------------------ kernel pieces
@numba.njit(cache=True, inline="always")
def _transfer(code, n):
    if code == 0:
        return n
    if code == 1:
        return math.tanh(n)
    if code == 2:
        return math.sin(n)
    return math.cos(n)


@numba.njit(cache=True, inline="always")
def _slope(code, n, a):
    if code == 0:
        return 1.0
    if code == 1:
        return 1.0 - a * a
    if code == 2:
        return math.cos(n)
    return -math.sin(n)


@numba.njit(cache=True)
def _rtrl_step(t, inputs, net, conn_val, dval, a_buf, s_buf, slot_of, dn):
    """One time step of eq. (1)-(2) and of RTRL (see :mod:`.kernels`) into slot ``t % ring``."""
    conn_ptr, conn_kind, conn_src, conn_delay, transfer, dptr, dtheta, _ = net
    ring = a_buf.shape[0]
    n_theta = s_buf.shape[2]
    slot = t % ring
    for d in range(ring):
        slot_of[d] = (t - d + ring) % ring
    for k in range(transfer.shape[0]):
        n = 0.0
        for p in range(n_theta):
            dn[p] = 0.0
        for c in range(conn_ptr[k], conn_ptr[k + 1]):
            kind = conn_kind[c]
            d = conn_delay[c]
            w = conn_val[c]
            if kind == 0:
                src_slot = slot_of[d]
                src = conn_src[c]
                x = a_buf[src_slot, src]
                if t - d >= 0 and w != 0.0:  # history has zero sensitivity
                    for p in range(n_theta):
                        dn[p] += w * s_buf[src_slot, src, p]
            elif kind == 1:
                x = inputs[max(t - d, 0), conn_src[c]]
            else:
                x = 1.0
            n += w * x
            for e in range(dptr[c], dptr[c + 1]):
                dn[dtheta[e]] += x * dval[e]
        a = _transfer(transfer[k], n)
        a_buf[slot, k] = a
        g = _slope(transfer[k], n, a)
        for p in range(n_theta):
            s_buf[slot, k, p] = g * dn[p]


@numba.njit(cache=True)
def _resync(win_J, win_c, win_e, A, b, u_ref, u, fs, its):
    """Recompute the window sums from the ring (valid rows ``head - count .. head - 1``), re-referenced to u."""
    window = win_J.shape[0]
    n_out = win_J.shape[1]
    n_theta = win_J.shape[2]
    A[:, :] = 0.0
    b[:] = 0.0
    cc = 0.0
    ee = 0.0
    count = its[I_COUNT]
    for i in range(count):
        q = (its[I_HEAD] - count + i + window) % window
        for o in range(n_out):
            jq = win_J[q, o]
            shift = 0.0
            for p in range(n_theta):
                shift += jq[p] * (u[p] - u_ref[p])
            c = win_c[q, o] - shift
            win_c[q, o] = c
            cc += c * c
            ee += win_e[q, o] * win_e[q, o]
            for p in range(n_theta):
                jp = jq[p]
                b[p] += jp * c
                for r in range(p + 1):
                    A[p, r] += jp * jq[r]
    for p in range(n_theta):
        u_ref[p] = u[p]
    fs[F_CC] = cc
    fs[F_EE] = ee


@numba.njit(cache=True, inline="always")
def _remove_row(h, win_J, win_c, win_e, A, b, fs):
    n_out = win_J.shape[1]
    n_theta = win_J.shape[2]
    for o in range(n_out):
        jo = win_J[h, o]
        co = win_c[h, o]
        fs[F_CC] -= co * co
        fs[F_EE] -= win_e[h, o] * win_e[h, o]
        for p in range(n_theta):
            jp = jo[p]
            b[p] -= jp * co
            for r in range(p + 1):
                A[p, r] -= jp * jo[r]


@numba.njit(cache=True)
def _pop_rows(n, win_J, win_c, win_e, A, b, fs, its):
    """Take back the n newest rows (those of a rejected block); the window shrinks by n."""
    window = win_J.shape[0]
    for _ in range(min(n, its[I_COUNT])):
        h = (its[I_HEAD] - 1 + window) % window
        _remove_row(h, win_J, win_c, win_e, A, b, fs)
        its[I_HEAD] = h
        its[I_COUNT] -= 1


@numba.njit(cache=True)
def _push_row(e, J, win_J, win_c, win_e, A, b, u_ref, u, fs, its):
    """FIFO: drop the oldest row when the window is full, add (J, e); resync when the ring wraps."""
    window = win_J.shape[0]
    n_out = win_J.shape[1]
    n_theta = win_J.shape[2]
    h = its[I_HEAD]
    if its[I_COUNT] == window:
        _remove_row(h, win_J, win_c, win_e, A, b, fs)  # when full, the oldest row sits at the head
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
            jp = J[o, p]
            win_J[h, o, p] = jp
            b[p] += jp * c
            for r in range(p + 1):
                A[p, r] += jp * J[o, r]
    its[I_BLOCK_ROWS] += 1
    h += 1
    if h == window:
        h = 0
    its[I_HEAD] = h
    its[I_SINCE_RESYNC] += 1
    if its[I_SINCE_RESYNC] >= window:
        _resync(win_J, win_c, win_e, A, b, u_ref, u, fs, its)
        its[I_SINCE_RESYNC] = 0
        its[I_RESYNC] += 1


@numba.njit(cache=True)
def _lm_step(A, b, u_ref, u, mu, mu_inc, mu_max, M, L, g, delta, its):
    """delta from (A + mu I) delta = b - A (u - u_ref); a larger mu when not positive definite. False: no step."""
    n = u.shape[0]
    diag_max = 0.0
    for p in range(n):
        diag_max = max(diag_max, A[p, p])
    for p in range(n):
        s = b[p]
        for r in range(n):
            arc = A[p, r] if r <= p else A[r, p]
            s -= arc * (u[r] - u_ref[r])
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
        # start the fallback at a size that can matter against A: rounding is relative to its diagonal
        m = max(m * mu_inc, 1e-14 * diag_max)
        if m > mu_max:
            break
    its[I_SKIPPED] += 1
    return False


@numba.njit(cache=True)
def set_params(st, bnd, wp, stack):
    """x, dx/du and the weights from st.u; False when a weight is not finite."""
    u, x, dxdu, conn_val, dval = st[0], st[1], st[2], st[3], st[4]
    _external(u, bnd[0], bnd[1], bnd[2], x, dxdu)
    return eval_weights(x, wp, conn_val, dval, stack)


@numba.njit(cache=True)
def _all_finite(a):
    for v in a.ravel():
        if not math.isfinite(v):
            return False
    return True


@numba.njit(cache=True)
def _restore(st, bnd, wp, stack):
    """Parameters, state and sensitivities back to the shadow's (to the history when it diverged too)."""
    u, a_buf, s_buf, u_ck, a_ck, s_ck, history = st[0], st[5], st[6], st[7], st[10], st[11], st[12]
    u[:] = u_ck
    set_params(st, bnd, wp, stack)
    if not (_all_finite(a_ck) and _all_finite(s_ck)):
        for s in range(a_ck.shape[0]):
            a_ck[s, :] = history
        s_ck[:, :, :] = 0.0
    a_buf[:, :] = a_ck
    s_buf[:, :, :] = s_ck


@numba.njit(cache=True)
def _checkpoint(st):
    """The shadow takes the model's parameters, weights, state and sensitivities."""
    st[7][:] = st[0]
    st[8][:] = st[3]
    st[9][:] = st[4]
    st[10][:, :] = st[5]
    st[11][:, :, :] = st[6]


@numba.njit(cache=True)
def _note_divergence(t, div_t, its):
    if its[I_N_DIV_T] < div_t.shape[0]:
        div_t[its[I_N_DIV_T]] = t
        its[I_N_DIV_T] += 1
    its[I_DIVERGED] += 1


@numba.njit(cache=True)
def _reject(st, bnd, wp, stack, wnd, fs, its, mu_inc, mu_max):
    """Take back the current block as trainlm takes back a step: its rows, parameters and state; raise mu."""
    win_J, win_c, win_e, A, b, u_ref = wnd
    _pop_rows(its[I_BLOCK_ROWS], win_J, win_c, win_e, A, b, fs, its)
    _restore(st, bnd, wp, stack)
    # the rejected rows may have been huge: subtracting them leaves rounding noise of their size in A
    _resync(win_J, win_c, win_e, A, b, u_ref, st[0], fs, its)
    its[I_SINCE_RESYNC] = 0
    its[I_RESYNC] += 1
    fs[F_MU] = min(fs[F_MU] * mu_inc, mu_max)
    fs[F_EM] = 0.0
    fs[F_ES] = 0.0
    its[I_BLOCK_POS] = 0
    its[I_BLOCK_ROWS] = 0


# ------------------------------------------------------------------------------------------ the kernel
@numba.njit(cache=True)
def online_chunk(t0, t1, inputs, targets, net, wp, bnd, fopt, iopt, st, wnd, avg, fs, its, div_t,
                 rec_x, rec_cost, rec_mu):
    """Advance the quasi-online run over samples ``[t0, t1)`` (global indices into `inputs`/`targets`).

    net  = (conn_ptr, conn_kind, conn_src, conn_delay, transfer, dptr, dtheta, output_index)
    wp   = :attr:`WeightProgram.exprs`;  bnd = (bound code (P,) int, lower (P,), upper (P,))
    fopt = [mu_inc, mu_dec, mu_min, mu_max];  iopt = [start, every, block, record_every, stack size]
    st   = :meth:`OnlineState.model`;  wnd = :meth:`OnlineState.window`;  avg = (avg_x, avg_cost)
    rec_x (n_rec, P), rec_cost, rec_mu (n_rec,): decimated records at samples ``t % record_every == 0``.

    Returns STATUS_OK, or STATUS_DIVERGED_BEFORE_START when the model diverged at its start parameters.
    """
    u, x, dxdu, conn_val, dval, a_buf, s_buf, u_ck, conn_ck, dval_ck, a_ck, s_ck, history = st
    win_J, win_c, win_e, A, b, u_ref = wnd
    avg_x, avg_cost = avg
    output_index = net[7]
    mu_inc, mu_dec, mu_min, mu_max = fopt[0], fopt[1], fopt[2], fopt[3]
    start, every, block, record_every = iopt[0], iopt[1], iopt[2], iopt[3]
    n_theta = u.shape[0]
    n_out = output_index.shape[0]
    ring = a_buf.shape[0]
    window = win_J.shape[0]
    stack = np.empty(iopt[4])
    slot_of = np.empty(ring, dtype=np.int64)
    dn = np.empty(n_theta)
    e = np.empty(n_out)
    J = np.empty((n_out, n_theta))
    M = np.empty((n_theta, n_theta))
    L = np.empty((n_theta, n_theta))
    g = np.empty(n_theta)
    delta = np.empty(n_theta)
    for t in range(t0, t1):
        if t == start:  # the shadow starts from the model as identification begins
            _checkpoint(st)
            its[I_BLOCK_ROWS] = 0
        slot = t % ring
        _rtrl_step(t, inputs, net, conn_val, dval, a_buf, s_buf, slot_of, dn)
        active = t >= start
        if active:
            _rtrl_step(t, inputs, net, conn_ck, dval_ck, a_ck, s_ck, slot_of, dn)
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
        if not (math.isfinite(sq * window) and math.isfinite(jj * window)):
            if not active:
                return STATUS_DIVERGED_BEFORE_START
            _note_divergence(t, div_t, its)
            _reject(st, bnd, wp, stack, wnd, fs, its, mu_inc, mu_max)
        else:
            _push_row(e, J, win_J, win_c, win_e, A, b, u_ref, u, fs, its)
            if active:
                fs[F_EM] += sq
                for o in range(n_out):
                    es = targets[t, o] - a_ck[slot, output_index[o]]
                    fs[F_ES] += es * es  # inf or nan when the shadow diverged: then the block is accepted
                its[I_BLOCK_POS] += 1
                if (t - start) % every == 0 and _lm_step(A, b, u_ref, u, fs[F_MU], mu_inc, mu_max, M, L, g,
                                                         delta, its):
                    for p in range(n_theta):
                        u[p] += delta[p]
                    if set_params(st, bnd, wp, stack):
                        k = its[I_STEPS] % avg_x.shape[0]
                        for p in range(n_theta):
                            avg_x[k, p] = x[p]
                        avg_cost[k] = 0.5 * max(fs[F_EE], 0.0)
                        its[I_STEPS] += 1
                    else:  # a gain such as 1/J2 failed at the new parameters: refuse this one step
                        for p in range(n_theta):
                            u[p] -= delta[p]
                        set_params(st, bnd, wp, stack)
                        _note_divergence(t, div_t, its)
                        fs[F_MU] = min(fs[F_MU] * mu_inc, mu_max)
                if its[I_BLOCK_POS] >= block:
                    if fs[F_EM] <= fs[F_ES] or not math.isfinite(fs[F_ES]):
                        fs[F_MU] = max(fs[F_MU] * mu_dec, mu_min)
                        its[I_ACCEPTED] += 1
                        _checkpoint(st)
                        fs[F_EM] = 0.0
                        fs[F_ES] = 0.0
                        its[I_BLOCK_POS] = 0
                        its[I_BLOCK_ROWS] = 0
                    else:
                        its[I_REJECTED] += 1
                        _reject(st, bnd, wp, stack, wnd, fs, its, mu_inc, mu_max)
        if t % record_every == 0:
            i = t // record_every
            for p in range(n_theta):
                rec_x[i, p] = x[p]
            rec_cost[i] = 0.5 * max(fs[F_EE], 0.0)
            rec_mu[i] = fs[F_MU]
        its[I_NEXT] = t + 1
    return STATUS_OK

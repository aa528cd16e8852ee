"""The weights of a compiled network as postfix programs a numba kernel evaluates (the quasi-online kernel).

The quasi-online run (:mod:`flowchart2sdnn.identify.online.kernel`) changes the parameters inside its numba loop, so the connection
values and their theta-derivatives cannot come from the Python runtime: the runtime's weight expressions are
compiled once into flat arrays of operations (:func:`weight_program`) that :func:`eval_weights` runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ..expr import BinOp, Neg, Num, Var
from .runtime import CompiledNetwork

__all__ = ["WeightProgram", "weight_program", "eval_weights"]

OP_CONST, OP_VAR, OP_NEG, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW = range(8)
_BINARY = {"+": OP_ADD, "-": OP_SUB, "*": OP_MUL, "/": OP_DIV, "^": OP_POW}


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

    Reads only the public :attr:`CompiledNetwork.weights` table, the parameter and free-weight lists of
    ``compiled.net`` (their start values) and ``compiled.names``.
    """
    net = compiled.net
    table = compiled.weights
    pindex = {p.name: i for i, p in enumerate(net.parameters)}
    findex = {f.name: i for i, f in enumerate(net.free_weights)}
    ops: list[int] = []
    iarg: list[int] = []
    farg: list[float] = []
    ptr = [0]
    for expr in table.coefs + table.term_expr:
        _postfix(expr, pindex, ops, iarg, farg)
        ptr.append(len(ops))
    weight_free = [findex[f] if f is not None else -1 for f in table.weight_free]
    term_free = [findex[f] if f is not None else -1 for f in table.term_free]
    theta_is_param = [1 if flag else 0 for flag in table.theta_is_param]
    theta_idx = [pindex[n] if flag else findex[n] for n, flag in zip(compiled.names, theta_is_param, strict=True)]
    i64 = np.int64
    exprs = (
        np.array(ops, dtype=i64),
        np.array(iarg, dtype=i64),
        np.array(farg, dtype=float),
        np.array(ptr, dtype=i64),
        np.array(table.weight_coef, dtype=i64),
        np.array(weight_free, dtype=i64),
        np.array(table.weight_conn, dtype=i64),
        np.array(table.term_slot, dtype=i64),
        np.array(term_free, dtype=i64),
        np.array(theta_is_param, dtype=i64),
        np.array(theta_idx, dtype=i64),
        np.array([float(p.init) for p in net.parameters], dtype=float),
        np.array([float(f.init) for f in net.free_weights], dtype=float),
    )
    longest = max([b - a for a, b in zip(ptr[:-1], ptr[1:], strict=True)] + [1])
    return WeightProgram(exprs, table.n_connections, table.n_slots, longest)


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

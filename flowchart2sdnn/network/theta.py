"""The theta of a :class:`~.model.Network` and the values of its connections at a theta, with their exact
derivatives.

theta, the vector the trainer moves, holds the free quantities: by default the non-fixed physical parameters
(``net.parameters`` order) followed by the non-fixed free weights (``net.free_weights`` order). Every weight is
``w_j = coef_j(parameters) * (free weight or 1)``, so by the chain rule

    dw_j/dp = (d coef_j / dp)(parameters) * (free weight or 1)     for a parameter p,
    dw_j/df = coef_j(parameters)                                   for the free weight f of w_j.

The symbolic derivatives are taken once here; each call evaluates them into a sparse (connection, theta,
value) list that the kernel of :mod:`.kernels` consumes. :attr:`CompiledNetwork.weights` publishes these
tables (:class:`WeightTable`) for other evaluators of the weights (:mod:`.weight_program`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..expr import Expr, parse_expr
from .flat import FlatNetwork, flatten
from .model import Network

__all__ = ["ThetaNetwork", "WeightTable"]


def _frozen(a, dtype) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class WeightTable:
    """How the connection values and their theta-derivatives follow from theta (read-only arrays).

    With W weights (``net.weights`` order), T derivative terms, D nonzero (connection, theta) slots and C
    connections:

    coefs : tuple of Expr            the distinct coef expressions
    weight_coef : (W,) int64         the coef of each weight, an index into `coefs`
    weight_free : tuple of str|None  the free weight each weight is multiplied by (None: none)
    weight_conn : (W,) int64         the connection each weight adds to (several weights may share one)
    term_expr : tuple of Expr        each term's d(coef)/d(theta) (a parameter) or coef (a free weight)
    term_free : tuple of str|None    the free weight the term is multiplied by (None: none)
    term_slot : (T,) int64           the slot each term adds to
    slot_theta : (D,) int64          the theta index of each slot
    conn_slots : (C + 1,) int64      the slots of connection c are ``conn_slots[c]:conn_slots[c + 1]``
    theta_is_param : tuple of bool   theta i is a parameter (else a free weight)

    So ``conn[weight_conn[j]] += coef[weight_coef[j]] * (free value or 1)`` over the weights, and
    ``dconn[term_slot[i]] += term_expr[i] * (free value or 1)`` over the terms.
    """

    coefs: tuple[Expr, ...]
    weight_coef: np.ndarray
    weight_free: tuple[str | None, ...]
    weight_conn: np.ndarray
    term_expr: tuple[Expr, ...]
    term_free: tuple[str | None, ...]
    term_slot: np.ndarray
    slot_theta: np.ndarray
    conn_slots: np.ndarray
    theta_is_param: tuple[bool, ...]

    @property
    def n_connections(self) -> int:
        return int(self.conn_slots.shape[0]) - 1

    @property
    def n_slots(self) -> int:
        return int(self.slot_theta.shape[0])


def _evaluate(expr, env: Mapping[str, float]) -> float:
    """Evaluate an expression; arithmetic failures (J = 0 in 1/J) give NaN so the trainer can reject the step."""
    try:
        return float(expr.evaluate(env))
    except (ArithmeticError, ValueError):
        return float("nan")


class ThetaNetwork:
    """A network's theta (the names it holds, in order) and its weights (:class:`WeightTable`): the connection
    values and their derivatives at a theta. The base of :class:`~.runtime.CompiledNetwork`, which runs it."""

    def __init__(self, net: Network, free: Sequence[str] | None = None) -> None:
        self.net = net
        self._flat: FlatNetwork = flatten(net)
        self.names = self._theta_names(free)
        self._param_names = {p.name for p in net.parameters}
        self._theta_param = {n: i for i, n in enumerate(self.names) if n in self._param_names}
        self._theta_free = {n: i for i, n in enumerate(self.names) if n not in self._param_names}
        self._build_expressions()
        self._build_derivatives()
        self.weights = WeightTable(
            coefs=tuple(self._exprs),
            weight_coef=_frozen(self._weight_expr, np.int64),
            weight_free=tuple(self._weight_free),
            weight_conn=_frozen(self._flat.weight_conn, np.int64),
            term_expr=tuple(expr for _, _, expr, _ in self._terms),
            term_free=tuple(f for _, _, _, f in self._terms),
            term_slot=_frozen(self._term_slot, np.int64),
            slot_theta=_frozen(self._dtheta, np.int64),
            conn_slots=_frozen(self._dptr, np.int64),
            theta_is_param=tuple(n in self._theta_param for n in self.names),
        )

    # ------------------------------------------------------------------ construction
    def _theta_names(self, free: Sequence[str] | None) -> tuple[str, ...]:
        net = self.net
        params = {p.name: p for p in net.parameters}
        weights = {f.name: f for f in net.free_weights}
        if free is None:
            names = [p.name for p in net.parameters if not p.fixed]
            names += [f.name for f in net.free_weights if not f.fixed]
        else:
            if isinstance(free, str):
                raise ValueError("`free` must be a sequence of names, not a single string")
            names = list(free)
            if len(set(names)) != len(names):
                raise ValueError(f"`free` lists a name twice: {names}")
            for name in names:
                spec = params.get(name) or weights.get(name)
                if spec is None:
                    raise ValueError(
                        f"`free`: {name!r} is neither a parameter nor a free weight of {net.name!r}"
                    )
                if spec.fixed:
                    raise ValueError(f"`free`: {name!r} is fixed and cannot be differentiated")
        for name in names:
            if name in params and name in weights:
                raise ValueError(f"{name!r} is both a parameter and a free weight; theta would be ambiguous")
        return tuple(names)

    def _build_expressions(self) -> None:
        """Parse every distinct coef text once; each weight refers to one of them."""
        known = self._param_names
        texts: dict[str, int] = {}
        self._exprs = []
        self._weight_expr = np.empty(len(self.net.weights), dtype=np.int64)
        for j, w in enumerate(self.net.weights):
            if w.coef not in texts:
                expr = parse_expr(w.coef)
                unknown = sorted(set(expr.variables) - known)
                if unknown:
                    raise ValueError(
                        f"weight {j} ({w.origin or w.matrix}): coef {w.coef!r} uses unknown parameter(s) {unknown}"
                    )
                texts[w.coef] = len(self._exprs)
                self._exprs.append(expr)
            self._weight_expr[j] = texts[w.coef]
        self._weight_free = [w.free for w in self.net.weights]

    def _build_derivatives(self) -> None:
        """The sparse structure of d(connection)/d(theta) and, per term, how to evaluate it."""
        terms: list[tuple[int, int, object, str | None]] = []  # (weight, theta, expression, free factor)
        diff_cache: dict[tuple[int, str], object] = {}
        for j, w in enumerate(self.net.weights):
            e = int(self._weight_expr[j])
            expr = self._exprs[e]
            for name in sorted(expr.variables):
                if name not in self._theta_param:
                    continue
                key = (e, name)
                if key not in diff_cache:
                    diff_cache[key] = expr.diff(name)
                d = diff_cache[key]
                if d.is_constant and d.evaluate({}) == 0:
                    continue
                terms.append((j, self._theta_param[name], d, w.free))
            if w.free is not None and w.free in self._theta_free:
                terms.append((j, self._theta_free[w.free], expr, None))
        conn = self._flat.weight_conn
        slots = sorted({(int(conn[j]), p) for j, p, _, _ in terms})
        slot_index = {key: s for s, key in enumerate(slots)}
        self._terms = terms
        self._term_slot = np.array([slot_index[(int(conn[j]), p)] for j, p, _, _ in terms], dtype=np.int64)
        slot_conn = np.array([c for c, _ in slots], dtype=np.int64)
        self._dtheta = np.array([p for _, p in slots], dtype=np.int64)
        self._dptr = np.searchsorted(slot_conn, np.arange(self._flat.n_connections + 1)).astype(np.int64)

    # ------------------------------------------------------------------ values
    @property
    def n_theta(self) -> int:
        return len(self.names)

    def theta0(self) -> np.ndarray:
        """theta at the initial values written in the network file."""
        params = self.net.parameter_values()
        weights = self.net.free_weight_values()
        return np.array(
            [params[n] if n in self._theta_param else weights[n] for n in self.names], dtype=float
        )

    def _check_theta(self, theta) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.n_theta,):
            raise ValueError(
                f"theta has shape {theta.shape}, expected ({self.n_theta},) for {list(self.names)}"
            )
        return theta

    def values(self, theta) -> tuple[dict[str, float], dict[str, float]]:
        """(parameter values, free weight values): the file's initial values with theta applied."""
        theta = self._check_theta(theta)
        params = self.net.parameter_values()
        weights = self.net.free_weight_values()
        for name, i in self._theta_param.items():
            params[name] = float(theta[i])
        for name, i in self._theta_free.items():
            weights[name] = float(theta[i])
        return params, weights

    def connection_values(self, theta, with_derivatives: bool = False):
        """Every connection's value at `theta` (the flat network's order), and with `with_derivatives` the
        values of its sparse d(value)/d(theta) entries (the kernels' ``dval``); else None.

        The last result is kept: multiple shooting runs the kernels once per segment at one theta, and
        evaluating the chart's expressions each time cost a third of its Jacobian (250 segments)."""
        key = (np.asarray(theta, dtype=float).tobytes(), with_derivatives)
        cached = getattr(self, "_last_values", None)
        if cached is not None and cached[0] == key:
            return cached[1]
        out = self._connection_values(theta, with_derivatives)
        self._last_values = (key, out)
        return out

    def _connection_values(self, theta, with_derivatives: bool):
        params, weights = self.values(theta)
        coef = np.array([_evaluate(expr, params) for expr in self._exprs])
        wv = coef[self._weight_expr]
        for j, f in enumerate(self._weight_free):
            if f is not None:
                wv[j] *= weights[f]
        conn_val = self._flat.connection_values(wv)
        if not with_derivatives:
            return conn_val, None
        tv = np.empty(len(self._terms))
        for i, (_, _, expr, f) in enumerate(self._terms):
            tv[i] = _evaluate(expr, params) * (weights[f] if f is not None else 1.0)
        dval = np.bincount(self._term_slot, weights=tv, minlength=self._dtheta.shape[0]).astype(float)
        return conn_val, dval

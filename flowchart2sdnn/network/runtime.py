"""Run a :class:`Network`: simulation and the exact Jacobian of its outputs by RTRL.

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

import hashlib
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..expr import Expr, parse_expr
from .flat import FlatNetwork, flatten, signal_names
from .inputsignal import step_inputs
from .kernels import jacobian_kernel, jacobian_pieces_kernel, simulate_kernel, simulate_pieces_kernel
from .model import Network

__all__ = ["CompiledNetwork", "WeightTable"]

#: step-input arrays of shaped inputs kept per network (records x recent dead times)
STEP_CACHE = 8


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


class CompiledNetwork:
    """A network ready to simulate and differentiate.

    Parameters
    ----------
    net : Network
        The network file.
    free : sequence of str, optional
        Names of the quantities to put in theta (parameters and/or free weights, none fixed). Default: every
        non-fixed parameter, then every non-fixed free weight.

    Attributes
    ----------
    net : Network
    names : tuple of str
        theta order.
    n_inputs, n_outputs : int
    input_names, output_names : tuple of str
    weights : WeightTable
        How the connection values and their derivatives follow from theta.
    """

    def __init__(self, net: Network, free: Sequence[str] | None = None) -> None:
        self.net = net
        self._flat: FlatNetwork = flatten(net)
        self.n_inputs = len(net.inputs)
        self.n_outputs = len(net.outputs)
        self.input_names = tuple(i.name for i in net.inputs)
        self.output_names = tuple(o.name for o in net.outputs)
        self._signal_names = signal_names(net)
        self.names = self._theta_names(free)
        self._param_names = {p.name for p in net.parameters}
        self._theta_param = {n: i for i, n in enumerate(self.names) if n in self._param_names}
        self._theta_free = {n: i for i, n in enumerate(self.names) if n not in self._param_names}
        # states started at a free parameter (`init: <parameter>`): (global neuron, theta index)
        offsets = self._flat.layer_offset
        self._theta_starts = tuple((int(offsets[s.layer]) + s.neuron, self._theta_param[s.parameter])
                                   for s in net.initial_states if s.parameter in self._theta_param)
        self._build_expressions()
        self._build_derivatives()
        self._step_cache: dict = {}
        self._step_lock = threading.Lock()
        self._linear = np.array([i.intersample == "linear" for i in net.inputs], dtype=bool)
        self._delays = tuple(i.delay for i in net.inputs)
        # input i's dead time is theta[_delay_theta[i]] when fitted (-1: fixed or none)
        self._delay_theta = np.array([self._theta_param.get(d, -1) if d is not None else -1 for d in self._delays],
                                     dtype=np.int64)
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

    def __getstate__(self) -> dict:
        """Picklable as before the step-input cache: the lock and the cache stay behind."""
        state = self.__dict__.copy()
        state.pop("_step_lock", None)
        state["_step_cache"] = {}
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._step_lock = threading.Lock()

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

    # ------------------------------------------------------------------ checks
    def _check_inputs(self, inputs) -> np.ndarray:
        try:
            u = np.ascontiguousarray(inputs, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"inputs must be a numeric array: {exc}") from None
        if u.ndim != 2 or u.shape[1] != self.n_inputs:
            raise ValueError(
                f"inputs has shape {u.shape}, expected (Q, {self.n_inputs}) with columns {list(self.input_names)}"
            )
        if u.shape[0] == 0:
            raise ValueError("inputs has no samples (Q = 0)")
        bad = ~np.isfinite(u)
        if bad.any():
            q, i = np.argwhere(bad)[0]
            raise ValueError(
                f"inputs contain {int(bad.sum())} non-finite value(s), first at sample {q} of {self.input_names[i]!r}"
            )
        return u

    @property
    def flat(self) -> FlatNetwork:
        """The flattened network the kernels walk (index arrays, ring buffer length, output rows)."""
        return self._flat

    def initial_history(self, init: Mapping[str, float] | None, theta=None) -> np.ndarray:
        """The delay ring buffer before the first sample: the chart's initial states, the given initial outputs
        (name -> value) for states started from data, and, with `theta`, the states started at a parameter
        (`init: <parameter>`) at theta's value (without it: the parameter's chart value)."""
        if init is not None:
            unknown = sorted(set(init) - set(self.output_names))
            if unknown:
                raise ValueError(
                    f"init: {unknown} are not outputs of {self.net.name!r} ({list(self.output_names)})"
                )
        hist = self._flat.history_with(init)
        if theta is not None:
            theta = np.asarray(theta, dtype=float)
            for k, i in self._theta_starts:
                hist[k] = theta[i]
        return hist

    @property
    def estimates_starts(self) -> bool:
        """Some state starts at a free parameter: a caller that passes its own history must set it."""
        return bool(self._theta_starts)

    # ------------------------------------------------------------------ running
    @property
    def substeps(self) -> int:
        """Network steps per input sample (the network file's `substeps`)."""
        return self.net.substeps

    @property
    def shaped_inputs(self) -> bool:
        """Some input is not simply held over its sample: `intersample: linear` or a dead time."""
        return bool(self._linear.any()) or any(d is not None for d in self._delays)

    @property
    def fitted_delays(self) -> bool:
        """Some input's dead time is a free parameter (its sensitivity enters RTRL through the input)."""
        return bool(np.any(self._delay_theta >= 0))

    def _shifts(self, theta) -> np.ndarray:
        """Each input's dead time in samples at theta."""
        if all(d is None for d in self._delays):
            return np.zeros(self.n_inputs)
        params, _ = self.values(theta) if theta is not None else (self.net.parameter_values(), None)
        out = np.zeros(self.n_inputs)
        for i, d in enumerate(self._delays):
            if d is not None:
                out[i] = (params[d] if d in params else float(d)) / self.net.sample_time
        return out

    def step_inputs(self, u: np.ndarray, theta=None) -> np.ndarray:
        """The input of every network step for samples u (Q, n_inputs) at theta (None: the file's values)."""
        return self._steps(self._check_inputs(u), theta)

    def _steps(self, u: np.ndarray, theta=None, with_derivative: bool = False):
        """The input of every network step: each sample held over its `substeps` steps (zero-order hold), or
        for shaped inputs the signal's mean over the step (network.inputsignal). With `with_derivative`, also
        (in_theta, in_dval) for the kernels: d input / d theta of the inputs whose dead time is fitted.

        The kernels keep the last step of each sample, so outputs, residuals and Jacobian rows exist only at
        the data's samples while RTRL runs through every step.
        """
        if not self.shaped_inputs:
            p = u if self.net.substeps == 1 else np.repeat(u, self.net.substeps, axis=0)
            return (p, None, None) if with_derivative else p
        fitted = with_derivative and self.fitted_delays
        shifts = self._shifts(theta)
        # the trainer asks for the same record at the same dead times many times (simulate, Jacobian, trial
        # steps); building the step inputs cost 0.19 s per call at 30000 samples x 32 sub-steps
        key = (hashlib.blake2b(np.ascontiguousarray(u).tobytes(), digest_size=16).digest(), u.shape,
               shifts.tobytes(), fitted)
        with self._step_lock:  # multiple shooting runs segments on threads
            found = self._step_cache.get(key)
        if found is None:
            found = step_inputs(u, self.net.substeps, self._linear, shifts, with_derivative=fitted)
            with self._step_lock:
                if len(self._step_cache) >= STEP_CACHE:
                    self._step_cache.pop(next(iter(self._step_cache)))
                self._step_cache[key] = found
        p, dp = found
        if not with_derivative:
            return p
        if not fitted:
            return p, None, None
        return p, self._delay_theta, np.ascontiguousarray(dp / self.net.sample_time)

    def _history(self, init, history, theta=None) -> np.ndarray:
        if history is None:
            return self.initial_history(init, theta)
        hist = np.array(history, dtype=float)
        if hist.shape != (self._flat.n_neurons,) or not np.all(np.isfinite(hist)):
            raise ValueError(f"history must be {self._flat.n_neurons} finite values (one per neuron), "
                             f"got shape {hist.shape}")
        return hist

    def _recorded(self, states) -> np.ndarray:
        """The neurons a kernel records: the outputs, then `states` (None: none)."""
        if states is None:
            return self._flat.output_index
        return np.concatenate([self._flat.output_index, np.asarray(states, dtype=np.int64)]).astype(np.int64)

    def _state_sensitivities(self, states) -> tuple[int, np.ndarray | None]:
        """(columns, d history / d (theta, history[states])): theta's P columns, then one per state whose
        history value is a quantity (identity there); None when there are no states."""
        if states is None:
            return self.n_theta, None
        states = np.asarray(states, dtype=np.int64)
        n_theta = self.n_theta + len(states)
        s_init = np.zeros((self._flat.n_neurons, n_theta))
        s_init[states, self.n_theta + np.arange(len(states))] = 1.0
        return n_theta, s_init

    def _run(self, theta, inputs, init, record: np.ndarray, history=None) -> np.ndarray:
        u = self._steps(self._check_inputs(inputs), theta)
        hist = self._history(init, history, theta)
        conn_val, _ = self.connection_values(theta, with_derivatives=False)
        f = self._flat
        return simulate_kernel(
            u, f.conn_ptr, f.conn_kind, f.conn_src, f.conn_delay, conn_val, f.transfer, hist, f.ring, record,
            self.net.substeps,
        )

    def simulate(self, theta, inputs: np.ndarray, init: Mapping[str, float] | None = None,
                 history: np.ndarray | None = None, states: np.ndarray | None = None) -> np.ndarray:
        """Network outputs for `inputs`.

        Parameters
        ----------
        theta : (P,) array_like
        inputs : (Q, n_inputs) array_like
        init : mapping, optional
            Output name -> value, for states initialised from data.
        history : (n_neurons,) array_like, optional
            Every neuron's output before the first step (replaces the file's initial states and `init`):
            an initial state estimated from data (identify.offline.initstate).
        states : (S,) int64, optional
            Neurons whose values follow the outputs' (as in :meth:`jacobian`).

        Returns
        -------
        (Q, n_outputs [+ S]) ndarray, possibly non-finite when theta makes the network unstable.
        """
        return self._run(theta, inputs, init, self._recorded(states), history)

    def jacobian(
        self, theta, inputs: np.ndarray, init: Mapping[str, float] | None = None,
        history: np.ndarray | None = None, states: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs and their exact derivatives with respect to theta (RTRL).

        `history` (every neuron's value before the first step) replaces the initial states as in
        :meth:`simulate`. `states` (S,) int64, optional: neurons whose history values are quantities too (free
        initial states): the derivatives then have P + S columns, the last S with respect to
        ``history[states]``, and the outputs are followed by those neurons' values (the end state of a
        multiple-shooting segment and its sensitivities).

        Returns
        -------
        yhat : (Q, n_outputs [+ S]) ndarray
        dyhat : (Q, n_outputs [+ S], P [+ S]) ndarray
            ``dyhat[t, o, i] = d yhat[t, o] / d theta[i]``.
        """
        u, in_theta, in_dval = self._steps(self._check_inputs(inputs), theta, with_derivative=True)
        hist = self._history(init, history, theta)
        conn_val, dval = self.connection_values(theta, with_derivatives=True)
        f = self._flat
        record = self._recorded(states)
        n_theta, s_init = self._state_sensitivities(states)
        if history is None and self._theta_starts:  # d history / d theta: 1 where a state is a parameter
            if s_init is None:
                s_init = np.zeros((f.n_neurons, n_theta))
            for k, i in self._theta_starts:
                s_init[k, i] = 1.0
        return jacobian_kernel(
            u,
            f.conn_ptr,
            f.conn_kind,
            f.conn_src,
            f.conn_delay,
            conn_val,
            self._dptr,
            self._dtheta,
            dval,
            f.transfer,
            hist,
            f.ring,
            record,
            n_theta,
            self.net.substeps,
            s_init,
            in_theta,
            in_dval,
        )

    def run_pieces(self, theta, inputs: np.ndarray, first, last, histories, states: np.ndarray | None = None,
                   with_jac: bool = False):
        """:meth:`simulate` (or with `with_jac` :meth:`jacobian`) of the samples ``first[i]:last[i]`` of
        `inputs`, each piece from its own ``histories[i]``, stacked row after row: multiple shooting's segments
        of one record in one kernel call. With `states`, the sensitivities' last S columns are with respect to
        each piece's ``histories[i][states]``.

        Returns
        -------
        yhat : (sum(last - first), n_outputs [+ S]) ndarray
        dyhat : (sum(last - first), n_outputs [+ S], P [+ S]) ndarray, or None without `with_jac`
        """
        u, in_theta, in_dval = self._steps(self._check_inputs(inputs), theta, with_derivative=True) if with_jac \
            else (self._steps(self._check_inputs(inputs), theta), None, None)
        first, last = np.asarray(first, dtype=np.int64), np.asarray(last, dtype=np.int64)
        if first.shape != last.shape or first.ndim != 1 or np.any(first < 0) or np.any(last <= first) \
                or np.any(last > u.shape[0] // self.net.substeps):
            raise ValueError(f"pieces must be 0 <= first < last <= {u.shape[0] // self.net.substeps}, "
                             f"got first {first} and last {last}")
        hist = np.ascontiguousarray(histories, dtype=float)
        if hist.shape != (first.size, self._flat.n_neurons) or not np.all(np.isfinite(hist)):
            raise ValueError(f"histories must be ({first.size}, {self._flat.n_neurons}) finite values (one row "
                             f"per piece), got shape {hist.shape}")
        f = self._flat
        record = self._recorded(states)
        conn_val, dval = self.connection_values(theta, with_derivatives=with_jac)
        if not with_jac:
            return simulate_pieces_kernel(u, first, last, hist, f.conn_ptr, f.conn_kind, f.conn_src, f.conn_delay,
                                          conn_val, f.transfer, f.ring, record, self.net.substeps), None
        n_theta, s_init = self._state_sensitivities(states)
        if s_init is None:  # the kernel takes one array type: zeros, as a history that depends on nothing
            s_init = np.zeros((f.n_neurons, n_theta))
        return jacobian_pieces_kernel(u, first, last, hist, f.conn_ptr, f.conn_kind, f.conn_src, f.conn_delay,
                                      conn_val, self._dptr, self._dtheta, dval, f.transfer, f.ring, record, n_theta,
                                      self.net.substeps, s_init, in_theta, in_dval)

    def signals(
        self, theta, inputs: np.ndarray, init: Mapping[str, float] | None = None
    ) -> dict[str, np.ndarray]:
        """Every neuron's output over time, keyed "layer" (1-neuron layers) or "layer[k]"; each (Q,)."""
        record = np.arange(self._flat.n_neurons, dtype=np.int64)
        a = self._run(theta, inputs, init, record)
        return {name: a[:, k].copy() for k, name in enumerate(self._signal_names)}

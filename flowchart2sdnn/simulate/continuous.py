"""The continuous-time oracle: simulate a chart with fine RK4 steps, independent of the compiled network.

This module reads only the chart IR; it never imports the compiler or the network runtime, so a discrete
network can be checked against it (and data can be generated with it) without sharing a line of code.

Semantics (the chart in continuous time, sample time ``T = diagram.sample_time``, ``t_k = k T``):

* every block's output signal carries its name; a block's operand is ``x = sum_i sign_i * signal_i``;
* ``sum``: ``x``;  ``gain``: ``k x``;  ``constant``: ``k``;  ``integrator``: state ``s`` with ``ds/dt = x``;
  ``nonlinear``: ``sum_i v_i tanh(a_i x + b_i) + c x``;  ``function``: ``f(k x)`` with ``f`` one of ``tanh``,
  ``sin``, ``cos``, ``sign_smooth(z) = tanh(z / eps)`` (``eps`` defaults to 1e-3), ``sat(z) = clip(z, -1, 1)``,
  ``sqrt`` (``sqrt(z)`` for ``z >= eps``, ``-sqrt(-z)`` for ``z <= -eps``, and between them the odd cubic
  ``sqrt(eps) (5 u - u^3) / 4`` with ``u = z / eps``, which meets both in value and slope), ``abs``, ``exp``,
  ``square(z) = z^2``, ``signed_square(z) = z |z|``;  ``product``: ``k prod_i sign_i signal_i``;
* ``delay`` with ``n`` samples: on ``[t_k, t_{k+1})`` its output is its operand sampled at ``t_{k-n}``.
  Before ``t_0`` the operand is taken as its value at ``t_0`` (so the output starts at that value). When the
  operand at ``t_0`` depends on the delay's own output without an integrator in between (a purely discrete
  loop), that value is undefined and the delay starts from 0 instead. ``n = 0`` is a sample-and-hold;
* inputs are zero-order held: input row ``k`` acts on ``[t_k, t_{k+1})``; output row ``k`` is the chart at
  ``t_k`` (row 0 holds the initial values). An input with ``intersample: linear`` runs straight from row k to
  row k+1 instead (each RK4 stage reads it at its own time); one with a ``delay`` tau is that signal at
  ``t - tau`` (a held one as its mean over each RK4 step, so a jump inside a step costs that step O(h^2));
  before ``t_0`` an input is its first row;
* every cycle must pass an integrator or a delay with ``n >= 1``; the other blocks are evaluated in a
  topological order of the graph without the edges into integrators and out of such delays.

The chart is translated into opcode tables and interpreted by a compiled (numba) RK4 loop (:mod:`.rk4`) with
``substeps`` steps per sample interval.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from ..diagram.blocks import core_diagram
from ..diagram.model import Block, Diagram, NonlinearWeights
from .functions import FUNCTION_CODES as _FUNCTION
from .rk4 import CONSTANT, DELAY, FUNCTION, GAIN, INTEGRATOR, NONLINEAR, PRODUCT, SUM, run_rk4

__all__ = ["RelayFeedback", "simulate_continuous"]

_KIND = {"sum": SUM, "gain": GAIN, "integrator": INTEGRATOR, "delay": DELAY, "constant": CONSTANT,
         "nonlinear": NONLINEAR, "function": FUNCTION, "product": PRODUCT}
DEFAULT_EPS = 1e-3


@dataclass(frozen=True)
class RelayFeedback:
    """A digital hysteresis relay added to one chart input (the bias of the paper's excitation, section 6.1).

    Once per sample, from the measured signal ``y_k = signal(t_k) + noise[k]``: the relay state switches to
    ``-level`` when ``y_k > switch`` and to ``+level`` when ``y_k < -switch`` (otherwise it keeps its value;
    it starts at ``+level``); its output is the state times ``band_scale`` while ``|y_k| < band``, else the
    state. The input applied on ``[t_k, t_{k+1})`` is the given input sample plus the relay output.

    ``noise`` (length Q, or None for none) is the measurement noise the controller sees, so that the relay
    acts on the same measured signal that is logged. The measured signal must not depend on the relayed
    input without an integrator or delay in between.
    """

    input: str
    measured: str
    level: float = 4.0
    switch: float = 10.0
    band: float = 2.0
    band_scale: float = 0.2
    noise: np.ndarray | None = field(default=None, compare=False, repr=False)


# --------------------------------------------------------------------------------------------- program
@dataclass(frozen=True)
class _Program:
    names: tuple[str, ...]  # signal names: inputs, then blocks
    ti: np.ndarray
    tf: np.ndarray
    src: np.ndarray
    sgn: np.ndarray
    nl: np.ndarray
    order: np.ndarray
    order0: np.ndarray
    integ: np.ndarray
    delays: np.ndarray
    zero0: np.ndarray
    x0: np.ndarray
    graph: nx.DiGraph  # feedthrough graph at t_0 (superset of the one inside intervals), inputs included


def _number(value, block: Block, what: str, env: Mapping[str, float]) -> float:
    if value is None:
        raise ValueError(f"block '{block.name}': {block.kind} block has no {what}")
    try:
        number = float(value) if isinstance(value, (int, float)) else float(value.evaluate(env))
    except (ValueError, ArithmeticError, TypeError) as exc:  # ExprError is a ValueError
        raise ValueError(f"block '{block.name}': cannot evaluate {what} '{value}': {exc}") from exc
    if not math.isfinite(number):
        raise ValueError(f"block '{block.name}': {what} '{value}' evaluates to {number}")
    return number


def _environment(diagram: Diagram, parameters: Mapping[str, float] | None) -> dict[str, float]:
    env = diagram.parameter_values()
    for name, value in (parameters or {}).items():
        if name not in env:
            raise ValueError(f"unknown parameter '{name}' (chart parameters: {', '.join(env) or 'none'})")
        env[name] = float(value)
    env.setdefault("T", float(diagram.sample_time))
    env.setdefault("pi", math.pi)
    return env


def _topological(graph: nx.DiGraph, nodes) -> list[str]:
    sub = graph.subgraph(nodes)
    try:
        return list(nx.topological_sort(sub))
    except nx.NetworkXUnfeasible:
        loop = [u for u, _ in nx.find_cycle(sub)]
        raise ValueError("algebraic loop (no integrator or delay on it): " + " -> ".join(loop + loop[:1])) \
            from None


def _compile(diagram: Diagram, env: Mapping[str, float], init: Mapping[str, float] | None,
             nonlinear: Mapping[str, NonlinearWeights] | None) -> _Program:
    diagram = core_diagram(diagram)  # a registered kind means the core block it lowers to
    names = diagram.input_names + diagram.block_names
    index = {name: i for i, name in enumerate(names)}
    if len(index) != len(names):
        raise ValueError("duplicate signal names among the chart's inputs and blocks")
    init = dict(init or {})
    nonlinear = dict(nonlinear or {})
    kinds = {b.name: b.kind for b in diagram.blocks}
    for arg, names_given, kind in (("init", init, "an integrator"), ("nonlinear", nonlinear, "a nonlinear")):
        for name in names_given:
            if kinds.get(name) != kind.split()[1]:
                raise ValueError(f"`{arg}` names '{name}', which is not {kind} block of the chart")
    n_in, n_b = len(diagram.inputs), len(diagram.blocks)
    ti = np.zeros((n_b, 8), dtype=np.uint64)
    tf = np.zeros((n_b, 2))
    src: list[int] = []
    sgn: list[float] = []
    nl: list[tuple[float, float, float]] = []
    integ: list[int] = []
    delays: list[int] = []
    x0: list[float] = []
    graph = nx.DiGraph()
    graph.add_nodes_from(names)
    for j, b in enumerate(diagram.blocks):
        if b.kind not in _KIND:
            raise ValueError(f"block '{b.name}': unknown kind '{b.kind}'")
        kind = _KIND[b.kind]
        ti[j, 0], ti[j, 1], ti[j, 2] = n_in + j, kind, len(src)
        for term in b.inputs:
            if term.signal not in index:
                raise ValueError(f"block '{b.name}': unknown signal '{term.signal}'")
            src.append(index[term.signal])
            sgn.append(-1.0 if term.sign < 0 else 1.0)
            if kind != INTEGRATOR:
                graph.add_edge(term.signal, b.name)
        ti[j, 3] = len(src)
        if kind in (GAIN, CONSTANT):
            tf[j, 0] = _number(b.k, b, "k", env)
        elif kind == PRODUCT:
            tf[j, 0] = 1.0 if b.k is None else _number(b.k, b, "k", env)
        elif kind == FUNCTION:
            tf[j, 0] = 1.0 if b.k is None else _number(b.k, b, "k", env)
            if b.f not in _FUNCTION:
                raise ValueError(f"block '{b.name}': unknown function '{b.f}' (one of {', '.join(_FUNCTION)})")
            ti[j, 6] = _FUNCTION[b.f]
            tf[j, 1] = DEFAULT_EPS if b.eps is None else float(b.eps)
            if not tf[j, 1] > 0:
                raise ValueError(f"block '{b.name}': eps must be > 0, got {b.eps}")
        elif kind == NONLINEAR:
            w = nonlinear.get(b.name, b.weights)
            if w is None:
                raise ValueError(f"block '{b.name}': nonlinear block without weights "
                                 "(a plant chart must state its curve; or pass `nonlinear=`)")
            bias = w.b if w.b is not None else (0.0,) * len(w.a)
            if not len(w.a) == len(w.v) == len(bias):
                raise ValueError(f"block '{b.name}': weights a, v, b differ in length")
            tf[j, 0] = 0.0 if w.c is None else float(w.c)
            ti[j, 4] = len(nl)
            nl.extend(zip(map(float, w.a), map(float, bias), map(float, w.v), strict=True))
            ti[j, 5] = len(nl)
        elif kind == INTEGRATOR:
            value = init.get(b.name, b.init)
            if isinstance(value, str) and value in env:  # init names a parameter
                value = env[value]
            if isinstance(value, str):
                raise ValueError(f"integrator '{b.name}' has init '{value}': pass its value in `init`")
            x0.append(0.0 if value is None else float(value))
            if not math.isfinite(x0[-1]):
                raise ValueError(f"integrator '{b.name}': initial value {value} is not finite")
            integ.append(j)
        elif kind == DELAY:
            n = b.n if b.n is not None else 1
            if n < 0:
                raise ValueError(f"delay '{b.name}': n must be >= 0, got {n}")
            ti[j, 6], ti[j, 7] = len(delays), n
            delays.append(j)
    # Inside intervals the delays with n >= 1 feed nothing through; at t_0 they pass their operand through.
    held = [b.name for b in diagram.blocks if b.kind == "delay" and (b.n is None or b.n >= 1)]
    inner = graph.copy()
    inner.remove_edges_from([e for name in held for e in graph.out_edges(name)])
    evaluated = [b.name for b in diagram.blocks if b.kind != "integrator"]
    order = _topological(inner, evaluated)
    zero0 = np.zeros(len(delays), dtype=np.int64)
    first = graph.copy()
    while True:  # break each purely discrete loop at t_0 at one of its delays, which then starts from 0
        try:
            cycle = [u for u, _ in nx.find_cycle(first.subgraph(evaluated))]
        except nx.NetworkXNoCycle:
            break
        name = next(u for u in cycle if u in held)
        zero0[ti[diagram.block_names.index(name), 6]] = 1
        first.remove_edges_from(list(first.out_edges(name)))
    order0 = _topological(first, evaluated)
    position = {name: j for j, name in enumerate(diagram.block_names)}
    return _Program(
        names=names, ti=ti, tf=tf, src=np.asarray(src, dtype=np.uint64), sgn=np.asarray(sgn, dtype=float),
        nl=np.asarray(nl, dtype=float).reshape(-1, 3),
        order=np.asarray([position[n] for n in order], dtype=np.uint64),
        order0=np.asarray([position[n] for n in order0], dtype=np.uint64),
        integ=np.asarray(integ, dtype=np.uint64), delays=np.asarray(delays, dtype=np.int64), zero0=zero0,
        x0=np.asarray(x0, dtype=float), graph=first)


def _controller_tables(program: _Program, controller: RelayFeedback | None, diagram: Diagram, q: int):
    if controller is None:
        return np.zeros(3, dtype=np.int64), np.zeros(4), np.zeros(q)
    if not isinstance(controller, RelayFeedback):
        raise TypeError(f"`controller` must be a RelayFeedback, got {type(controller).__name__}")
    if controller.input not in diagram.input_names:
        raise ValueError(f"relay input '{controller.input}' is not a chart input")
    if controller.measured not in program.names:
        raise ValueError(f"relay measured signal '{controller.measured}' is not a chart signal")
    if nx.has_path(program.graph, controller.input, controller.measured):
        raise ValueError(f"relay measured signal '{controller.measured}' depends on '{controller.input}' "
                         "without an integrator or delay in between")
    noise = np.zeros(q) if controller.noise is None else np.ascontiguousarray(controller.noise, dtype=float)
    if noise.shape != (q,):
        raise ValueError(f"relay noise must have shape ({q},), got {noise.shape}")
    ctrl_i = np.array([1, diagram.input_names.index(controller.input), program.names.index(controller.measured)],
                      dtype=np.int64)
    ctrl_f = np.array([controller.level, controller.switch, controller.band, controller.band_scale], dtype=float)
    return ctrl_i, ctrl_f, noise


def simulate_continuous(
    diagram: Diagram,
    inputs: np.ndarray,
    parameters: Mapping[str, float] | None = None,
    init: Mapping[str, float] | None = None,
    substeps: int = 20,
    signals: bool = False,
    nonlinear: Mapping[str, NonlinearWeights] | None = None,
    controller: RelayFeedback | None = None,
) -> np.ndarray | dict[str, np.ndarray]:
    """Simulate a chart in continuous time (RK4, `substeps` steps per sample interval, inputs held).

    Parameters
    ----------
    diagram : Diagram
        The chart. Its nonlinear blocks need weights (or an entry in `nonlinear`).
    inputs : ndarray, shape (Q, n_inputs)
        Input samples in ``diagram.inputs`` order; row k acts on ``[t_k, t_{k+1})``. A 1-D array is
        accepted for a chart with one input.
    parameters : mapping, optional
        Parameter values overriding the chart's initial values.
    init : mapping, optional
        Initial values of integrators by block name (required for ``init: data``).
    substeps : int
        RK4 steps per sample interval.
    signals : bool
        Return every input and block signal by name instead of the output matrix.
    nonlinear : mapping, optional
        Weights of nonlinear blocks by block name (override the chart's).
    controller : RelayFeedback, optional
        A digital relay added to one input, evaluated once per sample inside the compiled loop.

    Returns
    -------
    ndarray, shape (Q, n_outputs), or dict of name -> ndarray (Q,)
        Row k is the chart at ``t_k = k * sample_time``. With a controller, the signals' input entries
        hold the applied input (given samples plus relay).

    Raises
    ------
    ValueError
        Bad arguments, algebraic loops, missing weights or initial values, or a non-finite state
        (the message names the time).
    """
    if not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ValueError(f"`substeps` must be a positive integer, got {substeps!r}")
    u = np.asarray(inputs, dtype=float)
    if u.ndim == 1 and len(diagram.inputs) == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[1] != len(diagram.inputs) or u.shape[0] < 1:
        raise ValueError(f"`inputs` must have shape (Q >= 1, {len(diagram.inputs)}), got {u.shape}")
    if not np.all(np.isfinite(u)):
        raise ValueError("`inputs` holds non-finite values")
    if not diagram.sample_time > 0:
        raise ValueError(f"sample_time must be > 0, got {diagram.sample_time}")
    env = _environment(diagram, parameters)
    program = _compile(diagram, env, init, nonlinear)
    in_linear = np.array([s.intersample == "linear" for s in diagram.inputs], dtype=np.int64)
    in_shift = np.array([0.0 if s.delay is None else (env[s.delay] if s.delay in env else float(s.delay))
                         / diagram.sample_time for s in diagram.inputs], dtype=float)
    for out in diagram.output_names:
        if out not in program.names:
            raise ValueError(f"output '{out}' is neither a block nor an input of the chart")
    q = u.shape[0]
    ctrl_i, ctrl_f, noise = _controller_tables(program, controller, diagram, q)
    rec = np.empty((q, len(program.names)))
    buf_len = max([int(program.ti[j, 7]) for j in program.delays] + [1])
    status, k = run_rk4(np.ascontiguousarray(u), program.x0, program.ti, program.tf, program.src, program.sgn,
                     program.nl, program.order, program.order0, program.integ, program.delays, program.zero0,
                     buf_len, int(substeps), diagram.sample_time / substeps, ctrl_i, ctrl_f, noise, rec, in_linear,
                     in_shift)
    if status:
        what = "a signal" if status == 1 else "the state"
        raise ValueError(f"simulation blew up: {what} became non-finite at t = {k * diagram.sample_time:g} s "
                         f"(sample {k})")
    if signals:
        return {name: rec[:, i].copy() for i, name in enumerate(program.names)}
    return rec[:, [program.names.index(name) for name in diagram.output_names]]

"""Loop analysis: algebraic loops, and which feedback edges the discretization delays.

The paper (section 5) redraws the chart so that every feedback loop passes an integrator, then uses implicit
Euler on forward paths and explicit Euler on feedback paths. Explicit Euler of an integrator seen from a
feedback path is the implicit integrator's output one sample late, so the discretization reduces to choosing,
in every delay-free loop, one feedback edge that carries a one-sample delay.

The choice: a depth-first search from the chart inputs (then constants, then anything left), visiting
neighbours nearest the inputs first and, among equals, farthest from the outputs; the edges that close a loop
back to a block still on the search path are the feedback edges. Forward paths from the inputs are explored
first, so they never carry a delay; the keys depend on the chart's structure, not on the order of the YAML,
and names only break exact structural ties.

With `delays: torques` (the rule chosen for accuracy, and the default: DEFAULT_DELAYS) every edge that closes a
loop into a *speed sum* -- a sum that feeds an integrator through a gain, Newton's sum of torques before its
1/J -- is delayed first, and the search above breaks whatever loops remain (all of them, on a chart without a
speed sum: there `torques` is `search`). `delays: search` is the search alone. Speeds then follow from the previous step's torques and angles
from the new speeds: symplectic Euler for every mass, where the search alone may delay a neighbour's speed
instead (`w2 -> dw`), which lets a mass feel a shaft torque computed from a one-step-old neighbour and errs
several times more on a chain of masses. The set is structural, so the choice still ignores the YAML order.
`delays: midpoint` delays the same edges; the compiler then takes the speed-dependent torques at mid-step
(network.midstep, second order).
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx

from ..diagram.blocks import block_types
from ..diagram.model import Diagram
from .graph import algebraic_graph, chart_graph, delay_free_graph, distances

__all__ = ["DEFAULT_DELAYS", "LoopReport", "analyse_loops", "delay_rule", "find_algebraic_loops", "torque_edges"]

#: the delay rule of a chart without `delays`
DEFAULT_DELAYS = "torques"


def _kind_rank(kind: str) -> int:
    """A chart input first, then the kinds in the order of their `rank` (diagram.blocks)."""
    bt = block_types().get(kind)
    return 0 if kind == "input" else bt.rank if bt is not None else 9


@dataclass(frozen=True)
class LoopReport:
    """What loop analysis found.

    algebraic_loops: each a list of block names in signal order (first == entry point, not repeated).
    delayed_edges: (source, target, loop) for every edge given a one-sample delay; `loop` is one delay-free
        loop the edge breaks, in signal order starting at the target.
    order: every signal in search order (a name-independent ranking used to order layers).
    """

    algebraic_loops: tuple[tuple[str, ...], ...]
    delayed_edges: tuple[tuple[str, str, tuple[str, ...]], ...]
    order: tuple[str, ...]

    @property
    def delayed(self) -> frozenset[tuple[str, str]]:
        return frozenset((u, v) for u, v, _ in self.delayed_edges)


def find_algebraic_loops(g: nx.DiGraph) -> list[tuple[str, ...]]:
    """One loop per strongly connected component of the feedthrough graph, in signal order."""
    h = algebraic_graph(g)
    loops = []
    cyclic = [c for c in nx.strongly_connected_components(h) if len(c) > 1 or h.has_edge(*(next(iter(c)),) * 2)]
    for comp in sorted(cyclic, key=sorted):
        # the shortest cycle through the first name, by names only: not by the order of the YAML
        start = min(comp)
        succ = {n: sorted(x for x in h.successors(n) if x in comp) for n in comp}
        cycles = [(start,) + _shortest_path(succ, first, start)[:-1] for first in succ[start]]
        loops.append(min(cycles, key=len))
    return loops


def torque_edges(g: nx.DiGraph, h: nx.DiGraph) -> list[tuple[str, str]]:
    """Edges of the delay-free graph `h` into a speed sum (see the module docstring)."""
    kind = dict(g.nodes(data="kind"))
    speed_sums = set()
    for n in g:
        if kind[n] != "integrator":
            continue
        gains, node, seen = 0, n, {n}
        while True:  # walk the integrator's input back through gains: sum -> gain(1/J) -> integrator
            preds = list(g.predecessors(node))
            if len(preds) != 1 or preds[0] in seen:  # a loop of gains only is reported by the compiler
                break
            seen.add(preds[0])
            node = preds[0]
            if kind[node] != "gain":
                break
            gains += 1
        if gains and kind[node] == "sum":
            speed_sums.add(node)
    return sorted((u, v) for v in speed_sums for u in h.predecessors(v))


def _take_needed(h: nx.DiGraph, candidates: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """Remove from `h` (in place), in the given order, each candidate edge that still closes a loop; the removed.

    One delay per loop: a loop through two speed sums (a motor's current and speed) delayed at both would be
    explicit Euler, which pumps energy into the oscillation, so the second is left to the first.
    """
    taken = []
    for u, v in candidates:
        h.remove_edge(u, v)
        if nx.has_path(h, v, u):
            taken.append((u, v))
        else:
            h.add_edge(u, v)
    return taken


def delay_rule(diagram: Diagram) -> str:
    """The chart's `delays`, or DEFAULT_DELAYS when it does not say."""
    return diagram.delays or DEFAULT_DELAYS


def analyse_loops(diagram: Diagram) -> LoopReport:
    g = chart_graph(diagram)
    algebraic = find_algebraic_loops(g)
    full = delay_free_graph(g)
    candidates = torque_edges(g, full) if delay_rule(diagram) in ("torques", "midpoint") else []
    h = full.copy() if candidates else full
    inputs = [s.name for s in diagram.inputs if s.name in g]
    din = distances(full, inputs)
    dout = distances(full, [s.name for s in diagram.outputs if s.name in g], reverse=True)
    far = len(g) + 1

    def key(node: str):
        return (din.get(node, far), -dout.get(node, -1), _kind_rank(g.nodes[node]["kind"]),
                full.in_degree(node), full.out_degree(node), node)

    # speed sums nearest the inputs first: the order is structural, so the choice ignores the YAML order
    preferred = _take_needed(h, sorted(candidates, key=lambda e: (key(e[1]), key(e[0]))))
    succ = {n: sorted(h.successors(n), key=key) for n in h}  # every search visits neighbours in this order
    succ_full = {n: sorted(full.successors(n), key=key) for n in full} if preferred else succ
    roots = sorted(inputs, key=key)
    roots += sorted((n for n in g if g.nodes[n]["kind"] == "constant"), key=key)
    roots += sorted(g, key=key)

    order: list[str] = []
    back: list[tuple[str, str]] = list(preferred)
    state: dict[str, int] = {}  # 1 = on the search path, 2 = finished
    for root in roots:
        if root in state:
            continue
        # iterative DFS: charts of 1000 masses are deeper than Python's recursion limit
        state[root] = 1
        order.append(root)
        stack = [(root, iter(succ[root]))]
        while stack:
            node, children = stack[-1]
            for child in children:
                mark = state.get(child)
                if mark is None:
                    state[child] = 1
                    order.append(child)
                    stack.append((child, iter(succ[child])))
                    break
                if mark == 1:
                    back.append((node, child))
            else:
                state[node] = 2
                stack.pop()

    delayed = []
    for u, v in back:
        if any(u in loop and v in loop for loop in algebraic):
            continue  # reported as an algebraic loop; delaying it would hide the error
        delayed.append((u, v, _shortest_path(succ_full, v, u)))
    return LoopReport(tuple(algebraic), tuple(delayed), tuple(order))


def _shortest_path(succ: dict[str, list[str]], source: str, target: str) -> tuple[str, ...]:
    """Breadth-first path visiting neighbours in `succ` order, so that among equally short loops the one shown
    does not depend on the YAML order (networkx's shortest_path follows insertion order)."""
    parent: dict[str, str | None] = {source: None}
    frontier = [source]
    while frontier and target not in parent:
        nxt = []
        for node in frontier:
            for child in succ[node]:
                if child not in parent:
                    parent[child] = node
                    nxt.append(child)
        frontier = nxt
    path = [target]
    while parent[path[-1]] is not None:
        path.append(parent[path[-1]])  # type: ignore[arg-type]
    return tuple(reversed(path))

"""Semantic checks of a validated chart. Returns diagnostics; never raises for a chart problem.

| code    | severity | what |
|---------|----------|------|
| LINT001 | error    | algebraic loop (a cycle with neither an integrator nor a delay) |
| LINT002 | warning  | block whose output nobody uses (a dangling signal) |
| LINT003 | warning  | parameter no block uses |
| LINT004 | warning  | output not reachable from any input |
| LINT005 | error    | unit mismatch (sum of unlike units, declared unit disagrees with the computed one) |
| LINT006 | error    | parameter bounds: min >= max, or init outside [min, max] |
| LINT007 | warning  | parameters (or learned weights) that only appear together and cannot be identified apart |
| LINT008 | error    | bad unit text |
| LINT009 | warning  | argument of a function block is not dimensionless |
| LINT010 | error    | chart with no input or no output |
| LINT011 | error    | a gain cannot be evaluated at the parameters' initial values (1/J with J = 0, overflow) |
| LINT012 | warning  | the argument of a `sqrt` can be negative (a difference, k < 0, a negative start or constant) |
| LINT013 | info     | what a learned curve can represent: odd or any shape, the range its basis spans, its linear term |
"""

from __future__ import annotations

from functools import partial

import numpy as np

from ..diagram.blocks import block_types
from ..diagram.curves import describe_curve
from ..diagram.model import Block, Diagram
from ..diagram.units import DIMENSIONLESS, Unit, UnitError, parse_unit, unit_of_expr
from ..errors import Diagnostic, Location
from ..expr import Expr, ExprError
from .graph import chart_graph, distances
from .loops import find_algebraic_loops

__all__ = ["lint_diagram", "curve_notes"]


def lint_diagram(diagram: Diagram) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    for check in (_io, _algebraic_loops, _unused, _reachability, _bounds, _gains, _units, _identifiability,
                  _sqrt_domain):
        out.extend(check(diagram))
    return out


def curve_notes(diagram: Diagram) -> list[Diagnostic]:
    """One info line per learned curve: what it can represent (diagram.curves.describe_curve)."""
    return [Diagnostic("LINT013", "info", describe_curve(diagram, b), _loc(diagram, b), b.name)
            for b in diagram.blocks if b.kind == "nonlinear"]


def _loc(diagram: Diagram, obj) -> Location:
    return getattr(obj, "location", None) or Location(diagram.file)


def _io(diagram: Diagram):
    if not diagram.inputs:
        yield Diagnostic("LINT010", "error", "the chart has no inputs; identification needs a measured excitation",
                         Location(diagram.file, 1), hint="list the excitation signals under 'inputs:'")
    if not diagram.outputs:
        yield Diagnostic("LINT010", "error", "the chart has no outputs; nothing would be fitted",
                         Location(diagram.file, 1), hint="list the measured signals under 'outputs:'")


def _algebraic_loops(diagram: Diagram):
    g = chart_graph(diagram)
    for loop in find_algebraic_loops(g):
        first = diagram.block(loop[0])
        path = " -> ".join(loop + (loop[0],))
        yield Diagnostic(
            "LINT001", "error", f"algebraic loop {path}: no integrator or delay on it",
            _loc(diagram, first), loop[0],
            f"insert an integrator or a delay on the loop, e.g. between '{loop[-1]}' and '{loop[0]}'",
        )


def _unused(diagram: Diagram):
    used_signals = {t.signal for b in diagram.blocks for t in b.inputs} | set(diagram.output_names)
    for b in diagram.blocks:
        if b.name not in used_signals:
            yield Diagnostic("LINT002", "warning", "output of this block is used by no block and is not an output",
                             _loc(diagram, b), b.name, "remove it or list it under 'outputs:'")
    for s in diagram.inputs:
        if s.name not in used_signals:
            yield Diagnostic("LINT002", "warning", f"input '{s.name}' is used by no block", _loc(diagram, s))
    used_params: set[str] = set()
    for b in diagram.blocks:
        if b.k is not None:
            used_params |= b.k.variables
        if b.kind == "integrator" and isinstance(b.init, str):  # `init: <parameter>` (or "data")
            used_params.add(b.init)
    used_params |= {s.delay for s in diagram.inputs if s.delay is not None}  # an input's dead time
    for p in diagram.parameters:
        if p.name not in used_params:
            yield Diagnostic("LINT003", "warning", f"parameter '{p.name}' is used by no block", _loc(diagram, p),
                             hint="remove it or use it in a gain")


def _reachability(diagram: Diagram):
    g = chart_graph(diagram)
    reach = distances(g, diagram.input_names)
    for s in diagram.outputs:
        if s.name in g and s.name not in reach and diagram.inputs:
            yield Diagnostic("LINT004", "warning", f"output '{s.name}' is not reachable from any input",
                             _loc(diagram, s), s.name, "its parameters cannot be excited by the data")


def _bounds(diagram: Diagram):
    for p in diagram.parameters:
        if p.min is not None and p.max is not None and p.min >= p.max:
            yield Diagnostic("LINT006", "error", f"parameter '{p.name}': min {p.min} is not below max {p.max}",
                             _loc(diagram, p))
        elif p.min is not None and p.init < p.min:
            yield Diagnostic("LINT006", "error", f"parameter '{p.name}': init {p.init} is below min {p.min}",
                             _loc(diagram, p))
        elif p.max is not None and p.init > p.max:
            yield Diagnostic("LINT006", "error", f"parameter '{p.name}': init {p.init} is above max {p.max}",
                             _loc(diagram, p))


def _gains(diagram: Diagram):
    env = diagram.parameter_values()
    for b in diagram.blocks:
        if b.k is None:
            continue
        try:
            b.k.evaluate(env)
        except ExprError as exc:
            yield Diagnostic("LINT011", "error", f"'k: {b.k}' cannot be evaluated at the parameters' initial "
                             f"values: {exc.message}", _loc(diagram, b), b.name,
                             "give its parameters an init where the gain is a finite number")


def _sqrt_domain(diagram: Diagram):
    """What the chart alone tells about a square root's argument going negative (the data may tell more: the
    trainer counts the samples where it did). Below 0 `sqrt` is -sqrt(-z), which is a reversed flow between
    two tanks, but nonsense for a level that should never be negative, so the user should know."""
    env = diagram.parameter_values()
    for b in diagram.blocks:
        if b.kind != "function" or b.f != "sqrt" or not b.inputs:
            continue
        why = None
        try:
            k = b.k.evaluate(env) if b.k is not None else 1.0
        except ExprError:
            k = 1.0  # LINT011 reports it
        (term,) = b.inputs
        source = diagram.block(term.signal) if term.signal in diagram.block_names else None
        if k < 0 or term.sign < 0:
            why = "its factor k (with the input's sign) is negative"
        elif source is not None and source.kind == "sum" and any(t.sign < 0 for t in source.inputs):
            why = f"'{source.name}' is a difference"
        elif source is not None and source.kind == "integrator" and isinstance(source.init, float) \
                and source.init < 0:
            why = f"integrator '{source.name}' starts at {source.init:g}"
        elif source is not None and source.kind == "constant" and source.k is not None:
            try:
                if source.k.evaluate(env) < 0:
                    why = f"constant '{source.name}' is negative"
            except ExprError:
                pass
        if why:
            yield Diagnostic("LINT012", "warning", f"the argument of sqrt can be negative ({why}); below 0 it is "
                             "-sqrt(-z) (a reversed flow), not a NaN", _loc(diagram, b), b.name,
                             "if it should never be negative, check the chart's signs")


# ---------------------------------------------------------------------------------------------- units
def _units(diagram: Diagram):
    diags: list[Diagnostic] = []
    parsed: dict[str, Unit] = {}  # a big chart repeats a few unit texts thousands of times

    def parse(text: str | None, obj, what: str) -> Unit | None:
        if text is None:
            return None
        try:
            if text not in parsed:
                parsed[text] = parse_unit(text)
            return parsed[text]
        except UnitError as exc:
            diags.append(Diagnostic("LINT008", "error", f"{what}: bad unit '{text}': {exc.message}",
                                    _loc(diagram, obj), obj.name if isinstance(obj, Block) else None, exc.hint))
            return None

    pu = {p.name: parse(p.unit, p, f"parameter '{p.name}'") for p in diagram.parameters}
    declared: dict[str, Unit | None] = {}
    for s in diagram.inputs:
        declared[s.name] = parse(s.unit, s, f"input '{s.name}'")
    out_units = {s.name: parse(s.unit, s, f"output '{s.name}'") for s in diagram.outputs}
    for b in diagram.blocks:
        declared[b.name] = parse(b.unit, b, f"block '{b.name}'")
    unit = {k: v for k, v in declared.items() if v is not None}
    for name, u in out_units.items():
        if u is None:
            continue
        if name in unit and not _same(unit[name], u):
            diags.append(Diagnostic("LINT005", "error", f"output '{name}' declared as {u} but the block says "
                                    f"{unit[name]}", _loc(diagram, diagram.block(name)), name))
        unit.setdefault(name, u)
    reported: set[str] = set()

    # a block is evaluated again only when one of its inputs got a unit since its last evaluation: the
    # result cannot change otherwise, and re-evaluating every block in every pass is quadratic on long chains
    version: dict[str, int] = dict.fromkeys(unit, 0)
    evaluated: dict[str, int] = {}
    clock = 0
    k_units: dict[str, Unit | UnitError | None] = {}

    def k_unit(b: Block) -> Unit | None:
        if b.k is None:
            return DIMENSIONLESS
        if b.name not in k_units:
            try:
                k_units[b.name] = _unit_of_k(b.k, pu)
            except UnitError as exc:  # raised again at each evaluation (reported once, below)
                k_units[b.name] = exc
        ku = k_units[b.name]
        if isinstance(ku, UnitError):
            raise ku
        return ku

    def complain(b: Block, code: str, severity: str, message: str) -> None:
        if b.name not in reported:
            reported.add(b.name)
            diags.append(Diagnostic(code, severity, message, _loc(diagram, b), b.name))

    rules = {kind: bt.unit for kind, bt in block_types().items()}
    for _ in range(len(diagram.blocks) + 1):  # fixed point: feedback signals get units from declared ones
        changed = False
        for b in diagram.blocks:
            if b.name in evaluated and all(version.get(t.signal, -1) <= evaluated[b.name] for t in b.inputs):
                continue
            clock += 1
            evaluated[b.name] = clock
            ins = [unit.get(t.signal) for t in b.inputs]
            computed: Unit | None = None
            rule = rules.get(b.kind)  # the kind's unit rule (diagram.blocks)
            if rule is None:
                continue
            try:
                computed = rule(b, ins, partial(k_unit, b), partial(complain, b))
            except UnitError as exc:
                if b.name not in reported:
                    reported.add(b.name)
                    diags.append(Diagnostic("LINT005", "error", f"units of 'k' do not add up: {exc.message}",
                                            _loc(diagram, b), b.name))
                computed = None
            if computed is None:
                continue
            have = unit.get(b.name)
            if have is None:
                unit[b.name] = computed
                clock += 1
                version[b.name] = clock
                changed = True
            elif not _same(have, computed) and b.name not in reported:
                reported.add(b.name)
                diags.append(Diagnostic("LINT005", "error", f"unit mismatch: declared or expected {have}, but the "
                                        f"inputs give {computed}", _loc(diagram, b), b.name,
                                        "check the units of the gain's parameters and of its input"))
        if not changed:
            break
    return diags


def _unit_of_k(k: Expr, parameter_units: dict) -> Unit | None:
    """Unit of a block's `k`; None (unknown) for a plain number other than +-1.

    A bare number says nothing about units: `k: 0.3` on a friction-offset constant declared `unit: N*m`, or
    `k: 1.2` after a sign function, is a torque. Taking it as dimensionless reported unit errors in charts
    that declare no units at all, and in charts whose declared unit could not be reconciled with it.
    """
    if k.is_constant:
        try:
            value = k.evaluate({})
        except ExprError:
            return None
        return DIMENSIONLESS if abs(value) == 1.0 else None
    return unit_of_expr(k, parameter_units)


def _same(a: Unit, b: Unit) -> bool:
    return a == b


# ---------------------------------------------------------------------------------------------- identifiability
def _identifiability(diagram: Diagram):
    """Structural check: the map (free parameters) -> (gain values) must have full rank.

    Two parameters that only ever appear together (a product J*r, a ratio c/k) give proportional columns of
    d(gains)/d(parameters); no data can tell them apart. The Jacobian is sparse (a gain names a few
    parameters), so it is split into groups of parameters linked by shared gains and each group is checked
    on its own: a chart of 1000 masses has 3000 parameters, and one dense SVD of that size takes seconds.
    """
    free = [p for p in diagram.parameters if not p.fixed]
    if len(free) < 2:
        return
    index = {p.name: j for j, p in enumerate(free)}
    env = diagram.parameter_values()
    rows: list[dict[int, float]] = []
    for b in diagram.blocks:
        if b.k is None:
            continue
        row: dict[int, float] = {}
        for name in sorted(b.k.variables & index.keys()):
            try:
                row[index[name]] = b.k.diff(name).evaluate(env) * (abs(env[name]) or 1.0)
            except Exception:  # noqa: BLE001 - a singular point: skip the check rather than guess
                return
        if row:
            rows.append(row)
    parent = list(range(len(free)))  # union-find: parameters that share a gain

    def root(j: int) -> int:
        while parent[j] != j:
            parent[j] = parent[parent[j]]
            j = parent[j]
        return j

    for row in rows:
        first, *rest = row
        for j in rest:
            parent[root(j)] = root(first)
    groups: dict[int, list[int]] = {}
    for j in range(len(free)):
        groups.setdefault(root(j), []).append(j)
    group_rows: dict[int, list[dict[int, float]]] = {}
    for row in rows:
        group_rows.setdefault(root(next(iter(row))), []).append(row)
    for r, members in sorted(groups.items(), key=lambda kv: kv[1][0]):
        if len(members) < 2:
            continue
        yield from _rank_deficient(free, members, group_rows.get(r, []), diagram)


def _rank_deficient(free, members: list[int], rows: list[dict[int, float]], diagram: Diagram):
    col = {j: i for i, j in enumerate(members)}
    d = np.zeros((len(rows), len(members)))
    for i, row in enumerate(rows):
        for j, value in row.items():
            d[i, col[j]] = value
    if d.size == 0 or not np.all(np.isfinite(d)):
        return
    # scale rows so each gain counts equally
    norms = np.linalg.norm(d, axis=1, keepdims=True)
    norms[norms == 0] = 1.0
    d = d / norms
    _, s, vt = np.linalg.svd(d)
    for i in range(len(members)):
        sv = s[i] if i < len(s) else 0.0
        if sv <= 1e-9 * max(s[0], 1e-300):
            names = [free[members[j]].name for j in np.flatnonzero(np.abs(vt[i]) > 1e-6)]
            if len(names) >= 2:
                yield Diagnostic(
                    "LINT007", "warning",
                    f"parameters {', '.join(names)} only appear together and cannot be identified separately",
                    _loc(diagram, diagram.parameter(names[0])), hint=f"fix all but one of {', '.join(names)} "
                    "(fixed: true)")

"""Where an effect may attach: structural queries over a chart, and the small rewiring helpers patches use.

The chart IR knows blocks and terms, not physics; these functions read the physics off the structure:

* a **speed** is the output of an integrator whose integrand is a torque sum seen through at least one gain
  that depends on a parameter (``w1 = integral(MB1 / J1)``). A plain angle (``dphi = integral(w1 - w2)``)
  has no such gain and is not a speed;
* a **speed difference** is a sum of exactly two speeds with opposite signs (``dw = w1 - w2``);
* a **spring angle** is an integrator of a speed difference whose output feeds a parameter gain (the spring
  ``MC = c * dphi``) that acts in torque sums;
* the **sign** of a torque sum for a speed is the sign with which a term entering that sum accelerates the
  speed (the product of the gains' signs at the parameters' initial values), so that friction opposes motion;
* a **position** is an integrator of one speed (``x = integral(v)``, an angle ``phi = integral(w)``): a force
  of it enters the speed's torque sums, with the sign that pulls the position back when the force grows with
  it (a spring to ground). The integral of a speed difference is a spring angle, not a position;
* a **state** is any integrator; a **signal** any block's output or input, named by the user.

Nothing here mutates: every helper returns a new :class:`Diagram`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..diagram.curves import BASIS_FUNCTIONS, basis_weights
from ..diagram.model import RESERVED, Block, Diagram, Parameter, Term
from ..expr import ExprError

__all__ = [
    "Place",
    "speeds",
    "speed_differences",
    "spring_angles",
    "input_places",
    "positions",
    "position_of",
    "states",
    "signal_place",
    "sum_terms",
    "curve_block",
    "seat_curve",
    "fresh_name",
    "namer",
    "add_terms",
    "reroute",
    "add_blocks",
    "consumers",
]


@dataclass(frozen=True)
class Place:
    """Where an effect attaches.

    Attributes
    ----------
    at : str
        The signal the effect acts on (the report's `at`): a speed, a speed difference, a spring angle, a
        position, a state, an input or any named signal.
    kind : str
        "speed", "speed_difference", "spring_angle", "position", "input", "output", "state" or "signal".
    sums : tuple of (str, int)
        Torque sums a new torque enters and the sign that *opposes* the motion there (-1 for the usual
        ``MB = M - friction``); for a position, the sign that pulls it back. Empty for inputs.
    via : str or None
        The block an effect rewrites: the spring gain of a spring angle; the speed a position integrates.
    """

    at: str
    kind: str
    sums: tuple[tuple[str, int], ...] = ()
    via: str | None = None

    def __str__(self) -> str:
        return self.at


def _gain_sign(block: Block, env: dict[str, float]) -> int | None:
    try:
        value = block.k.evaluate(env)
    except (ExprError, ArithmeticError):
        return None
    return 1 if value > 0 else -1 if value < 0 else None


def _torque_sum(diagram: Diagram, integrator: Block) -> tuple[str, int] | None:
    """(sum, sign) when `integrator` integrates a sum through at least one parameter gain, else None."""
    if len(integrator.inputs) != 1:
        return None
    env = diagram.parameter_values()
    names = set(diagram.block_names)
    term = integrator.inputs[0]
    sign, has_mass = term.sign, False
    for _ in range(len(diagram.blocks)):
        if term.signal not in names:
            return None
        b = diagram.block(term.signal)
        if b.kind == "sum":
            return (b.name, -sign) if has_mass else None
        if b.kind != "gain" or len(b.inputs) != 1:
            return None
        s = _gain_sign(b, env)
        if s is None:
            return None
        has_mass = has_mass or not b.k.is_constant
        term = b.inputs[0]
        sign *= s * term.sign
    return None


def speeds(diagram: Diagram) -> tuple[Place, ...]:
    """Every speed of the chart with its torque sum (see the module docstring)."""
    out = []
    for b in diagram.blocks:
        if b.kind == "integrator":
            found = _torque_sum(diagram, b)
            if found is not None:
                out.append(Place(b.name, "speed", (found,)))
    return tuple(out)


def speed_differences(diagram: Diagram) -> tuple[Place, ...]:
    """Sums of two speeds with opposite signs; a damping torque there enters both torque sums."""
    speed = {p.at: p.sums[0] for p in speeds(diagram)}
    out = []
    for b in diagram.blocks:
        if b.kind != "sum" or len(b.inputs) != 2:
            continue
        (t1, t2) = b.inputs
        if t1.signal in speed and t2.signal in speed and t1.sign == -t2.sign and t1.signal != t2.signal:
            # D = sum s_i w_i: the torque -b*D*s_i on mass i dissipates power b*D^2
            sums = tuple((speed[t.signal][0], speed[t.signal][1] * t.sign) for t in (t1, t2))
            out.append(Place(b.name, "speed_difference", sums))
    return tuple(out)


def consumers(diagram: Diagram, signal: str) -> tuple[Block, ...]:
    """Blocks with `signal` among their operands."""
    return tuple(b for b in diagram.blocks if signal in b.signals_in)


def spring_angles(diagram: Diagram) -> tuple[Place, ...]:
    """Integrators of a speed difference that feed a parameter gain (the spring) acting in torque sums."""
    diffs = {p.at for p in speed_differences(diagram)}
    sums = {s for p in speeds(diagram) for s, _ in p.sums}
    out = []
    for b in diagram.blocks:
        if b.kind != "integrator" or len(b.inputs) != 1 or b.inputs[0].signal not in diffs:
            continue
        for g in consumers(diagram, b.name):
            if g.kind == "gain" and not g.k.is_constant and any(c.name in sums for c in consumers(diagram, g.name)):
                out.append(Place(b.name, "spring_angle", via=g.name))
                break
    return tuple(out)


def positions(diagram: Diagram) -> tuple[Place, ...]:
    """Integrators of one speed (``x = integral(+-v)``) with the speed's torque sums: a force ``f(x)`` entered
    with these signs acts against x as a spring to ground does (x grows with +-v, so the sign is the speed's
    times the term's)."""
    speed = {p.at: p.sums for p in speeds(diagram)}
    out = []
    for b in diagram.blocks:
        if b.kind == "integrator" and len(b.inputs) == 1 and b.inputs[0].signal in speed:
            t = b.inputs[0]
            out.append(Place(b.name, "position", tuple((s, sign * t.sign) for s, sign in speed[t.signal]),
                             via=t.signal))
    return tuple(out)


def position_of(diagram: Diagram, speed: str) -> str | None:
    """The chart's own position of `speed` (an integrator reading exactly it), if it has one."""
    return next((p.at for p in positions(diagram) if p.via == speed), None)


def states(diagram: Diagram) -> tuple[Place, ...]:
    """Every integrator."""
    return tuple(Place(b.name, "state") for b in diagram.blocks if b.kind == "integrator")


def signal_place(diagram: Diagram, signal: str) -> Place:
    """The place of a named signal: as the most specific kind it is (a speed with its torque sums, a position,
    ...), else a plain "signal" place (an input or any block). KeyError when the chart has no such signal."""
    if signal not in set(diagram.block_names) | set(diagram.input_names):
        raise KeyError(signal)
    for find in (speeds, speed_differences, spring_angles, positions, input_places, states):
        place = next((p for p in find(diagram) if p.at == signal), None)
        if place is not None:
            return place
    return Place(signal, "signal")


def input_places(diagram: Diagram) -> tuple[Place, ...]:
    return tuple(Place(s.name, "input") for s in diagram.inputs)


def output_places(diagram: Diagram) -> tuple[Place, ...]:
    """The measured outputs (a block started from the data keeps its start when renamed: see rename_block)."""
    return tuple(Place(s.name, "output") for s in diagram.outputs)


# ---------------------------------------------------------------------------------------------- rewiring
def sum_terms(place: Place, signal: str) -> dict[str, tuple[Term, ...]]:
    """`signal` as an operand of each of the place's torque sums, with the place's sign (for :func:`add_terms`)."""
    terms: dict[str, tuple[Term, ...]] = {}
    for s, sign in place.sums:
        terms[s] = terms.get(s, ()) + (Term(signal, sign),)
    return terms


def curve_block(name: str, at: str, span: float, description: str) -> Block:
    """A learned curve of `at` (the tanh basis over +-span, diagram.curves) whose weights are set once it sits in
    its chart (:func:`seat_curve`: whether it has a linear term depends on what it is summed with)."""
    return Block(name, "nonlinear", (Term(at),), description=description, neurons=BASIS_FUNCTIONS, basis="tanh",
                 span=span)


def seat_curve(diagram: Diagram, name: str) -> Diagram:
    """The chart with curve `name` flat (v = 0, c = 0: neutral) over its span."""
    return replace(diagram, blocks=tuple(
        replace(b, weights=basis_weights(diagram, b, b.span or 1.0)) if b.name == name else b
        for b in diagram.blocks))


def fresh_name(diagram: Diagram, base: str, taken: set[str] | frozenset[str] = frozenset()) -> str:
    """`base`, or `base_2`, `base_3`, ... : a name no signal or parameter of the chart uses yet."""
    used = set(diagram.block_names) | set(diagram.input_names) | set(diagram.parameter_names) | set(taken)
    used |= RESERVED
    if base not in used:
        return base
    i = 2
    while f"{base}_{i}" in used:
        i += 1
    return f"{base}_{i}"


def namer(diagram: Diagram):
    """A function giving fresh names for new blocks and parameters, distinct from the chart's and each other."""
    taken: set[str] = set()

    def new(base: str) -> str:
        n = fresh_name(diagram, base, taken)
        taken.add(n)
        return n

    return new


def add_blocks(diagram: Diagram, blocks: tuple[Block, ...] | list[Block],
               parameters: tuple[Parameter, ...] | list[Parameter] = ()) -> Diagram:
    """The chart with extra blocks and parameters appended (names must be fresh)."""
    names = set(diagram.block_names) | set(diagram.input_names) | set(diagram.parameter_names)
    for item in list(blocks) + list(parameters):
        if item.name in names:
            raise ValueError(f"patch adds {item.name!r}, which the chart already has")
        names.add(item.name)
    return replace(diagram, blocks=diagram.blocks + tuple(blocks), parameters=diagram.parameters + tuple(parameters),
                   source_sha256=None)


def add_terms(diagram: Diagram, terms: dict[str, tuple[Term, ...]]) -> Diagram:
    """Append operands to sum blocks: ``terms[sum name] = (Term, ...)``."""
    blocks = []
    for b in diagram.blocks:
        extra = terms.get(b.name)
        if extra:
            if b.kind != "sum":
                raise ValueError(f"cannot add an operand to {b.kind} block {b.name!r}; only sums take more")
            b = replace(b, inputs=b.inputs + tuple(extra))
        blocks.append(b)
    return replace(diagram, blocks=tuple(blocks), source_sha256=None)


def reroute(diagram: Diagram, signal: str, new: str, keep: set[str] | frozenset[str] = frozenset()) -> Diagram:
    """Every block except those in `keep` reads `new` where it read `signal`."""
    blocks = []
    for b in diagram.blocks:
        if b.name not in keep and signal in b.signals_in:
            b = replace(b, inputs=tuple(Term(new, t.sign) if t.signal == signal else t for t in b.inputs))
        blocks.append(b)
    return replace(diagram, blocks=tuple(blocks), source_sha256=None)


def rename_block(diagram: Diagram, old: str, new: str) -> Diagram:
    """The chart with block `old` named `new` and every block that read `old` reading `new`.

    An integrator started from the data (`init: data`) keeps its data column: renamed, it is `measured_by` the
    output it was, so the caller must leave a block of that name among the outputs (a sensor in between)."""
    renamed = tuple(replace(b, name=new, measured_by=b.data_column) if b.name == old else b for b in diagram.blocks)
    return reroute(replace(diagram, blocks=renamed, source_sha256=None), old, new)

"""The block registry: one :class:`BlockType` record per block kind says what that kind is.

A record holds what the passes ask of a kind: its YAML keys and operand shape (validate reads, and dump writes,
each key where a kind names it), whether `k` is required, its unit rule (lint), its rank among the kinds (loop
analysis orders layers by it), which of its edges carry no direct feedthrough (analysis.graph) and its label
(the drawing). The eight core kinds below are what the compiler and the continuous oracle implement; a new
kind that means a core block without a state (a `square` block k x^2 is a `product` of its input with itself)
says so in `lower`, and compile, the oracle and linearize see the core block it lowers to
(:func:`core_diagram`). Nothing else needs to change: see CONTRIBUTING.md, "Add a block type".

What stays special, and why. The compiler (compiler.discretize), the oracle (simulate.continuous) and
linearize (analysis.linearize) sit above this layer, so a record cannot hold their code: each keeps its own
case per core kind, and a new kind reaches them only through `lower`. The oracle's opcodes in particular are
its own on purpose: it must share no code with the compiler. `integrator`, `delay` and `nonlinear` are
structural there (a state, held samples, learned neurons with free weights), and the keys `init`, `n`, `f`
and the learned curve's keys have their checks in validate.py.

Layer: diagram.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from fractions import Fraction
from types import MappingProxyType

from .model import Block, Diagram
from .units import DIMENSIONLESS, Unit, parse_unit

__all__ = ["BlockType", "BLOCK_KINDS", "CORE_KINDS", "block_type", "block_types", "cuts", "register_block_type",
           "unregister_block_type", "registered", "core_block", "core_diagram", "LOWER_TO", "UNIT_FUNCTIONS"]

#: a unit rule: (the block, its operand units, a thunk giving the unit of `k` (DIMENSIONLESS without k), a
#: complaint (code, severity, message)) -> the output's unit, None when it cannot be told yet. The thunk may
#: raise UnitError; lint reports that, and a complaint, once per block.
UnitRule = Callable[[Block, Sequence[Unit | None], Callable[[], Unit | None], Callable[[str, str, str], None]],
                    Unit | None]
#: functions whose output has a unit: the argument's to this power (the others need a dimensionless argument)
UNIT_FUNCTIONS = {"sqrt": Fraction(1, 2), "abs": 1, "square": 2, "signed_square": 2}
_SECOND = parse_unit("s")


@dataclass(frozen=True)
class BlockType:
    """What one block kind defines.

    kind: the `type:` of the chart; equation: its output in one line (docs, error hints).
    keys: the YAML keys it takes besides `type`, `unit` and `description`.
    operands: "none" (no `in`), "one" (one signal, possibly negated) or "many" (a list); min_operands: the
        fewest signals a list may hold, with `too_few` the message when it holds fewer.
    k: "none", "required" or "optional" (an expression of parameters, 1 when absent).
    rank: its place among the kinds when loop analysis orders blocks that are otherwise alike.
    unit: its unit rule (UnitRule); None: lint tells no unit (a learned curve's output unit is declared).
    label: the text under its name in the drawing.
    cut: which edges of the chart graph carry no direct feedthrough (analysis.graph): "in" for a state
        (the edge into an integrator), "out" for held samples (the edges out of a delay), "" for none.
    lower: for a kind the compiler does not know: the core block it means (same name and input signals), one
        of LOWER_TO. A kind with a state of its own (integrator, delay, learned curve) is core: loop analysis
        and lint read the chart as written.
    """

    kind: str
    equation: str
    keys: tuple[str, ...]
    operands: str = "one"
    label: Callable[[Block], str] = lambda b: b.kind
    k: str = "none"
    rank: int = 9
    unit: UnitRule | None = None
    min_operands: int = 1
    too_few: str = ""
    cut: str = ""
    lower: Callable[[Block], Block] | None = None

    def __post_init__(self) -> None:
        if self.operands not in ("none", "one", "many"):
            raise ValueError(f"operands must be 'none', 'one' or 'many', not {self.operands!r}")
        if self.k not in ("none", "required", "optional"):
            raise ValueError(f"k must be 'none', 'required' or 'optional', not {self.k!r}")
        if self.cut not in ("", "in", "out"):
            raise ValueError(f"cut must be '', 'in' or 'out', not {self.cut!r}")
        wanted = (("in",) if self.operands != "none" else ()) + (("k",) if self.k != "none" else ())
        missing = [key for key in wanted if key not in self.keys]
        if missing:
            raise ValueError(f"block type '{self.kind}': keys must name {', '.join(missing)}")


def _k_label(b: Block) -> str:
    return f"{b.kind} k = {b.k}" if b.k is not None else b.kind


def _sum_unit(b, ins, k, complain):
    known = [(t.signal, u) for t, u in zip(b.inputs, ins, strict=True) if u is not None]
    for sig, u in known[1:]:
        if u != known[0][1]:
            complain("LINT005", "error", f"sum of unlike units: '{known[0][0]}' is {known[0][1]} but '{sig}' is {u}")
    return known[0][1] if known and len(known) == len(ins) else None


def _function_unit(b, ins, k, complain):
    ku = k()
    arg = ins[0] * ku if ins[0] is not None and ku is not None else None
    if b.f in UNIT_FUNCTIONS:  # these carry the argument's unit through
        return None if arg is None else arg ** UNIT_FUNCTIONS[b.f]
    if arg is not None and not arg.is_dimensionless and b.f != "sign_smooth":
        complain("LINT009", "warning", f"argument of {b.f} has unit {arg}, expected dimensionless")
    return DIMENSIONLESS


def _gain_unit(b, ins, k, complain):
    ku = k() if ins[0] is not None else None
    return ins[0] * ku if ku is not None else None


def _product_unit(b, ins, k, complain):
    if any(u is None for u in ins):
        return None
    out = k()
    if out is not None:
        for u in ins:
            out = out * u
    return out


_CORE = (
    BlockType("sum", "sum_i sign_i x_i", ("in",), "many", rank=2, unit=_sum_unit),
    BlockType("gain", "k x", ("in", "k"), label=_k_label, k="required", rank=3, unit=_gain_unit),
    BlockType("integrator", "state s, ds/dt = x", ("in", "init", "measured_by"), label=lambda b: "integrator ∫",
              rank=7, cut="in", unit=lambda b, ins, k, complain: ins[0] * _SECOND if ins[0] is not None else None),
    BlockType("delay", "x, n samples earlier", ("in", "n"), label=lambda b: f"delay {b.n or 1}", rank=6,
              cut="out", unit=lambda b, ins, k, complain: ins[0]),
    BlockType("constant", "k", ("k",), "none", label=_k_label, k="required", rank=1,
              unit=lambda b, ins, k, complain: k()),
    BlockType("nonlinear", "sum_i v_i tanh(a_i x + b_i) + c x",
              ("in", "neurons", "basis", "linear", "span", "bias", "init_range", "fixed", "weights"),
              label=lambda b: f"learned, {b.neurons} tanh", rank=5),
    BlockType("function", "f(k x)", ("in", "f", "k", "eps"),
              label=lambda b: f"{b.f}" + (f" (k = {b.k})" if b.k is not None else ""), k="optional", rank=4,
              unit=_function_unit),
    BlockType("product", "k prod_i sign_i x_i", ("in", "k"), "many", label=_k_label, k="optional", rank=8,
              unit=_product_unit, min_operands=2,
              too_few="a product needs at least two signals in 'in'; use a gain block to scale one signal"),
)
#: shipped kinds that mean a core block (each with `lower`): a new simple block type is one entry here
_LOWERED: tuple[BlockType, ...] = ()
#: the kinds the compiler, the network and the continuous oracle implement
CORE_KINDS = tuple(t.kind for t in _CORE)
#: the core kinds a registered kind may lower to: those without a state, so that the chart as written has the
#: feedthrough of the chart compiled
LOWER_TO = ("sum", "gain", "constant", "function", "product")
#: the kinds of a chart as shipped; block_types() also lists the ones registered at run time
BLOCK_KINDS = CORE_KINDS + tuple(t.kind for t in _LOWERED)
_REGISTRY: dict[str, BlockType] = {t.kind: t for t in _CORE}
#: keys validate reads (and dump writes) that no core kind takes: a new one goes here with its Block field
_MORE_KEYS: frozenset[str] = frozenset()
#: the keys validate reads (and dump writes) for any kind that names them
_READ_KEYS = frozenset(key for t in _CORE for key in t.keys) | _MORE_KEYS


def cuts(kind: str) -> str:
    """The `cut` of a kind ("" for a chart input or a kind nobody registered)."""
    bt = _REGISTRY.get(kind)
    return bt.cut if bt is not None else ""


def block_types() -> MappingProxyType:
    """Every registered kind -> its BlockType, core kinds first."""
    return MappingProxyType(_REGISTRY)


def block_type(kind: str) -> BlockType:
    """The record of `kind`; KeyError for a kind nobody registered."""
    return _REGISTRY[kind]


def register_block_type(bt: BlockType) -> None:
    """Add a kind to the chart language. It must lower onto a core kind (the compiler implements only those)."""
    if bt.kind in _REGISTRY:
        raise ValueError(f"block type '{bt.kind}' is already registered")
    if bt.lower is None:
        raise ValueError(f"block type '{bt.kind}' needs `lower`: the core block ({', '.join(LOWER_TO)}) it means")
    if bt.cut:
        raise ValueError(f"block type '{bt.kind}' lowers onto a kind without a state: it cuts no edge")
    unread = [key for key in bt.keys if key not in _READ_KEYS]
    if unread:
        raise ValueError(f"block type '{bt.kind}': no core kind takes {', '.join(unread)}; a new key needs a field "
                         "of Block, its check in validate.py, its line in dump.py and its name in _MORE_KEYS")
    _REGISTRY[bt.kind] = bt


def unregister_block_type(kind: str) -> None:
    if kind in CORE_KINDS:
        raise ValueError(f"'{kind}' is a core block type")
    del _REGISTRY[kind]


@contextmanager
def registered(bt: BlockType) -> Iterator[BlockType]:
    """Register `bt` for the duration of a `with` block (tests, plug-ins tried out)."""
    register_block_type(bt)
    try:
        yield bt
    finally:
        unregister_block_type(bt.kind)


def core_block(b: Block) -> Block:
    """`b` as the core block the compiler knows (itself when its kind is core)."""
    if b.kind in CORE_KINDS:
        return b
    lowered = block_type(b.kind).lower(b)
    # loop analysis and lint read the chart as written: the lowered block must use the same signals
    if lowered.kind not in LOWER_TO or lowered.name != b.name or set(lowered.signals_in) != set(b.signals_in):
        raise ValueError(f"block type '{b.kind}' lowers '{b.name}' to a {lowered.kind} block with another name or "
                         f"other signals; it must keep both and give one of {', '.join(LOWER_TO)}")
    return lowered


def core_diagram(diagram: Diagram) -> Diagram:
    """The chart with every block a core block: what compile, the continuous oracle and linearize read."""
    if all(b.kind in CORE_KINDS for b in diagram.blocks):
        return diagram
    return replace(diagram, blocks=tuple(core_block(b) for b in diagram.blocks))


for _t in _LOWERED:
    register_block_type(_t)

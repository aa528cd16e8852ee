"""The chart IR: frozen dataclasses that know nothing about YAML.

A :class:`Diagram` is what `validate` makes of a chart file and what every later pass reads. Nothing here
mutates: passes that change a chart (diagnose's effects, identify's learned values) build a new one with
:func:`dataclasses.replace`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..errors import Location

if TYPE_CHECKING:  # pragma: no cover
    from ..expr import Expr

__all__ = [
    "RESERVED",
    "FORMAT_VERSION",
    "MAX_SUBSTEPS",
    "DELAY_RULES",
    "FUNCTIONS",
    "EPS_FUNCTIONS",
    "Signal",
    "Parameter",
    "Term",
    "NonlinearWeights",
    "Block",
    "Diagram",
]

FORMAT_VERSION = 1
#: `substeps` may name at most this many network steps per sample (auto caps far lower, see compiler.substeps)
MAX_SUBSTEPS = 1000
#: `delays`: which feedback edges carry the one-step delay (see analysis.loops)
#: names no block, input or parameter may take (the expression language's pi, `init: data`, the step T)
RESERVED = frozenset({"pi", "data", "T"})
DELAY_RULES = ("search", "torques", "midpoint")
# sat(z) = clip(z, -1, 1); sqrt is signed and regularised within eps of 0 (see FUNCTION_HELP);
# square is z^2, signed_square z*|z| (a drag that keeps the sign of the speed)
FUNCTIONS = ("tanh", "sin", "cos", "sign_smooth", "sat", "sqrt", "abs", "exp", "square", "signed_square")
#: functions whose `eps` means something (the others ignore it)
EPS_FUNCTIONS = ("sign_smooth", "sqrt")


@dataclass(frozen=True)
class Signal:
    """A measured chart signal: an input (excitation) or an output (fitted)."""

    name: str
    unit: str | None = None
    description: str | None = None
    location: Location | None = None
    #: inputs only: "hold" (zero-order, each sample acts until the next) or "linear" (first-order hold:
    #: straight between the samples), MATLAB iddata's InterSample zoh / foh
    intersample: str = "hold"
    #: inputs only: a dead time in seconds, a parameter name (fitted) or a number; None: none
    delay: str | None = None


#: the intersample behaviours of an input (Signal.intersample)
INTERSAMPLE = ("hold", "linear")


@dataclass(frozen=True)
class Parameter:
    """A named physical parameter: initial value, unit, bounds and whether it is identified."""

    name: str
    init: float
    unit: str | None = None
    min: float | None = None
    max: float | None = None
    fixed: bool = False
    description: str | None = None
    location: Location | None = None
    # with several training records, one value per record (identify.offline.problem); last so positional use stays
    per_record: bool = False


@dataclass(frozen=True)
class Term:
    """One operand of a block: a signal name with the sign it enters with (sums only use -1)."""

    signal: str
    sign: int = 1

    def __str__(self) -> str:
        return ("-" if self.sign < 0 else "") + self.signal


@dataclass(frozen=True)
class NonlinearWeights:
    """Weights of a `nonlinear` block: y = sum_i v_i * tanh(a_i * x + b_i) + c * x (c: the linear term, None
    when the curve has none)."""

    a: tuple[float, ...]
    v: tuple[float, ...]
    b: tuple[float, ...] | None = None
    c: float | None = None


@dataclass(frozen=True)
class Block:
    """A chart block. Its output signal carries its name. Fields unused by a kind stay None."""

    name: str
    kind: str
    inputs: tuple[Term, ...] = ()
    unit: str | None = None
    description: str | None = None
    location: Location | None = None
    # gain, constant, function, product: the factor k (an expression of parameters)
    k: Expr | None = None
    # integrator: initial value (a number, "data": the first measured sample of this output, or a parameter's
    # name: the start is that parameter, fitted like any other; `init: estimate` adds one, diagram.initestimate)
    init: float | str | None = None
    # integrator with `init: data` that is not itself an output: the measured output whose first sample starts
    # it (a sensor in between, e.g. a clip: the true state starts where the sensor read it; issue 16)
    measured_by: str | None = None
    # delay: samples of pure delay
    n: int | None = None
    # nonlinear
    neurons: int | None = None
    bias: bool | None = None
    init_range: tuple[float, float] | None = None
    fixed: bool | None = None
    weights: NonlinearWeights | None = None
    # "tanh": fixed slopes spanning the input's range, output weights (and the linear term) learned, so the
    # curve enters the fit linearly; "neurons": the paper's free-slope tanh neurons (diagram.curves)
    basis: str | None = None
    # the linear term c*x: None decides by the chart (off where a gain of the same input sits in the same sum)
    linear: bool | None = None
    # the half-width of the input range the basis spans; None takes it from the data at fit time
    span: float | None = None
    # function
    f: str | None = None
    eps: float | None = None

    @property
    def data_column(self) -> str | None:
        """The measured output whose first sample starts this integrator (`init: data`), else None."""
        if self.kind != "integrator" or self.init != "data":
            return None
        return self.measured_by or self.name

    @property
    def signals_in(self) -> tuple[str, ...]:
        return tuple(t.signal for t in self.inputs)


@dataclass(frozen=True)
class Diagram:
    """A validated chart. `file` is the path it came from (for messages); `source_sha256` its hash."""

    name: str
    sample_time: float
    inputs: tuple[Signal, ...]
    outputs: tuple[Signal, ...]
    parameters: tuple[Parameter, ...]
    blocks: tuple[Block, ...]
    description: str | None = None
    version: int = FORMAT_VERSION
    file: str = "<chart>"
    source_sha256: str | None = None
    # network steps per sample: an int >= 1 (1: the paper's network), "auto", or None (not given: auto, see
    # compiler.substeps.DEFAULT_SUBSTEPS)
    substeps: int | str | None = None
    # which feedback edges are delayed: "search", "torques" or "midpoint" (torques with the speed torques taken at
    # mid-step, network.midstep) (None: not given, torques; analysis.loops.delay_rule)
    delays: str | None = None
    extra: dict = field(default_factory=dict, compare=False, hash=False)

    # --- look-ups (cheap; charts are small) ---
    def block(self, name: str) -> Block:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(name)

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def block_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.blocks)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.inputs)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.outputs)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def parameter_values(self) -> dict[str, float]:
        return {p.name: p.init for p in self.parameters}

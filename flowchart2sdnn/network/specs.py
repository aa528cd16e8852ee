"""The entries of a network file (:mod:`.model`): its neurons, layers, inputs, parameters, free weights,
weights, outputs, initial states and delayed edges, each a frozen record; :class:`~.model.Network` holds them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ["NeuronSpec", "LayerSpec", "InputSpec", "ParameterSpec", "FreeWeightSpec", "WeightSpec", "OutputSpec",
           "InitialState", "DelayedEdge"]


@dataclass(frozen=True)
class NeuronSpec:
    """One neuron. ``net_input`` "prod": n = prod_c w_c x_c over its connections instead of the sum, one
    connection per factor (two weights from the same source and delay are two factors, x^2)."""

    name: str
    transfer: str = "linear"
    net_input: str = "sum"

    def to_dict(self) -> dict:
        d = {"name": self.name, "transfer": self.transfer}
        if self.net_input != "sum":  # files of networks without products stay as they were
            d["net_input"] = self.net_input
        return d


@dataclass(frozen=True)
class LayerSpec:
    """One layer m. `block` is the chart block it comes from; `kind` that block's kind."""

    name: str
    neurons: tuple[NeuronSpec, ...]
    block: str | None = None
    kind: str | None = None

    @property
    def size(self) -> int:
        return len(self.neurons)


@dataclass(frozen=True)
class InputSpec:
    """Network input p^l (dimension 1: one chart input signal each).

    `intersample` "hold" or "linear" and `delay` (a dead time in seconds: a parameter name or a number text,
    None for none) say what the input is between its samples; the runtime feeds each network step the input's
    mean over the step (network.inputsignal)."""

    name: str
    unit: str | None = None
    intersample: str = "hold"
    delay: str | None = None

    def to_dict(self) -> dict:
        d = asdict(self)
        if self.intersample == "hold":  # files of networks with held inputs stay as they were
            del d["intersample"]
        if self.delay is None:
            del d["delay"]
        return d


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    init: float
    unit: str | None = None
    min: float | None = None
    max: float | None = None
    fixed: bool = False


@dataclass(frozen=True)
class FreeWeightSpec:
    """A weight learned directly (a `nonlinear` block's a_i, v_i, b_i, or any weight of a plain GDNN)."""

    name: str
    init: float
    block: str | None = None
    role: str | None = None  # "a" (input weight), "v" (output weight), "b" (bias) or None
    fixed: bool = False


@dataclass(frozen=True)
class WeightSpec:
    """One existing weight: where it sits and what it is.

    matrix: "LW" (from layer `source` with `delay`), "IW" (from input `source`), or "b" (bias; source -1).
    value = coef(parameters) * (free weight `free`, or 1 when None). `coef` is an expression text in
    parameter names and numbers (the sample time is folded in as a number).
    """

    matrix: str
    layer: int
    row: int
    source: int = -1
    col: int = 0
    delay: int = 0
    coef: str = "1"
    free: str | None = None
    origin: str | None = None


@dataclass(frozen=True)
class OutputSpec:
    """A fitted output: neuron `neuron` of layer `layer` is the chart signal `name`."""

    name: str
    layer: int
    neuron: int = 0
    unit: str | None = None


@dataclass(frozen=True)
class InitialState:
    """History of one neuron: a number, `data`: the first measured sample of output `data`, or `parameter`:
    the value of that physical parameter (`value` holds its chart value; a fit differentiates it)."""

    layer: int
    neuron: int = 0
    value: float = 0.0
    data: str | None = None
    parameter: str | None = None


@dataclass(frozen=True)
class DelayedEdge:
    """A chart edge the discretization delays (explicit Euler in a feedback path), and why."""

    source: str
    target: str
    delay: int
    loop: tuple[str, ...] = ()

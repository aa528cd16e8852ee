"""Discretize a chart: blocks become neurons, gain chains and delays fold into connections.

Which blocks become neurons (the paper's summing junctions):
- sum -> one linear neuron; integrator -> one linear neuron with a self connection a(t-1) (implicit Euler:
  y(t) = y(t-1) + T*x(t); its inputs carry the factor T); function -> one neuron with transfer f;
  product -> one linear neuron whose net input is the product of its weighted inputs (MATLAB's netprod), k in
  the first factor's weight;
  nonlinear -> `neurons` tanh neurons whose output weights v_i sit on the consumers' connections, and a linear
  neuron for the tanh basis's linear term c x (diagram.curves: with that basis the slopes a_i are fixed weights);
- gain, delay and constant blocks are folded: a gain multiplies the connection's coefficient, a delay adds
  samples to its delay, a constant becomes a bias. A folded block that is a chart output gets a linear
  read-out neuron of its own.
The feedback edges chosen by loop analysis add one step of delay (explicit Euler in the feedback path).

With `substeps` N the network steps at h = T/N: integrator inputs carry h instead of T (T/J1 becomes h/J1) and a
delay block of n samples becomes n*N steps, so the chart means the same in seconds; N = 1 is the paper's network.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..analysis.loops import LoopReport
from ..diagram.blocks import core_diagram
from ..diagram.curves import basis_of, basis_weights, learned_roles
from ..diagram.model import Block, Diagram
from ..errors import SdnnError
from ..expr import Expr, Num, const, mul, neg

__all__ = ["Source", "Connection", "NeuronBlock", "DiscreteChart", "discretize", "NEURON_KINDS"]

NEURON_KINDS = ("sum", "integrator", "function", "nonlinear", "product")
_TRANSFER = {"tanh": "tanh", "sin": "sin", "cos": "cos", "sign_smooth": "tanh", "sat": "sat", "sqrt": "sqrt",
             "abs": "abs", "exp": "exp", "square": "square", "signed_square": "signed_square"}
_SINGLE = ("sum", "integrator", "function", "product")  # blocks that are one neuron
DEFAULT_EPS = 1e-3
MAX_FOLDED = 40  # gain/delay blocks folded into one weight with a parameter in it (expr.py nests at most 50)


@dataclass(frozen=True)
class Source:
    """Where a connection comes from: a neuron (block, index), a chart input, or a constant (bias)."""

    kind: str  # "neuron" | "input" | "bias"
    name: str
    index: int = 0


@dataclass(frozen=True)
class Connection:
    """target neuron += coef * (free weight) * source(t - delay)."""

    source: Source
    coef: Expr
    delay: int
    free: str | None
    origin: tuple[str, ...]  # chart signals along the folded path, source first


@dataclass(frozen=True)
class NeuronBlock:
    """A chart block (or an output read-out) realised as neurons: one layer of the network."""

    name: str
    kind: str  # block kind, or "readout"
    transfers: tuple[str, ...]
    inputs: tuple[tuple[Connection, ...], ...]  # per neuron
    init: tuple[float | str, ...] | None = None  # integrators: history value or "data"
    net_input: str = "sum"  # "prod": the neuron multiplies its weighted inputs (a product block)


@dataclass(frozen=True)
class DiscreteChart:
    name: str
    sample_time: float
    neuron_blocks: tuple[NeuronBlock, ...]
    free_weights: tuple[tuple[str, str, str, float, bool], ...]  # (name, block, role, init, fixed)
    outputs: tuple[tuple[str, str, int], ...]  # (output signal, neuron block, neuron index)


def initial_nonlinear_weights(block: Block, seed: int, position: int,
                              diagram: Diagram | None = None) -> dict[str, np.ndarray]:
    """Stored weights when the chart has them; for the tanh basis the flat curve over the chart's `span` (1
    until a fit sets it from the data); for the paper's neurons uniform draws in init_range (seeded per block
    position)."""
    s = block.neurons or 3
    if block.weights is None and basis_of(block) == "tanh" and diagram is not None:
        block = replace(block, weights=basis_weights(diagram, block, block.span or 1.0))
    if block.weights is not None:
        w = block.weights
        return {"a": np.array(w.a), "v": np.array(w.v), "b": np.array(w.b) if w.b is not None else np.zeros(len(w.a)),
                "c": None if w.c is None else float(w.c)}
    lo, hi = block.init_range or (-0.5, 0.5)
    rng = np.random.default_rng([seed, position])
    a, v = rng.uniform(lo, hi, s), rng.uniform(lo, hi, s)
    b = rng.uniform(lo, hi, s) if block.bias else np.zeros(s)
    return {"a": a, "v": v, "b": b, "c": None}


def output_scale(b: Block) -> float:
    """What a neuron's output is multiplied by to give the block's signal: sqrt(eps) for `sqrt`, whose network
    transfer is the square root regularised on (-1, 1) fed with z / eps (sqrt(z) = sqrt(eps) sqrt(z / eps)); 1
    for every other block."""
    if b.kind == "function" and b.f == "sqrt":
        return float(np.sqrt(b.eps or DEFAULT_EPS))
    return 1.0


def discretize(diagram: Diagram, loops: LoopReport, seed: int = 0, substeps: int = 1) -> DiscreteChart:
    diagram = core_diagram(diagram)  # a registered kind compiles as the core block it lowers to
    blocks = {b.name: b for b in diagram.blocks}
    inputs = set(diagram.input_names)
    delayed = loops.delayed
    rank = {name: i for i, name in enumerate(loops.order)}

    def trace(signal: str, consumer: str, coef: Expr, delay: int, path: tuple[str, ...]) -> list[Connection]:
        """Follow `signal` back through folded blocks (gain, delay) to a neuron, an input or a constant.

        A loop: long chains of gains are legal, and Python's recursion limit is not a chart limit.
        """
        folded: list[str] = []
        while True:
            delay += 1 if (signal, consumer) in delayed else 0
            path = (signal,) + path
            if signal in inputs:
                return [Connection(Source("input", signal), coef, delay, None, path)]
            b = blocks[signal]
            if b.kind in _SINGLE:
                return [Connection(Source("neuron", b.name), mul(coef, const(output_scale(b))), delay, None, path)]
            if b.kind == "nonlinear":
                n = len(initial[b.name]["a"])  # stored weights say how many (a chart edited in code may differ)
                out = [Connection(Source("neuron", b.name, i), coef, delay, f"{b.name}.v{i + 1}", path)
                       for i in range(n)]
                if linear_term[b.name]:  # the linear term: a linear neuron after the tanh ones
                    out.append(Connection(Source("neuron", b.name, n), coef, delay, f"{b.name}.c", path))
                return out
            if b.kind == "constant":
                return [Connection(Source("bias", b.name), mul(coef, b.k), 0, None, path)]
            if b.name in folded:  # a loop of gains and delays only: no neuron to carry its state
                loop = folded[folded.index(b.name):][::-1]
                raise SdnnError.at(
                    "COMPILE003", f"loop {' -> '.join(loop + [loop[0]])} has only gain and delay blocks: it has no "
                    "input and always carries 0", diagram.file, b.location.line if b.location else None,
                    block=b.name, hint="add a sum block to the loop, or remove the loop")
            folded.append(b.name)
            (term,) = b.inputs
            factor = b.k if b.kind == "gain" else const(1.0)
            if term.sign < 0:
                factor = neg(factor)
            extra = b.n * substeps if b.kind == "delay" else 0
            signal, consumer, coef, delay = term.signal, b.name, mul(coef, factor), delay + extra
            if not isinstance(coef, Num) and len(folded) > MAX_FOLDED:
                # the folded weight nests one level per gain; the network file must be able to read it back
                raise SdnnError.at(
                    "COMPILE004", f"{len(folded)} gain/delay blocks in series fold into one weight, more than "
                    f"the {MAX_FOLDED} a weight expression may nest", diagram.file,
                    b.location.line if b.location else None, block=b.name,
                    hint="merge the gains into one, or put a sum block in the chain")

    def terms_of(b: Block, scale: Expr) -> tuple[Connection, ...]:
        out: list[Connection] = []
        for t in b.inputs:
            sign = const(float(t.sign))
            out.extend(trace(t.signal, b.name, mul(scale, sign), 0, (b.name,)))
        return tuple(out)

    def factors(b: Block) -> tuple[Connection, ...]:
        """One connection per factor of a product: a factor that is a sum of several connections (a learned
        curve's weighted tanh neurons) would need a neuron of its own."""
        out: list[Connection] = []
        for i, t in enumerate(b.inputs):
            scale = (b.k if b.k is not None else const(1.0)) if i == 0 else const(1.0)
            conns = trace(t.signal, b.name, mul(scale, const(float(t.sign))), 0, (b.name,))
            if len(conns) != 1:
                raise SdnnError.at(
                    "COMPILE005", f"a product cannot take the learned curve '{t.signal}' as a factor directly",
                    diagram.file, b.location.line if b.location else None, block=b.name,
                    hint=f"put a sum block in between: {{type: sum, in: [{t.signal}]}}")
            out.extend(conns)
        return tuple(out)

    initial = {b.name: initial_nonlinear_weights(b, seed, rank.get(b.name, 0), diagram)
               for b in diagram.blocks if b.kind == "nonlinear"}
    linear_term = {name: w["c"] is not None for name, w in initial.items()}
    neuron_blocks: list[NeuronBlock] = []
    free: list[tuple[str, str, str, float, bool]] = []
    T = const(diagram.sample_time / substeps)  # the step h; exactly T when substeps is 1
    for b in sorted(diagram.blocks, key=lambda b: rank.get(b.name, len(rank))):
        if b.kind == "sum":
            neuron_blocks.append(NeuronBlock(b.name, b.kind, ("linear",), (terms_of(b, const(1.0)),)))
        elif b.kind == "integrator":
            self_loop = Connection(Source("neuron", b.name), const(1.0), 1, None, (b.name, b.name))
            conns = (self_loop,) + terms_of(b, T)
            neuron_blocks.append(NeuronBlock(b.name, b.kind, ("linear",), (conns,), (b.init if b.init is not None
                                                                                      else 0.0,)))
        elif b.kind == "function":
            k = b.k if b.k is not None else const(1.0)
            if b.f in ("sign_smooth", "sqrt"):  # the network's tanh and sqrt have eps = 1: scale the argument
                k = mul(k, const(1.0 / (b.eps or DEFAULT_EPS)))
            neuron_blocks.append(NeuronBlock(b.name, b.kind, (_TRANSFER[b.f],), (terms_of(b, k),)))
        elif b.kind == "product":
            neuron_blocks.append(NeuronBlock(b.name, b.kind, ("linear",), (factors(b),), net_input="prod"))
        elif b.kind == "nonlinear":
            w = initial[b.name]
            learned = learned_roles(b)
            (base,) = [terms_of(b, const(1.0))]
            if any(c.free is not None for c in base):
                raise SdnnError.at(
                    "COMPILE001", "a nonlinear block cannot take another nonlinear block's output directly",
                    diagram.file, b.location.line if b.location else None, block=b.name,
                    hint="put a sum or function block in between")
            per_neuron = []
            for i in range(len(w["a"])):
                conns = tuple(
                    Connection(c.source, c.coef, c.delay, f"{b.name}.a{i + 1}", c.origin) for c in base
                )
                if b.bias:
                    conns += (Connection(Source("bias", b.name), const(1.0), 0, f"{b.name}.b{i + 1}", (b.name,)),)
                per_neuron.append(conns)
                free.append((f"{b.name}.a{i + 1}", b.name, "a", float(w["a"][i]), "a" not in learned))
                free.append((f"{b.name}.v{i + 1}", b.name, "v", float(w["v"][i]), "v" not in learned))
                if b.bias:
                    free.append((f"{b.name}.b{i + 1}", b.name, "b", float(w["b"][i]), "b" not in learned))
            transfers = ("tanh",) * len(w["a"])
            if linear_term[b.name]:  # c x: a linear neuron fed by the input as it is, c on its consumers
                per_neuron.append(base)
                transfers += ("linear",)
                free.append((f"{b.name}.c", b.name, "c", float(w["c"]), "c" not in learned))
            neuron_blocks.append(NeuronBlock(b.name, b.kind, transfers, tuple(per_neuron)))

    outputs = []
    for s in diagram.outputs:
        b = blocks[s.name]
        if b.kind in _SINGLE and output_scale(b) == 1.0:
            outputs.append((s.name, b.name, 0))
            continue
        # folded blocks (and a nonlinear block's weighted sum) are read out by a linear neuron of their own
        readout = f"{b.name}__out"
        conns = tuple(trace(b.name, readout, const(1.0), 0, (readout,)))
        neuron_blocks.append(NeuronBlock(readout, "readout", ("linear",), (conns,)))
        outputs.append((s.name, readout, 0))
    return DiscreteChart(diagram.name, diagram.sample_time, tuple(neuron_blocks), tuple(free), tuple(outputs))

"""Learned static curves (`nonlinear` blocks): which weights a curve has, which of them are learned.

A curve is y = sum_i v_i tanh(a_i x + b_i) + c x. Two bases:

* ``tanh`` (the default): BASIS_FUNCTIONS functions whose slopes a_i are fixed, log-spaced so that they span
  the input's range from bending once over the whole of it to a step over 1/1000 of it; only the output
  weights v_i and the linear term c are learned (a chart's `neurons` counts the paper's neurons, not these). The curve then enters the model linearly in its weights and Gauss-Newton treats
  it as linear least squares: no valley between a slope and its output weight to crawl along.
* ``neurons``: the paper's free-slope neurons, a_i, v_i (and b_i with ``bias``) all learned.

The linear term c x is on unless the chart already has one: a gain of the curve's own input summed with the
curve (a viscous gain beside a friction curve), which c could not be told apart from.

Layer: diagram (imports nothing above it).
"""

from __future__ import annotations

import math

from .model import Block, Diagram, NonlinearWeights

__all__ = ["BASES", "DEFAULT_BASIS", "SPAN_DECADES", "PER_DECADE", "BASIS_FUNCTIONS", "basis_of", "basis_gains", "has_linear_term",
           "basis_weights", "learned_roles", "weight_names", "describe_curve", "needs_span"]

BASES = ("tanh", "neurons")
DEFAULT_BASIS = "tanh"
#: The fixed slopes span three decades: the widest function bends once over the input's range, the steepest is
#: a step over 1/1000 of it, about the resolution of a 10-bit converter, beyond which a sharper step cannot be
#: told apart from the data.
SPAN_DECADES = 3.0
#: ... at two functions a decade: a tanh of any width in between is then matched by its two neighbours to
#: within a few per cent of its height, so a Stribeck fall at any speed is representable.
PER_DECADE = 2
BASIS_FUNCTIONS = int(SPAN_DECADES * PER_DECADE) + 1


def basis_of(block: Block) -> str:
    return block.basis or DEFAULT_BASIS


def basis_gains(n: int) -> tuple[float, ...]:
    """The fixed slopes times the span: log-spaced over SPAN_DECADES (one function: the middle of them)."""
    if n == 1:
        return (10.0 ** (SPAN_DECADES / 2),)
    return tuple(10.0 ** (SPAN_DECADES * k / (n - 1)) for k in range(n))


def _summed_with(diagram: Diagram, name: str) -> list[Block]:
    return [b for b in diagram.blocks if b.kind == "sum" and any(t.signal == name for t in b.inputs)]


def _reads(diagram: Diagram, name: str, signal: str, depth: int = 8) -> bool:
    """Whether signal `name` is a chain of gains of `signal` alone (a viscous term k*x)."""
    blocks = {b.name: b for b in diagram.blocks}
    for _ in range(depth):
        if name == signal:
            return True
        b = blocks.get(name)
        if b is None or b.kind != "gain":
            return False
        name = b.inputs[0].signal
    return False


def has_linear_term(diagram: Diagram, block: Block) -> bool:
    """Whether the curve carries its own c x: `linear` when the chart says, else unless a sum that adds the
    curve also adds a gain of the curve's input (the two could not be told apart)."""
    if basis_of(block) == "neurons":
        return False
    if block.weights is not None:  # stored weights say it
        return block.weights.c is not None
    if block.linear is not None:
        return bool(block.linear)
    x = block.inputs[0].signal if block.inputs else None
    for s in _summed_with(diagram, block.name):
        for t in s.inputs:
            if t.signal != block.name and t.signal != x and _reads(diagram, t.signal, x):
                return False
    return True


def needs_span(block: Block) -> bool:
    """A tanh-basis curve whose slopes are not set yet (no stored weights, no `span`): the fit sets them."""
    return basis_of(block) == "tanh" and block.weights is None and block.span is None


def basis_weights(diagram: Diagram, block: Block, span: float) -> NonlinearWeights:
    """The flat curve (v = 0, c = 0) of the tanh basis over an input range of +-span."""
    n = block.neurons or 3
    # a span so small that the steepest slope overflows is no range at all (an input that never moves)
    span = span if math.isfinite(span) and span > 0 and math.isfinite(max(basis_gains(n)) / span) else 1.0
    a = tuple(g / span for g in basis_gains(n))
    return NonlinearWeights(a, (0.0,) * n, (0.0,) * n if block.bias else None,
                            0.0 if has_linear_term(diagram, block) else None)


def learned_roles(block: Block) -> tuple[str, ...]:
    """The roles of the weights a fit moves (none for a fixed curve)."""
    if block.fixed:
        return ()
    if basis_of(block) == "neurons":
        return ("a", "v", "b") if block.bias else ("a", "v")
    return ("v", "c")


def weight_names(diagram: Diagram, block: Block, learned_only: bool = True) -> list[str]:
    """The curve's weight names as the network has them (a1, v1, b1, a2, ..., c)."""
    n = block.neurons or 3
    roles = learned_roles(block) if learned_only else ("a", "v", "b", "c")
    out = []
    for i in range(1, n + 1):
        out += [f"{block.name}.{r}{i}" for r in ("a", "v", "b") if r in roles and (r != "b" or block.bias)]
    if "c" in roles and has_linear_term(diagram, block):
        out.append(f"{block.name}.c")
    return out


def describe_curve(diagram: Diagram, block: Block) -> str:
    """What the curve can represent, in words (lint)."""
    x = block.inputs[0].signal if block.inputs else "?"
    n = block.neurons or 3
    if basis_of(block) == "neurons":
        shape = "any shape" if block.bias else "odd"
        return f"{block.name} = f({x}): {n} free-slope tanh neurons (the paper's), {shape}"
    w = block.weights
    odd = not block.bias or w is None or w.b is None or not any(w.b)
    if w is not None:
        span = f"+-{max(g for g in basis_gains(n)) / max(abs(a) for a in w.a):.4g}"
    elif block.span is not None:
        span = f"+-{block.span:.4g}"
    else:
        span = "the data's range of " + x
    lin = " + a linear term" if has_linear_term(diagram, block) else " (the chart's gain gives the linear part)"
    return (f"{block.name} = f({x}): {'odd' if odd else 'any shape'}, {n} tanh functions at fixed slopes "
            f"spanning {span}{lin}; learned weights enter linearly")

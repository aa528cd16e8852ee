"""Two small effects that widen a chart's laws at neutral values: a power law's linear companion and an
input's zero offset.

* ``linear_term`` at a power-law block ``r = f(x)`` (f = sqrt, square or signed_square: Torricelli's outflow,
  quadratic drag): every gain that scales it, ``q = k r``, becomes ``q = k r + c x`` with a new parameter
  c = 0 (neutral). A real orifice passes a laminar share besides the turbulent one, a drag has a viscous
  share; the fit sets how much (c may take over: on Cascaded Tanks the upper tank's outflow becomes linear,
  k1 -> 0, which ``k (r + c x)`` could not express). Blocks of the chart only; f's operand must be one signal.
* ``input_offset`` at an input u: the chart's physics reads ``u + o`` (o = 0, neutral) - a pump that starts
  delivering above some voltage (seen as a negative o), an amplifier's zero, a torque command's bias. The
  input twin of ``sensor_offset``.

Layer: diagnose.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..diagram.model import Block, Diagram, Parameter, Term
from ..expr import parse_expr
from .graph import Place, add_blocks, consumers, input_places, namer, reroute

__all__ = ["LinearTerm", "InputOffset", "POWER_LAWS"]

#: functions whose law ``k f(x)`` a linear term ``c x`` widens
POWER_LAWS = ("sqrt", "square", "signed_square")


@dataclass(frozen=True)
class LinearTerm:
    """``k f(x)`` becomes ``k f(x) + c x`` (c = 0) at a power-law block f; see the module's text."""

    name: str = "linear_term"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return tuple(Place(b.name, "law", via=b.inputs[0].signal) for b in diagram.blocks
                     if b.kind == "function" and b.f in POWER_LAWS and len(b.inputs) == 1 and b.inputs[0].sign > 0)

    def options(self, diagram: Diagram, place: Place, scales) -> tuple:
        return (None,)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        r, x = place.at, place.via
        new = namer(diagram)
        c = new(f"{r}_lin")
        law = diagram.block(r)
        gains = [g for g in consumers(diagram, r) if g.kind == "gain"]
        # the scaled law q = k r takes the term (k may go to 0); a law read unscaled takes it on r itself
        targets = [g.name for g in gains] if gains and len(gains) == len(consumers(diagram, r)) else [r]
        params = [Parameter(c, 0.0, description=f"linear share of the law {law.f}({x}) at {r}: + {c}*{x} "
                                                "(diagnose)")]
        out = add_blocks(diagram, (), params)
        for t in targets:
            lin, widened = new(f"{t}_linterm"), new(f"{t}_widened")
            blocks = (Block(lin, "gain", (Term(x),), k=parse_expr(c)),
                      Block(widened, "sum", (Term(t), Term(lin)), unit=diagram.block(t).unit,
                            description=f"{t} with the linear term of {x} (diagnose)"))
            out = reroute(add_blocks(out, blocks), t, widened, keep={widened})
        return out

    def describe(self) -> str:
        return "linear_term: a power law k*f(x) (sqrt, square) widened by c*x, c learned from 0"

    def label(self, option) -> str:
        return ""


@dataclass(frozen=True)
class InputOffset:
    """The chart's physics reads an input plus a learned zero offset, ``u + o`` (o = 0, neutral)."""

    name: str = "input_offset"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return input_places(diagram)

    def options(self, diagram: Diagram, place: Place, scales) -> tuple:
        return (None,)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        u = place.at
        new = namer(diagram)
        off, const, phys = new(f"{u}_zero"), new(f"{u}_zeroc"), new(f"{u}_phys")
        unit = next((s.unit for s in diagram.inputs if s.name == u), None)
        p = Parameter(off, 0.0, unit=unit, description=f"zero offset of the input {u}: the physics reads {u} + this "
                      "(diagnose)")
        blocks = (Block(const, "constant", k=parse_expr(off), unit=unit),
                  Block(phys, "sum", (Term(u), Term(const)), unit=unit,
                        description=f"{u} as the physics sees it: + its zero offset (diagnose)"))
        return reroute(add_blocks(diagram, blocks, [p]), u, phys, keep={phys})

    def describe(self) -> str:
        return "input_offset: the physics reads an input plus a learned zero offset"

    def label(self, option) -> str:
        return ""

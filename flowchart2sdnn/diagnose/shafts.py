"""Effects of a shaft's play on its spring: exact backlash of a scanned gap (dead_zone) and a learned odd
curve of the angle (backlash). The table of all effects is :mod:`.effects`'s."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from ..diagram.model import Block, Diagram, Parameter, Term
from ..expr import parse_expr
from .graph import Place, add_blocks, curve_block, fresh_name, namer, seat_curve, spring_angles

if TYPE_CHECKING:
    from .effects import Scales


@dataclass(frozen=True)
class DeadZone:
    """Exact backlash, a dead zone in the shaft: the spring torque ``c x`` becomes ``c (x - g sat(x / g))``, g the half gap.

    Inside ``|x| < g`` the shaft transmits nothing; outside it acts as before, shifted by the gap. At g = 0
    the patch is neutral but the clip is undefined, so g is scanned as fractions of the angle's RMS (like a
    saturation limit) and learned by the refit.
    """

    fractions: tuple[float, ...] = (0.05, 0.1, 0.2, 0.35, 0.5)
    name: str = "dead_zone"
    neutral: bool = False
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return spring_angles(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return tuple(round(f * scales.scale(place.at), 15) for f in self.fractions)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        gap = float(option) if option else 1e-3
        x = place.at
        spring = diagram.block(place.via)
        new = namer(diagram)

        g, clip, width, inside = new(f"{x}_gap"), new(f"dz_{x}_clip"), new(f"dz_{x}_g"), new(f"dz_{x}")
        unit = next((b.unit for b in diagram.blocks if b.name == x), None)
        param = Parameter(g, gap, unit=unit, min=0.0, description=f"half gap of the backlash in {x} (diagnose)")
        blocks = [
            Block(clip, "function", (Term(x),), k=parse_expr(f"1/{g}"), f="sat"),
            Block(width, "gain", (Term(clip),), k=parse_expr(g), unit=unit),
            Block(inside, "sum", (Term(x), Term(width, -1)), unit=unit,
                  description=f"{x} beyond the backlash (diagnose)"),
        ]
        patched = add_blocks(diagram, blocks, [param])
        return replace(patched, blocks=tuple(
            replace(b, inputs=tuple(Term(inside, t.sign) if t.signal == x else t for t in b.inputs))
            if b.name == spring.name else b for b in patched.blocks))

    def describe(self) -> str:
        return "dead_zone: a hard gap of learned width in the shaft angle before the spring (exact backlash)"

    def label(self, option) -> str:
        return f"gap={float(option):.3g}"


@dataclass(frozen=True)
class Backlash:
    """Backlash: the spring torque ``c x`` becomes ``c x + sum v_i tanh(a_i x)`` (odd, the tanh basis over the
    angle's range, v = 0 at the start), a learned curve that can form a dead zone (or a hardening or softening
    spring)."""

    name: str = "backlash"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return spring_angles(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return (scales.span(place.at),)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        span = float(option) if option else 1.0
        spring = diagram.block(place.via)
        lin = fresh_name(diagram, f"{spring.name}_lin")
        curve = fresh_name(diagram, f"bl_{place.at}", {lin})
        block = curve_block(curve, place.at, span, f"backlash of {place.at} (diagnose)")
        blocks = []
        for b in diagram.blocks:
            if b.name == spring.name:
                blocks.append(replace(b, name=lin))
                blocks.append(Block(spring.name, "sum", (Term(lin), Term(curve)), unit=spring.unit,
                                    description="spring torque with backlash (diagnose)"))
            else:
                blocks.append(b)
        return seat_curve(add_blocks(replace(diagram, blocks=tuple(blocks)), [block]), curve)

    def describe(self) -> str:
        return "backlash: the spring torque becomes c*x plus a learned odd curve of the shaft angle"

    def label(self, option) -> str:
        return ""

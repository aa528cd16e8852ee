"""Effects of a position: a learned spring to ground, and torques periodic in the angle (cogging, unbalance).

A position is an integrator of one speed (:func:`.graph.positions`); a machine whose chart has no position
block still has an angle, the integral of its speed, which a periodic torque integrates for itself.

* ``spring`` at a position x whose chart has a spring to ground (a parameter gain ``k x`` in the torque
  sum of x's speed): a force ``f(x)``, an odd learned curve (the tanh basis of diagram.curves over x's
  range, flat at the start: neutral) entered in that sum against x. The curve has no linear term of its own
  (k is that): it bends ``k x`` into a hardening or softening spring, as backlash bends a shaft's. A position
  without a spring is not offered one: on EMPS (a linear axis, 0.25 m of travel) a learned curve of the
  position took the place of the friction the axis has (any smooth function of a position that travels
  little fits part of anything); a user effect with ``attach: position`` states a spring there.
* ``cogging`` at a speed: ``A sin(p phi) + B cos(p phi)`` (A = B = 0: neutral), phi the chart's position of
  that speed when it has one (an encoder's angle started from the data keeps its true phase in every
  record), else a new integral of the speed. p = 1 is one period per revolution: the unbalance of a load,
  ``m g l sin(phi + phase)``, is its A and B. Offered at every speed, the motor's and the load's.

Layer: diagnose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..diagram.model import Block, Diagram, Parameter, Term
from ..expr import parse_expr
from .graph import (
    Place,
    add_blocks,
    add_terms,
    consumers,
    curve_block,
    namer,
    position_of,
    positions,
    seat_curve,
    speeds,
    sum_terms,
)

__all__ = ["Spring", "Cogging"]


def _has_spring(diagram: Diagram, place: Place) -> bool:
    """Whether the position feeds a parameter gain that enters one of its speed's torque sums."""
    sums = {s for s, _ in place.sums}
    return any(g.kind == "gain" and not g.k.is_constant and any(c.name in sums for c in consumers(diagram, g.name))
               for g in consumers(diagram, place.at))


@dataclass(frozen=True)
class Spring:
    """A spring to ground bent by a learned curve: ``k x + sum v_i tanh(a_i x)`` (odd, v = 0) against x."""

    name: str = "spring"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return tuple(p for p in positions(diagram) if _has_spring(diagram, p))

    def options(self, diagram: Diagram, place: Place, scales) -> tuple:
        return (scales.span(place.at),)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        span = float(option) if option else 1.0
        name = namer(diagram)(f"spring_{place.at}")
        block = curve_block(name, place.at, span, f"spring force of the position {place.at} (diagnose)")
        return seat_curve(add_terms(add_blocks(diagram, [block]), sum_terms(place, name)), name)

    def describe(self) -> str:
        return "spring: a spring to ground k*x plus a learned odd curve of the position (hardening, softening)"

    def label(self, option) -> str:
        return ""


@dataclass(frozen=True)
class Cogging:
    """A position-periodic torque ``A sin(p phi) + B cos(p phi)`` at a speed, ``phi`` its angle (see the
    module's text).

    When the chart already integrates the speed into a position (``q = integral(w)``, e.g. a linear axis
    whose output is its position), harmonics whose period ``2 pi / p`` is longer than twice the RMS of that
    position are not offered: over less than about one period a "periodic" torque is only a smooth function
    of the position (on EMPS, p = 1..3 rad/m over 0.25 m of travel fitted amplitudes of 1 kN that cancel).
    Except p = 1 on an angle (unit rad): one period a revolution is the law of an unbalance, m g l sin(phi +
    phase), whose A and B are the physical m g l and zero angle even where the load only swings.
    """

    harmonics: tuple[int, ...] = (1, 2, 3, 4, 6, 8, 12)
    name: str = "cogging"
    neutral: bool = True
    extra_dof: int = 1  # p is chosen too
    repeatable: bool = True  # harmonics of one place add up

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return speeds(diagram)

    def options(self, diagram: Diagram, place: Place, scales) -> tuple:
        own = [b for b in diagram.blocks if b.kind == "integrator" and b.inputs == (Term(place.at),)]
        spans = [float(scales.rms[b.name]) for b in own if b.name in scales.rms]
        if not spans:
            return tuple(self.harmonics)
        units = {s.name: s.unit for s in diagram.outputs}
        angle = any((b.unit or units.get(b.name)) == "rad" for b in own)
        return tuple(p for p in self.harmonics if 2 * math.pi / p <= 2 * max(spans) or (p == 1 and angle))

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        p = int(option) if option is not None else 1
        w = place.at
        new = namer(diagram)

        own = position_of(diagram, w)
        pa, pb = new(f"cog{p}_A_{w}"), new(f"cog{p}_B_{w}")
        phi = own or new(f"phi_{w}")
        s, c = new(f"cog{p}_sin_{w}"), new(f"cog{p}_cos_{w}")
        ga, gb, out = new(f"cog{p}_As_{w}"), new(f"cog{p}_Bc_{w}"), new(f"cog{p}_{w}")
        unit = next((b.unit for b in diagram.blocks if b.name == place.sums[0][0]), None) if place.sums else None
        params = [Parameter(pa, 0.0, unit=unit, description=f"cogging sine amplitude, harmonic {p} (diagnose)"),
                  Parameter(pb, 0.0, unit=unit, description=f"cogging cosine amplitude, harmonic {p} (diagnose)")]
        angle = [] if own else [Block(phi, "integrator", (Term(w),), init=0.0, description=f"angle of {w} (diagnose)")]
        blocks = angle + [
            Block(s, "function", (Term(phi),), k=parse_expr(p), f="sin"),
            Block(c, "function", (Term(phi),), k=parse_expr(p), f="cos"),
            Block(ga, "gain", (Term(s),), k=parse_expr(pa)),
            Block(gb, "gain", (Term(c),), k=parse_expr(pb)),
            Block(out, "sum", (Term(ga), Term(gb)), unit=unit, description=f"cogging torque of {w} (diagnose)"),
        ]
        return add_terms(add_blocks(diagram, blocks, params), sum_terms(place, out))

    def describe(self) -> str:
        return (f"cogging: A sin(p phi) + B cos(p phi) of the angle of a speed (the motor's or the load's; p = 1 "
                f"an unbalance), p in {list(self.harmonics)}")

    def label(self, option) -> str:
        return f"p={int(option)}"

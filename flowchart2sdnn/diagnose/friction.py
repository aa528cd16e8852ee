"""Effects of a speed's friction: a learned curve of the speed (friction), its physical terms (coulomb, an
option of friction) and a viscous gain (damping). The table of all effects is :mod:`.effects`'s."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..diagram.model import Block, Diagram, Parameter, Term
from ..expr import parse_expr
from .graph import (
    Place,
    add_blocks,
    add_terms,
    curve_block,
    fresh_name,
    namer,
    seat_curve,
    speed_differences,
    speeds,
    sum_terms,
)

if TYPE_CHECKING:
    from .effects import Scales


@dataclass(frozen=True)
class Coulomb:
    """Physical friction terms instead of a learned curve: ``Fc sign_smooth(w) + c + dFv relu(w)``.

    ``sign_smooth(w) = tanh(w / eps)`` with ``eps = rms(w) / sharpness``; ``relu(w) = max(w, 0)``, built
    exactly from a clip, ``L sat((w - L) / L) + L`` for ``w < 2 L``, ``L = reach * rms(w)``. Fc (>= 0), c and
    dFv start at 0 (neutral). Against the motion this adds ``Fc + c`` (Coulomb) and ``dFv`` (viscous) forwards,
    ``Fc - c`` and 0 backwards: the asymmetric Coulomb and viscous friction of a drive (Janot et al.'s
    ``Fc+-``, ``Fv+-``) or, with dFv = 0, the ``Fc sign(v) + offset`` model. With three parameters it
    generalises where a learned curve (:class:`Friction`) bends into one record's details. With
    ``asymmetric=False`` only Fc and c are added.
    """

    sharpness: float = 100.0
    reach: float = 10.0
    asymmetric: bool = True
    name: str = "coulomb"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return speeds(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return (scales.scale(place.at),)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        scale = float(option) if option else 1.0
        w = place.at
        new = namer(diagram)

        fc, c = new(f"Fc_{w}"), new(f"c_{w}")
        sgn, fric, off = new(f"sgn_{w}"), new(f"coulomb_{w}"), new(f"offset_{w}")
        unit = next((b.unit for b in diagram.blocks if b.name == place.sums[0][0]), None) if place.sums else None
        w_unit = next((b.unit for b in diagram.blocks if b.name == w), None)
        params = [Parameter(fc, 0.0, unit=unit, min=0.0, description=f"Coulomb friction of {w} (diagnose)"),
                  Parameter(c, 0.0, unit=unit, description=f"constant torque in the sum of {w} (diagnose)")]
        blocks = [
            Block(sgn, "function", (Term(w),), f="sign_smooth", eps=scale / self.sharpness),
            Block(fric, "gain", (Term(sgn),), k=parse_expr(fc), unit=unit,
                  description=f"Coulomb friction of {w} (diagnose)"),
            Block(off, "constant", k=parse_expr(c), unit=unit,
                  description=f"constant torque in the sum of {w} (diagnose)"),
        ]
        new_terms = [fric, off]
        if self.asymmetric:
            dfv = new(f"dFv_{w}")
            lvl, one, shifted, clip, relu, visc = (new(f"reach_{w}"), new(f"one_{w}"), new(f"{w}_shift"),
                                                   new(f"{w}_clip"), new(f"relu_{w}"), new(f"dvisc_{w}"))
            reach = self.reach * scale
            params.append(Parameter(dfv, 0.0, description=f"extra viscous friction of {w} > 0 (diagnose)"))
            # relu(w) / L = sat((w - L) / L) + 1, exact for w < 2 L
            blocks += [
                Block(lvl, "constant", k=parse_expr(repr(reach)), unit=w_unit),
                Block(one, "constant", k=parse_expr("1")),
                Block(shifted, "sum", (Term(w), Term(lvl, -1)), unit=w_unit),
                Block(clip, "function", (Term(shifted),), k=parse_expr(repr(1.0 / reach)), f="sat"),
                Block(relu, "sum", (Term(clip), Term(one))),
                Block(visc, "gain", (Term(relu),), k=parse_expr(f"{dfv}*{reach!r}"), unit=unit,
                      description=f"extra viscous friction of {w} forwards (diagnose)"),
            ]
            new_terms.append(visc)
        terms: dict[str, tuple[Term, ...]] = {}
        for s, sign in place.sums:
            terms[s] = terms.get(s, ()) + tuple(Term(t, sign) for t in new_terms)
        return add_terms(add_blocks(diagram, blocks, params), terms)

    def describe(self) -> str:
        return ("coulomb: Coulomb friction Fc*sign_smooth(w), a constant c and an extra viscous dFv*max(w, 0) "
                "(asymmetric friction with physical parameters) on a speed")

    def label(self, option) -> str:
        return ""


@dataclass(frozen=True)
class Physical:
    """The option of :class:`Friction` that adds :class:`Coulomb`'s physical terms instead of a learned curve."""

    scale: float

    def __str__(self) -> str:
        return "coulomb"


@dataclass(frozen=True)
class Friction:
    """Friction of a speed against the motion: a learned curve ``sum v_i tanh(a_i w + b_i)`` or physical terms.

    Two options per speed. The learned curve: the tanh basis of diagram.curves over the speed's range, flat at
    the start (v = 0, neutral), fixed slopes from nearly a sign function to nearly linear, so that the curve can
    bend into a Stribeck bump and enters the fit linearly. The physical option (:class:`Physical`, when `physical`
    is set): :class:`Coulomb`'s ``Fc sign_smooth(w) + c + dFv max(w, 0)`` with three named parameters. Both
    are scored; the refit set takes the better-scored option of each place, and the other one as a runner-up
    when friction at that speed is the best place; the refits decide (validation RMS, within a tie the
    criterion, where the physical terms' fewer parameters count). Sharing one (effect, place) key, the
    second option never pushes another place out of the refit set.
    """

    physical: Coulomb | None = Coulomb()
    name: str = "friction"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return speeds(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        scale = scales.scale(place.at)
        return (scales.span(place.at),) + ((Physical(scale),) if self.physical is not None else ())

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        if isinstance(option, Physical):
            return (self.physical or Coulomb()).patch(diagram, place, option.scale)
        span = float(option) if option else 1.0
        name = fresh_name(diagram, f"fric_{place.at}")
        block = curve_block(name, place.at, span, f"friction of {place.at} (diagnose)")
        return seat_curve(add_terms(add_blocks(diagram, [block]), sum_terms(place, name)), name)

    def describe(self) -> str:
        text = "friction: a learned curve of a speed (the tanh basis over its range) against the motion"
        return text + (", or Coulomb + offset + one-sided viscous terms with physical parameters"
                       if self.physical is not None else "")

    def label(self, option) -> str:
        return "coulomb" if isinstance(option, Physical) else ""

    def leaves_room(self, option) -> bool:
        """Accepted physical terms leave the learned curve on offer at that speed: Coulomb + viscous terms
        cannot bend into a Stribeck bump, and without the curve the loop filled the bump in with a cogging
        term the plant lacks (README tour bench)."""
        return isinstance(option, Physical)


@dataclass(frozen=True)
class Damping:
    """A viscous torque ``b * w`` (or ``b * (w1 - w2)``) with a new parameter b, starting at 0."""

    name: str = "damping"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return speeds(diagram) + speed_differences(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return (None,)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        pname = fresh_name(diagram, f"b_{place.at}")
        name = fresh_name(diagram, f"damp_{place.at}", {pname})
        # dissipative only: a negative damping would only imitate discretisation error or a missing effect
        p = Parameter(pname, 0.0, min=0.0, description=f"viscous damping of {place.at} (diagnose)")
        block = Block(name, "gain", (Term(place.at),), k=parse_expr(pname),
                      description=f"viscous damping of {place.at} (diagnose)")
        return add_terms(add_blocks(diagram, [block], [p]), sum_terms(place, name))

    def describe(self) -> str:
        return "damping: a viscous gain with a new parameter on a speed or a speed difference"

    def label(self, option) -> str:
        return ""

"""The effects library: named, composable candidates for what a chart lacks (PySINDy's feature libraries).

Each effect is a small frozen object that knows

* ``places(diagram)`` - where it may attach (:class:`~.graph.Place`);
* ``options(diagram, place, scales)`` - the discrete choices to try there (a dead time's n, a saturation
  limit, a cogging harmonic, or the signal scale that sets a learned curve's neutral shape);
* ``patch(diagram, place, option)`` - a NEW chart with the effect added and its new quantities at values
  that are *neutral* when ``neutral`` is True (the patched chart's outputs equal the input chart's, so the
  score test of :mod:`.score` applies at the current fit); effects whose choice changes the model at once
  (dead time, a saturation limit inside the data range) are scored from the patched chart as it is;
* ``describe()`` and ``label(option)`` for reports.

The chart given is never mutated (every patch goes through :func:`dataclasses.replace`).

=============  ==================  =====================================================================
effect         attaches at         adds
=============  ==================  =====================================================================
friction       speed               nonlinear curve of the speed (tanh neurons with bias, v = 0) subtracted
                                   in its torque sum; or (option "coulomb") the terms of `coulomb`
damping        speed, speed diff.  viscous gain with a new parameter (0) in the torque sum(s)
(coulomb)      speed               Fc*sign_smooth(w) + c + dFv*max(w, 0), new parameters at 0: asymmetric
                                   Coulomb and viscous friction with physical parameters (an option of
                                   friction; not in the registry on its own)
dead_time      input               a dead time tau (s) on the input: n samples scanned, tau fitted within n -+ 1/2
saturation     input               L*sat((u - o)/L) + o: a hard clip at o -/+ L, L scanned in the data range
sensor_limit   output              the same clip on a measured output (a sensor or its converter at its range);
                                   the chart's block is renamed, the output reads the clipped signal (an
                                   `init: data` block keeps its start: `measured_by` the output)
sensor_offset  output (read)       the physics reads the measured output + o (o = 0): a sensor's zero offset
backlash       spring angle        c*x becomes c*x + an odd learned curve (v = 0) of x (a dead zone is learnable)
dead_zone      spring angle        c*x becomes c*(x - g*sat(x/g)): exact backlash of half gap g (scanned)
cogging        speed               A sin(p phi) + B cos(p phi) (A = B = 0) in the sum, phi the speed's position
                                   in the chart or a new integral of it; p = 1 an unbalance (p with a period
                                   beyond 2 RMS of a position the chart has: not offered) (:mod:`.positions`)
spring         position (sprung)   k*x to ground becomes k*x + an odd learned curve of x (v = 0) in its speed's
                                   sum: a hardening or softening spring (:mod:`.positions`)
overflow       integrator state    x' = f - K relu(x - L): x held at a learned level L (or above a lower one),
                                   the excess lost or routed into a downstream integrator (:mod:`.overflow`)
input_offset   input               the physics reads u + o (o = 0): an input's zero offset (:mod:`.lawterms`)
linear_term    power law f(x)      k*f(x) becomes k*f(x) + c*x (c = 0), f = sqrt, square, signed_square: a
                                   Torricelli outflow's laminar share, a drag's viscous share (:mod:`.lawterms`)
=============  ==================  =====================================================================
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol, runtime_checkable

from ..diagram.model import Block, Diagram, Parameter, Term
from ..errors import SdnnError, did_you_mean
from ..expr import parse_expr
from .graph import (
    Place,
    add_blocks,
    add_terms,
    curve_block,
    fresh_name,
    input_places,
    namer,
    output_places,
    rename_block,
    reroute,
    seat_curve,
    speed_differences,
    speeds,
    spring_angles,
    sum_terms,
)
from .lawterms import InputOffset, LinearTerm
from .overflow import Overflow
from .positions import Cogging, Spring

__all__ = [
    "Scales",
    "Effect",
    "Friction",
    "Coulomb",
    "Physical",
    "Damping",
    "DeadTime",
    "Saturation",
    "SensorLimit",
    "SensorOffset",
    "Backlash",
    "DeadZone",
    "Cogging",
    "Spring",
    "Overflow",
    "LinearTerm",
    "InputOffset",
    "BUILTIN_EFFECTS",
    "builtin_effects",
    "effect_library",
    "select_effects",
]


@dataclass(frozen=True)
class Scales:
    """Magnitudes seen on the training record: they set neutral curve shapes and scanned options.

    Attributes
    ----------
    rms : mapping str -> float
        Root mean square of chart signals (from a simulation of the current fit) and of the inputs.
    lo, hi : mapping str -> float
        Smallest and largest value of each input and of each chart signal (the current fit's simulation).
    """

    rms: Mapping[str, float] = field(default_factory=dict)
    lo: Mapping[str, float] = field(default_factory=dict)
    hi: Mapping[str, float] = field(default_factory=dict)

    def scale(self, signal: str) -> float:
        value = float(self.rms.get(signal, 1.0))
        return value if value > 0 else 1.0

    def span(self, signal: str) -> float:
        """The largest |value| of the signal (a learned curve's basis spans it); 3 RMS where unknown."""
        if signal in self.lo and signal in self.hi:
            value = max(abs(float(self.lo[signal])), abs(float(self.hi[signal])))
            if value > 0 and math.isfinite(value):
                return value
        return 3.0 * self.scale(signal)


@runtime_checkable
class Effect(Protocol):
    """A named candidate the chart may lack. ``repeatable``: once accepted at a place, its other options stay on
    offer there (cogging harmonics add up); effects that do not say so are not repeatable."""

    name: str
    neutral: bool
    extra_dof: int

    def places(self, diagram: Diagram) -> tuple[Place, ...]: ...

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple: ...

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram: ...

    def describe(self) -> str: ...

    def label(self, option) -> str: ...


_namer = namer  # fresh names for a patch's new blocks and parameters


# ------------------------------------------------------------------------------------------------ effects
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
        new = _namer(diagram)

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


@dataclass(frozen=True)
class DeadTime:
    """A dead time on an input: its `delay`, a new parameter tau in seconds started at n samples (n scanned
    over ``1..max_samples``) and fitted within half a sample of n (from 0 for n = 1): the scan decides the
    whole samples, the refit the fraction (network.inputsignal: the step means of the delayed input, exact in
    tau). Bounded so, the options stay apart: free, every refit went to the same tau and the option reported
    was whichever start happened to end lowest."""

    max_samples: int = 20
    name: str = "dead_time"
    neutral: bool = False
    extra_dof: int = 1  # n is estimated too (by the scan); tau is held at n samples while scored (screened)

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        delayed = {s.name for s in diagram.inputs if s.delay is not None}
        return tuple(p for p in input_places(diagram) if p.at not in delayed)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return tuple(range(1, self.max_samples + 1))

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        n = int(option) if option is not None else 1
        if n < 1:
            raise ValueError(f"dead_time needs n >= 1 samples, got {n}")
        pname = fresh_name(diagram, f"tau_{place.at}")
        T = diagram.sample_time
        p = Parameter(pname, n * T, unit="s", min=0.0 if n == 1 else (n - 0.5) * T, max=(n + 0.5) * T,
                      description=f"dead time of {place.at} (diagnose)")
        inputs = tuple(replace(s, delay=pname) if s.name == place.at else s for s in diagram.inputs)
        return add_blocks(replace(diagram, inputs=inputs), [], [p])

    def screened(self, diagram: Diagram) -> Diagram:
        """The patched chart as the score test sees it: tau held at its n samples (the scan ranks whole n)."""
        held = {s.delay for s in diagram.inputs if s.delay is not None}
        return replace(diagram, parameters=tuple(replace(p, fixed=True) if p.name in held and
                                                 p.description and "(diagnose)" in p.description else p
                                                 for p in diagram.parameters))

    def describe(self) -> str:
        return f"dead_time: a dead time on an input, n = 1..{self.max_samples} samples and the fraction fitted"

    def label(self, option) -> str:
        return f"n={int(option)}"


def _limits(fractions: Sequence[float], scales: Scales, signal: str, unseen: float) -> tuple:
    """Clip half-ranges to scan: `fractions` of the largest |value| of `signal` seen (``unseen`` where its range
    is not known); none where that is 0 (a clip of a signal that never moves changes nothing)."""
    top = max(abs(float(scales.lo.get(signal, -unseen))), abs(float(scales.hi.get(signal, unseen))))
    if not top > 0:
        return ()
    return tuple(round(f * top, 12) for f in fractions)


def _clip_blocks(new, signal: str, prefix: str, lim: str, off: str, unit: str | None,
                 description: str) -> tuple[Block, ...]:
    """``lim * sat((signal - off) / lim) + off``: constant, difference, clip, gain and the clipped signal last."""
    c, x, f, g = new(f"{prefix}_o"), new(f"{prefix}_x"), new(f"{prefix}_clip"), new(f"{prefix}_L")
    return (
        Block(c, "constant", k=parse_expr(off)),
        Block(x, "sum", (Term(signal), Term(c, -1))),
        Block(f, "function", (Term(x),), k=parse_expr(f"1/{lim}"), f="sat"),
        Block(g, "gain", (Term(f),), k=parse_expr(lim)),
        Block(new(prefix), "sum", (Term(g), Term(c)), unit=unit, description=description),
    )


@dataclass(frozen=True)
class Saturation:
    """A hard clip of an input at learned limits ``o - L .. o + L`` (``L * sat((u - o) / L) + o``).

    At a limit outside the data the clip does nothing and its score is 0, so L is scanned as fractions of
    the largest |input| seen, with the offset o starting at 0; the refit moves both.
    """

    fractions: tuple[float, ...] = (0.95, 0.9, 0.85, 0.8, 0.75, 0.7, 0.6, 0.5, 0.4)
    name: str = "saturation"
    neutral: bool = False
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return input_places(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return _limits(self.fractions, scales, place.at, 1.0)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        limit = float(option) if option is not None else 1.0
        u = place.at
        new = _namer(diagram)

        lim, off = new(f"{u}_lim"), new(f"{u}_off")
        unit = next((s.unit for s in diagram.inputs if s.name == u), None)
        params = [Parameter(lim, limit, unit=unit, min=0.0, description=f"saturation half-range of {u} (diagnose)"),
                  Parameter(off, 0.0, unit=unit, description=f"saturation centre of {u} (diagnose)")]
        blocks = _clip_blocks(new, u, f"sat_{u}", lim, off, unit, f"{u} after saturation (diagnose)")
        return reroute(add_blocks(diagram, blocks, params), u, blocks[-1].name, keep={blocks[1].name})

    def describe(self) -> str:
        return "saturation: a hard clip of an input at learned limits (scanned from the data's input range)"

    def label(self, option) -> str:
        return f"L={float(option):.4g}"


@dataclass(frozen=True)
class SensorLimit:
    """A measured output clipped at learned limits ``o - L .. o + L``: a sensor, an amplifier or a converter
    at the end of its range (issue 16). The chart's block keeps its dynamics under a new name and every block
    that read it reads the new name; the output's name is taken by the clip, so data columns stay mapped.

    L is scanned as fractions of the largest |value| of the current fit's simulation of the output (a clip
    beyond it changes nothing), o starts at 0; the refit moves both. An output started from the data
    (`init: data`) keeps that start: the hidden true state is `measured_by` the output, so it starts at the
    output's first measured sample (at the clip when the sensor read its limit there: the nearest start the
    reading allows, a bound of the true one; `--init-window` can move it only if the window leaves the clip).
    """

    fractions: tuple[float, ...] = (0.95, 0.9, 0.85, 0.8, 0.75, 0.7, 0.6, 0.5, 0.4)
    name: str = "sensor_limit"
    neutral: bool = False
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return output_places(diagram)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return _limits(self.fractions, scales, place.at, 0.0)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        limit = float(option) if option is not None else 1.0
        y = place.at
        new = _namer(diagram)
        inner = new(f"{y}_true")
        lim, off = new(f"{y}_lim"), new(f"{y}_off")
        unit = next((s.unit for s in diagram.outputs if s.name == y), None) or diagram.block(y).unit
        renamed = rename_block(diagram, y, inner)
        params = [Parameter(lim, limit, unit=unit, min=0.0, description=f"sensor half-range of {y} (diagnose)"),
                  Parameter(off, 0.0, unit=unit, description=f"sensor range centre of {y} (diagnose)")]
        clip = _clip_blocks(new, inner, f"sensor_{y}", lim, off, unit,
                            f"{y} as measured: clipped at the sensor's range (diagnose)")
        clip = clip[:-1] + (replace(clip[-1], name=y),)
        return add_blocks(renamed, clip, params)

    def describe(self) -> str:
        return "sensor_limit: a measured output clipped at learned limits (scanned from the output's range)"

    def label(self, option) -> str:
        return f"L={float(option):.4g}"


@dataclass(frozen=True)
class SensorOffset:
    """A measured output that the chart's physics reads as ``y + o``: the sensor reads the physical signal minus
    a zero offset o (a level sensor's zero, a tachometer's bias), o a new parameter starting at 0 (neutral).

    Offered at outputs that some block reads (an offset of a signal nothing reads is an output bias, which
    the chart can state with a constant). Measured on Cascaded Tanks: the Torricelli outflow of the lower tank
    reading the level sensor + 1.5 V lowers the test RMSE from 0.490 to 0.374 V (docs/diagnose.md).
    """

    name: str = "sensor_offset"
    neutral: bool = True
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        read = {t.signal for b in diagram.blocks for t in b.inputs}
        return tuple(Place(s.name, "output") for s in diagram.outputs if s.name in read)

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple:
        return (None,)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        y = place.at
        new = _namer(diagram)
        off, const, phys = new(f"{y}_off"), new(f"{y}_offc"), new(f"{y}_phys")
        unit = next((s.unit for s in diagram.outputs if s.name == y), None) or diagram.block(y).unit
        p = Parameter(off, 0.0, unit=unit, description=f"zero offset of the {y} sensor: physical = measured + this "
                      "(diagnose)")
        blocks = [Block(const, "constant", k=parse_expr(off), unit=unit),
                  Block(phys, "sum", (Term(y), Term(const)), unit=unit,
                        description=f"{y} as the physics sees it: measured + offset (diagnose)")]
        return reroute(add_blocks(diagram, blocks, [p]), y, phys, keep={phys})

    def describe(self) -> str:
        return "sensor_offset: the physics reads a measured output plus a learned zero offset"

    def label(self, option) -> str:
        return ""


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
        new = _namer(diagram)

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


# ------------------------------------------------------------------------------------------------ registry
BUILTIN_EFFECTS: dict[str, Effect] = {
    e.name: e for e in (Friction(), Damping(), DeadTime(), Saturation(), Backlash(), DeadZone(), Cogging(),
                        Spring(), Overflow(), SensorLimit(), SensorOffset(), InputOffset(), LinearTerm())
}


def builtin_effects() -> dict[str, Effect]:
    """A copy of the registry: name -> effect with its default options."""
    return dict(BUILTIN_EFFECTS)


def effect_library(dead_time_max: int | None = None, harmonics: Sequence[int] | None = None,
                   user: Mapping[str, Effect] | None = None) -> dict[str, Effect]:
    """The effects diagnose can choose from: the built-in ones with the scan options given, then the user's.

    Parameters
    ----------
    dead_time_max : int, optional
        dead_time scans n = 1..this many samples (default: DeadTime's).
    harmonics : sequence of int, optional
        The cogging harmonics p to try (default: Cogging's).
    user : mapping of str to Effect, optional
        User effects by name, e.g. from :func:`flowchart2sdnn.diagnose.usereffects.load_effects_file`.

    Returns
    -------
    dict of str to Effect
        Name -> effect, built-in ones first.

    Raises
    ------
    ValueError
        When a user effect has the name of a built-in effect.
    """
    library = builtin_effects()
    if dead_time_max is not None:
        library["dead_time"] = replace(library["dead_time"], max_samples=dead_time_max)
    if harmonics is not None:
        library["cogging"] = replace(library["cogging"], harmonics=tuple(harmonics))
    for name, effect in (user or {}).items():
        if name in library:
            raise ValueError(f"effect '{name}' has the name of a built-in effect")
        library[name] = effect
    return library


def select_effects(names: Sequence[str] | None, available: Mapping[str, Effect],
                   where: str = "--effects") -> tuple[Effect, ...]:
    """The effects named (all when `names` is None), in the order given; SdnnError for an unknown name."""
    if names is None:
        return tuple(available.values())
    out = []
    for n in names:
        n = n.strip()
        if not n:
            continue
        if n not in available:
            raise SdnnError.at("DIAG001", f"unknown effect {n!r}; known: {', '.join(available)}", where,
                               hint=did_you_mean(n, available))
        out.append(available[n])
    if not out:
        raise SdnnError.at("DIAG001", "no effect selected", where, hint=f"choose from {', '.join(available)}")
    return tuple(out)

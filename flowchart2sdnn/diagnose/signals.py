"""Effects on a chart's inputs and measured outputs: a dead time and a saturation on an input, a sensor's
range (a clip on an output) and its zero offset. The table of all effects is :mod:`.effects`'s."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from ..diagram.model import Block, Diagram, Parameter, Term
from ..expr import parse_expr
from .graph import Place, add_blocks, fresh_name, input_places, namer, output_places, rename_block, reroute

if TYPE_CHECKING:
    from .effects import Scales


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
        new = namer(diagram)

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
        new = namer(diagram)
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
        new = namer(diagram)
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

"""The overflow effect: an integrator's state held at a learned level (a tank that overflows, a position at an
end stop), the excess optionally routed into another integrator.

Built from existing blocks only, so the network, the continuous oracle and RTRL all run it: in front of the
integrator ``x`` a new sum takes its old integrand and subtracts an outflow

    q = K * relu(x - L)          (upper limit; a lower limit pushes back with K * relu(L - x))

``relu`` is exact from a clip, ``R (sat((z - R) / R) + 1)`` for ``z < 2 R`` (R = 10 times the state's range on
the training record, far beyond the one-step overshoot). K is not learned: ``K = 1 / h`` with h the network step (T / substeps), the stiffest
outflow explicit Euler takes without ringing: above L the next step lands on ``L + h * inflow``, so the clip
acts within one network step (a projection onto x <= L). The oracle integrates the same stiff term
continuously and holds x at ``L + inflow / K`` - the same level. (With ``substeps: auto``, given or by default,
the patch assumes N = 1, K = 1/T: a softer stop, still stable.)

The routed option adds ``g * q`` (g learned, in [0, 1], starting at 0) to the integrand of a downstream
integrator: one whose integrand takes with a plus sign a term x's integrand takes with a minus sign (the
upper tank's outflow ``q1`` is the lower tank's inflow). Routed flow needs no lower limit, so only the upper
limit is routed.

Layer: diagnose.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..diagram.model import Block, Diagram, Parameter, Term
from ..expr import parse_expr
from .graph import Place, add_blocks, add_terms, fresh_name, states

__all__ = ["Overflow", "Level", "integrators", "downstream"]


@dataclass(frozen=True)
class Level:
    """One option of :class:`Overflow`: the limit's side (+1 upper, -1 lower), its starting value, and the
    integrator the excess flows into (None: lost)."""

    side: int
    limit: float
    into: str | None = None
    span: float = 1.0  # the state's range on the training record: sets the clip's reach

    def __str__(self) -> str:
        return self.label()

    def label(self) -> str:
        text = ("max" if self.side > 0 else "min") + f"={self.limit:.4g}"
        return text + (f"->{self.into}" if self.into else "")


integrators = states  # every integrator: the places of an overflow


def _integrand_terms(diagram: Diagram, name: str) -> dict[str, int]:
    """The signals the integrand of `name` sums, with their signs (one level: a sum feeding it)."""
    b = diagram.block(name)
    if len(b.inputs) != 1:
        return {}
    src = next((s for s in diagram.blocks if s.name == b.inputs[0].signal), None)
    if src is None or src.kind != "sum":
        return {}
    return {t.signal: t.sign for t in src.inputs}


def downstream(diagram: Diagram, name: str) -> tuple[str, ...]:
    """Integrators whose integrand sum adds a term the integrand of `name` subtracts (a shared flow)."""
    out_flows = {s for s, sign in _integrand_terms(diagram, name).items() if sign < 0}
    if not out_flows:
        return ()
    return tuple(p.at for p in integrators(diagram) if p.at != name
                 and any(sign > 0 and s in out_flows for s, sign in _integrand_terms(diagram, p.at).items()))


@dataclass(frozen=True)
class Overflow:
    """A state held at a learned level: ``x' = f - K relu(x - L)`` (see the module's text); L scanned as
    fractions of the state's range on the training record, learned by the refit."""

    fractions: tuple[float, ...] = (0.98, 0.95, 0.9, 0.85, 0.8, 0.7)
    lower: bool = True  # also offer a lower limit (a position at the lower end stop)
    reach: float = 10.0
    name: str = "overflow"
    neutral: bool = False
    extra_dof: int = 0

    def places(self, diagram: Diagram) -> tuple[Place, ...]:
        return integrators(diagram)

    def options(self, diagram: Diagram, place: Place, scales) -> tuple:
        lo, hi = scales.lo.get(place.at), scales.hi.get(place.at)
        if lo is None or hi is None or not hi > lo:
            return ()
        span = hi - lo
        into = (None,) + downstream(diagram, place.at)
        out = [Level(1, round(lo + f * span, 12), t, span) for f in self.fractions for t in into]
        if self.lower:
            out += [Level(-1, round(hi - f * span, 12), None, span) for f in self.fractions]
        return tuple(out)

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram:
        opt = option if isinstance(option, Level) else Level(1, float(option or 0.0))
        x = place.at
        block = diagram.block(x)
        taken: set[str] = set()

        def new(base: str) -> str:
            n = fresh_name(diagram, base, taken)
            taken.add(n)
            return n

        substeps = diagram.substeps if isinstance(diagram.substeps, int) else 1
        k = substeps / diagram.sample_time  # 1/h: see the module's text
        reach = self.reach * (opt.span if opt.span > 0 else max(abs(opt.limit), 1.0))
        lim = new(f"{x}_{'max' if opt.side > 0 else 'min'}")
        c_lim, c_reach, z, clip, one, r, q, integrand = (
            new(f"{lim}_c"), new(f"ovf_{x}_R"), new(f"ovf_{x}_z"), new(f"ovf_{x}_clip"), new(f"ovf_{x}_one"),
            new(f"ovf_{x}_relu"), new(f"ovf_{x}"), new(f"{x}_in"))
        params = [Parameter(lim, opt.limit, unit=block.unit,
                            description=f"{'upper' if opt.side > 0 else 'lower'} limit of {x} (diagnose)")]
        away = (Term(x), Term(c_lim, -1)) if opt.side > 0 else (Term(c_lim), Term(x, -1))
        blocks = [
            Block(c_lim, "constant", k=parse_expr(lim), unit=block.unit),
            Block(c_reach, "constant", k=parse_expr(repr(reach)), unit=block.unit),
            Block(z, "sum", away + (Term(c_reach, -1),), unit=block.unit),
            Block(clip, "function", (Term(z),), k=parse_expr(repr(1.0 / reach)), f="sat"),
            Block(one, "constant", k=parse_expr("1")),
            Block(r, "sum", (Term(clip), Term(one))),
            Block(q, "gain", (Term(r),), k=parse_expr(repr(k * reach)),
                  description=f"flow that holds {x} at its limit (diagnose)"),
            Block(integrand, "sum", tuple(block.inputs) + (Term(q, -opt.side),),
                  description=f"integrand of {x} with the overflow (diagnose)"),
        ]
        terms: dict[str, tuple[Term, ...]] = {}
        if opt.into is not None and opt.side > 0:
            g, routed = new(f"ovf_{x}_to_{opt.into}"), new(f"ovf_{x}_in_{opt.into}")
            params.append(Parameter(g, 0.0, min=0.0, max=1.0,
                                    description=f"share of the overflow of {x} that reaches {opt.into} (diagnose)"))
            blocks.append(Block(routed, "gain", (Term(q),), k=parse_expr(g)))
            terms[diagram.block(opt.into).inputs[0].signal] = (Term(routed),)
        patched = add_blocks(diagram, blocks, params)
        patched = add_terms(patched, terms)
        return replace(patched, blocks=tuple(replace(b, inputs=(Term(integrand),)) if b.name == x else b
                                             for b in patched.blocks))

    def describe(self) -> str:
        return ("overflow: an integrator's state held at a learned upper (or lower) level, the excess lost or "
                "routed into a downstream integrator")

    def label(self, option) -> str:
        return option.label() if isinstance(option, Level) else ""

"""`init: estimate` on an integrator: its start becomes a fitted parameter (issue 14).

An unmeasured state whose start is unknown (a shaft twist, the speed of a record that starts in motion, a tank
level) is a quantity of the fit. An integrator's `init` may name a parameter (`init: x10`): the network's state
before the first sample is that parameter, with its exact RTRL sensitivity (network.runtime). `init: estimate`
is the short form: it adds the parameter ``<block>_0`` (unit of the block, start 0, `per_record: true`, so
every training record gets its own start) and points `init` at it. So lint, identify (intervals, per-record
values) and the identified chart need nothing new: the start is an ordinary parameter with its unit and
interval, and the identified chart writes ``init: <block>_0`` with the estimate as the parameter's value.
"""

from __future__ import annotations

from dataclasses import replace

from .model import RESERVED, Diagram, Parameter

__all__ = ["ESTIMATE", "expand_estimated_inits"]

#: the integrator `init` that asks for the start to be fitted
ESTIMATE = "estimate"


def expand_estimated_inits(diagram: Diagram) -> Diagram:
    """The chart with every ``init: estimate`` integrator started at a new parameter (unchanged when none)."""
    if not any(b.kind == "integrator" and b.init == ESTIMATE for b in diagram.blocks):
        return diagram
    used = set(diagram.block_names) | set(diagram.input_names) | set(diagram.parameter_names) | RESERVED
    blocks, parameters = [], list(diagram.parameters)
    for b in diagram.blocks:
        if b.kind == "integrator" and b.init == ESTIMATE:
            name, i = f"{b.name}_0", 2
            while name in used:
                name, i = f"{b.name}_0_{i}", i + 1
            used.add(name)
            parameters.append(Parameter(name, 0.0, unit=b.unit, per_record=True, location=b.location,
                                        description=f"initial value of {b.name} (init: estimate)"))
            b = replace(b, init=name)
        blocks.append(b)
    return replace(diagram, blocks=tuple(blocks), parameters=tuple(parameters))

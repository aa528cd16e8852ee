"""Bounds without a transform: LM steps in the physical coordinates, kept strictly inside the box.

:mod:`.transforms` maps a one-sided bound through ``x = min - 1 + sqrt(u**2 + 1)``; a quantity a fraction of a
unit above its bound (a viscous coefficient of 0.024 N·m·s/rad) lives near ``x = u**2 / 2``, where a straight
step in u is a curved one in x and plain LM steps crawl (docs/rough_init.md, "Speed"). Bounded trust-region
methods (Coleman & Li 1996; scipy's ``trf``) step in x itself and keep every iterate strictly feasible instead.
This module does that for the damped LM step, as an active set within one step:

1. the damped step ``dx`` is solved as usual (in the column-scaled coordinates the trainer uses);
2. every free component that would cover more than ``theta`` of its room to the bound it moves towards is held
   at ``theta`` of that room (``theta = 0.995``: the quantity moves 99.5 % of the way, never onto the bound);
3. the damped system is solved again for the other components with the held ones moved to the right-hand side
   (the model's best step given them, so a held quantity does not spoil its partners' steps); repeat until no
   free component crosses (at most P solves).

A quantity whose minimum lies on its bound thus closes 99.5 % of its distance per iteration (geometrically, not
the transform's crawl along ``u**2 / 2``) while the others move as if it were fixed. The trainer's acceptance
test still decides: a refused step raises the damping as any other.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .. import rules

__all__ = ["BOX_THETA", "feasible_step"]

#: The fraction of its room to a bound a quantity may cover in one step (scipy's trf uses at least 0.995 too).
BOX_THETA = rules.value("box_theta")


def feasible_step(x: np.ndarray, dx: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                  resolve: Callable[[np.ndarray, np.ndarray], np.ndarray], theta: float = BOX_THETA) -> np.ndarray:
    """The step ``dx`` (P,) from ``x`` (P,) with every component inside ``theta`` of its room to ``lower`` /
    ``upper`` (P,; +-inf for none), re-solved around the held components.

    ``resolve(held, value)`` returns the damped step with ``dx[held] = value[held]`` imposed and the other
    components solved for (``held`` a boolean mask (P,)). A component starting on its bound and pushed outwards
    is held at 0.
    """
    room_up = upper - x
    room_down = x - lower
    held = np.zeros(x.size, dtype=bool)
    value = np.zeros(x.size)
    for _ in range(x.size):
        with np.errstate(invalid="ignore"):
            over_up = ~held & (dx > theta * room_up)
            over_down = ~held & (dx < -theta * room_down)
        crossing = over_up | over_down
        if not crossing.any():
            return dx
        value[over_up] = theta * room_up[over_up]
        value[over_down] = -theta * room_down[over_down]
        held |= crossing
        if held.all():
            return value.copy()
        dx = np.array(resolve(held, value), dtype=float)
        dx[held] = value[held]
    return dx

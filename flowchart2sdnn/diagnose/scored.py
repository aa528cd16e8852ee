"""What the score test (:mod:`.score`) works on and returns: a candidate (an effect at a place with one option),
the baseline of the current fit, a candidate's score and a screen of them all, with their REPORT.json form."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

from ..diagram.model import Diagram
from ..strictjson import finite_or_none
from .effects import Effect
from .graph import Place

__all__ = ["Candidate", "Baseline", "Score", "Screen"]


@dataclass(frozen=True, eq=False)
class Candidate:
    """One effect at one place with one option, patched into `base` (its new quantities neutral)."""

    effect: Effect
    place: Place
    option: object
    base: Diagram

    @property
    def name(self) -> str:
        return self.effect.name

    @property
    def at(self) -> str:
        return self.place.at

    @property
    def key(self) -> tuple[str, str]:
        return (self.effect.name, self.place.at)

    @property
    def label(self) -> str:
        return self.effect.label(self.option)

    @property
    def neutral(self) -> bool:
        return bool(self.effect.neutral)

    @functools.cached_property
    def diagram(self) -> Diagram:
        return self.effect.patch(self.base, self.place, self.option)

    def title(self) -> str:
        return f"{self.name} at {self.at}" + (f" ({self.label})" if self.label else "")


@dataclass(frozen=True)
class Baseline:
    """The current chart at the current fit on the training record."""

    cost: float
    gn_decrease: float
    rank: int
    n_residuals: int
    n_theta: int
    sigma2: float
    # the residual's layout and the residual after the current chart's full Gauss-Newton step, from which the
    # significance reads the noise (diagnose.noise); None: the white-noise statistic
    layout: object = None
    e_hat: object = None
    names: tuple[str, ...] = ()

    @property
    def gn_cost(self) -> float:
        return self.cost - self.gn_decrease


@dataclass(frozen=True, eq=False)
class Score:
    """The score of one candidate; ``score`` and costs in cost units (E = 1/2 sum e^2).

    ``predicted_cost`` is None for an option that was only simulated (not among the best of its scan).
    """

    candidate: Candidate
    score: float
    cost: float
    predicted_cost: float | None
    dof: int = 0
    statistic: float = math.nan
    p_value: float = math.nan
    error: str | None = None
    # the full Gauss-Newton step the score stands for, (theta name, change) over the patched chart's quantities
    # (the current ones and the candidate's): where the one-step point validates (choice.one_step_relevant)
    step: tuple = ()

    @property
    def scored(self) -> bool:
        return self.error is None and self.predicted_cost is not None and math.isfinite(self.score)

    def as_dict(self) -> dict:
        c = self.candidate
        return {"effect": c.name, "at": c.at, "option": _jsonable(c.option), "label": c.label,
                "score": finite_or_none(self.score) if self.scored else None,
                "predicted_cost": finite_or_none(self.predicted_cost), "cost_patched": finite_or_none(self.cost),
                "dof": self.dof, "statistic": finite_or_none(self.statistic), "p_value": finite_or_none(self.p_value),
                "error": self.error}


@dataclass(frozen=True, eq=False)
class Screen:
    """All scores of one round, ranked (scored candidates first, best first)."""

    baseline: Baseline
    scores: tuple[Score, ...]
    seconds: float = 0.0
    passes: dict = field(default_factory=dict)

    def best_per_place(self) -> list[Score]:
        """The best scored option of every (effect, place), ranked."""
        seen, out = set(), []
        for s in self.scores:
            if s.scored and s.candidate.key not in seen:
                seen.add(s.candidate.key)
                out.append(s)
        return out


def _jsonable(option):
    if option is None or isinstance(option, (bool, int, str)):
        return option
    if isinstance(option, float):
        return finite_or_none(option)
    return str(option)

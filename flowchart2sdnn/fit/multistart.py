"""Several fits from different start values: seeded draws, the best run, and which runs got stuck.

The paper (Table 2) shows why: two initialisations of the same model reach different damping values,
and the higher final cost of one of them reveals a local minimum.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .. import rules
from .lm import LMResult
from .transforms import Bounds

__all__ = ["draw_starts", "run_multistart", "MultiStartResult", "QuantitySpread", "NEAR_BEST", "LOCAL_FACTOR"]

#: Runs with cost <= NEAR_BEST * best cost count as "at the best minimum".
NEAR_BEST = rules.value("near_best")
#: Runs with cost > LOCAL_FACTOR * best cost are flagged as local minima.
LOCAL_FACTOR = rules.value("local_factor")
# Costs below this fraction of the largest start cost are all "zero" (an exact fit), never local minima.
_ZERO_COST = rules.value("zero_cost")


def draw_starts(
    names: Sequence[str],
    x0: Sequence[float] | np.ndarray,
    lower: Sequence[float] | np.ndarray | float | None,
    upper: Sequence[float] | np.ndarray | float | None,
    n: int,
    seed: int,
    ranges: Mapping[str, tuple[float, float]] | None = None,
) -> np.ndarray:
    """Start values for a multistart fit, reproducible from ``seed``.

    Row 0 is ``x0``.  Each other value is drawn per quantity from one ``numpy.random.default_rng(seed)``
    stream of uniform numbers (one (n-1, P) block, so adding a range for one quantity leaves the draws of
    the others unchanged), mapped as follows:

    1. ``ranges[name] = (lo, hi)`` given: uniform on [lo, hi] (must lie within the bounds);
    2. else both bounds finite: uniform on [min, max];
    3. else ``x0 != 0``: log-uniform on [|x0|/10, 10 |x0|] with the sign of x0, cut to the bounds
       (a one-sided bound such as ``min: 0`` keeps the positive decade range);
    4. else (``x0 == 0``, at most one bound): uniform on [-1, 1] cut to the bounds.

    Parameters
    ----------
    names : sequence of str (P,)
    x0 : array_like (P,)
    lower, upper : array_like (P,), scalar or None
    n : int
        Number of starts (>= 1), including ``x0``.
    seed : int
    ranges : mapping name -> (lo, hi), optional

    Returns
    -------
    ndarray (n, P)
    """
    names = tuple(str(s) for s in names)
    x0 = np.array(x0, dtype=float).reshape(-1)
    if x0.size != len(names):
        raise ValueError(f"`x0` has {x0.size} entries, `names` has {len(names)}")
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"`n` must be an int >= 1, got {n!r}")
    bounds = Bounds.make(names, lower, upper)
    bounds.check(x0)
    ranges = dict(ranges or {})
    unknown = sorted(set(ranges) - set(names))
    if unknown:
        raise ValueError(f"`ranges` names unknown quantities: {', '.join(unknown)}")

    rng = np.random.default_rng(seed)
    q = rng.random((n - 1, len(names)))
    out = np.empty((n, len(names)))
    out[0] = x0
    for i, name in enumerate(names):
        lo_b, hi_b = bounds.lower[i], bounds.upper[i]
        if name in ranges:
            lo, hi = (float(v) for v in ranges[name])
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"`ranges['{name}']` = ({lo}, {hi}) must be finite with lo < hi")
            if lo < lo_b or hi > hi_b:
                raise ValueError(
                    f"`ranges['{name}']` = ({lo:g}, {hi:g}) leaves the bounds [{lo_b:g}, {hi_b:g}]"
                )
            col = lo + (hi - lo) * q[:, i]
        elif np.isfinite(lo_b) and np.isfinite(hi_b):
            col = lo_b + (hi_b - lo_b) * q[:, i]
        elif x0[i] != 0:
            sign, mag = np.sign(x0[i]), abs(x0[i])
            # the decade range in |x|, cut to what the bounds allow for this sign
            a, b = (lo_b, hi_b) if sign > 0 else (-hi_b, -lo_b)
            lo_m, hi_m = max(mag / 10, a), min(mag * 10, b)  # 0 < lo_m <= mag <= hi_m as x0 is inside
            col = sign * np.exp(np.log(lo_m) + (np.log(hi_m) - np.log(lo_m)) * q[:, i])
        else:
            lo, hi = max(-1.0, lo_b), min(1.0, hi_b)
            col = lo + (hi - lo) * q[:, i]
        out[1:, i] = np.clip(col, lo_b, hi_b)
    return out


@dataclass(frozen=True)
class QuantitySpread:
    """Range of one quantity among runs at the best minimum and among the others (None when no run)."""

    name: str
    near_best_min: float
    near_best_max: float
    others_min: float | None
    others_max: float | None

    @property
    def near_best_spread(self) -> float:
        """(max - min) / max(|min|, |max|) among the runs at the best minimum; 0 when they agree."""
        scale = max(abs(self.near_best_min), abs(self.near_best_max))
        return (self.near_best_max - self.near_best_min) / scale if scale > 0 else 0.0


@dataclass(frozen=True, eq=False)
class MultiStartResult:
    """Outcome of :func:`run_multistart`; runs are in start order whatever the executor did.

    Attributes
    ----------
    results : tuple of LMResult       one per start actually run
    starts : ndarray (n_run, P)       the start values of those runs
    costs : ndarray (n_run,)          final costs (inf for a run that diverged at its start)
    best_index : int                  lowest cost (first such run on a tie)
    near_best : tuple of int          runs with cost <= NEAR_BEST * best
    local_minima : tuple of int       runs with cost > LOCAL_FACTOR * best
    diverged : tuple of int           runs whose model diverged at the start
    spread : tuple of QuantitySpread  per quantity
    interrupted : bool                a run was interrupted (KeyboardInterrupt) or the callback stopped
    message : str                     human-readable summary naming the local minima
    """

    results: tuple[LMResult, ...]
    starts: np.ndarray
    costs: np.ndarray
    best_index: int
    near_best: tuple[int, ...]
    local_minima: tuple[int, ...]
    diverged: tuple[int, ...]
    spread: tuple[QuantitySpread, ...]
    interrupted: bool
    message: str

    @property
    def best(self) -> LMResult:
        return self.results[self.best_index]

    def summary(self) -> dict:
        """JSON-ready summary (the ``multistart`` entry of RESULT.json)."""
        return {
            "n": len(self.results),
            "best_index": self.best_index,
            "costs": [float(c) if math.isfinite(c) else None for c in self.costs],
            "near_best": list(self.near_best),
            "local_minima": list(self.local_minima),
            "diverged": list(self.diverged),
            "starts": [[float(v) for v in row] for row in self.starts],
            "message": self.message,
        }


def run_multistart(
    fit_one: Callable[[np.ndarray], LMResult],
    starts: np.ndarray,
    callback: Callable[[int, LMResult], bool | None] | None = None,
    executor=None,
) -> MultiStartResult:
    """Run ``fit_one`` from every row of ``starts`` and compare the minima reached.

    Parameters
    ----------
    fit_one : callable ``fit_one(x0) -> LMResult``
    starts : ndarray (n, P)
        For example from :func:`draw_starts`.
    callback : callable ``callback(index, result) -> bool | None``, optional
        Called after each run in start order; True stops (with an executor, runs already submitted
        may still execute but are ignored).
    executor : object with ``.map(fn, iterable)``, optional
        E.g. a ``concurrent.futures`` executor; results are consumed in start order.  Serial when None.

    Returns
    -------
    MultiStartResult
    """
    starts = np.array(starts, dtype=float)
    if starts.ndim != 2 or starts.shape[0] == 0:
        raise ValueError(f"`starts` must have shape (n, P) with n >= 1, got {starts.shape}")
    rows = [starts[k].copy() for k in range(starts.shape[0])]
    results_iter = map(fit_one, rows) if executor is None else executor.map(fit_one, rows)
    results: list[LMResult] = []
    stopped = False
    try:
        for k, res in enumerate(results_iter):
            results.append(res)
            if res.interrupted or (callback is not None and callback(k, res)):
                stopped = True
                break
    except KeyboardInterrupt:
        stopped = True
    if not results:
        raise KeyboardInterrupt
    return _summarise(results, starts[: len(results)], stopped)


def _summarise(results: list[LMResult], starts: np.ndarray, stopped: bool) -> MultiStartResult:
    costs = np.array([r.cost for r in results], dtype=float)
    best = int(np.argmin(costs))  # first minimum: deterministic on ties
    best_cost = costs[best]
    diverged = tuple(k for k, r in enumerate(results) if r.status == "diverged_at_start")
    finite = [k for k in range(len(results)) if math.isfinite(costs[k])]
    start_costs = [r.cost_history[0] for r in results if r.cost_history]
    zero = _ZERO_COST * max(start_costs, default=0.0)
    floor = max(best_cost, zero)
    near = tuple(k for k in finite if costs[k] <= NEAR_BEST * floor)
    local = tuple(k for k in finite if costs[k] > LOCAL_FACTOR * floor)

    names = results[best].names or tuple(f"p{i}" for i in range(starts.shape[1]))
    xs = np.array([r.x for r in results])
    others = [k for k in finite if k not in near]
    spread = tuple(
        QuantitySpread(
            name=name,
            near_best_min=float(xs[list(near), i].min()) if near else float("nan"),
            near_best_max=float(xs[list(near), i].max()) if near else float("nan"),
            others_min=float(xs[others, i].min()) if others else None,
            others_max=float(xs[others, i].max()) if others else None,
        )
        for i, name in enumerate(names)
    )

    parts = [f"best of {len(results)} runs: run {best} with cost {best_cost:.6g}"]
    if len(near) > 1:
        parts.append(f"{len(near)} runs within {100 * (NEAR_BEST - 1):.0f} % of it")
    if local:
        detail = ", ".join(f"{k} ({costs[k] / best_cost:.3g}x)" if best_cost > 0 else f"{k}" for k in local)
        parts.append(f"local minima (cost > {LOCAL_FACTOR:g}x the best): runs {detail}")
    if diverged:
        parts.append(f"diverged at the start: runs {', '.join(str(k) for k in diverged)}")
    if stopped:
        parts.append("stopped early")
    return MultiStartResult(
        results=tuple(results),
        starts=starts,
        costs=costs,
        best_index=best,
        near_best=near,
        local_minima=local,
        diverged=diverged,
        spread=spread,
        interrupted=stopped,
        message="; ".join(parts),
    )

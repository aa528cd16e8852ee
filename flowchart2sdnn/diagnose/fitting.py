"""A chart fitted for diagnosis: the settings, the :class:`Fitted` record (training cost, validation error,
information criteria) and fits with a growing horizon. What a fit says about itself, its residual analysis
among it, is :mod:`.fitstate`'s, re-exported here.

Layer: diagnose (below it: identify and everything under it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .. import rules
from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..identify import (
    REFIT_TAU,
    Identification,
    IdentifySettings,
    build_problem,
    data_init,
    estimate_initial_state,
    identify,
    measure_floor,
    metrics,
    pooled_floor,
)
from .fitstate import (
    current_problem,
    effect_scales,
    far_above_noise,
    residual_analysis,
    still_moving,
    unpredictable,
)

__all__ = ["DiagnoseSettings", "Fitted", "fit_chart", "with_floor", "fit_growing", "horizons", "current_problem",
           "effect_scales", "residual_analysis", "DEFAULT_SPLIT", "VALIDATION_SEGMENTS", "gain_spread", "unpredictable",
           "far_above_noise", "still_moving", "one_step_point", "one_step_line"]

DEFAULT_SPLIT = rules.value("default_split")
#: The validation records are cut into about this many consecutive parts in all (at least 2 per record): the
#: spread of the validation error's fall from part to part is what a candidate's gain is weighed against
#: (loop.refusal). 10 parts of a 15 s record are 1.5 s each, 15 periods of the slowest shaft mode of the benches.
VALIDATION_SEGMENTS = rules.value("validation_segments")

Progress = Callable[[str, "float | None"], None]


@dataclass(frozen=True)
class DiagnoseSettings:
    """Options of :func:`diagnose` (the CLI's flags)."""

    rounds: int = rules.value("rounds")
    top: int = rules.value("top")
    top_options: int = rules.value("top_options")
    runners_up: int = rules.value("runners_up")
    refit_iter: int = rules.value("refit_iter")
    # a safety limit, as identify's: with geodesic LM a complete chart's first fit stops on convergence (physical
    # two-mass charts 24-50 iterations, the learned two-mass chart 490 at noise 0.003, seed 1:
    # bench_false_alarms.py); at 100 the learned charts' first fits stopped unconverged and were not traced
    max_iter: int = rules.value("fit_max_iter")
    alpha: float = rules.value("alpha")
    criterion: str = "bic"
    min_gain: float = rules.value("min_gain")
    alignment: str = "zoh"
    seed: int = 0
    split: float | None = None
    # the refit from the chart as given of a candidate that is not neutral (a scanned gap, clip or delay), and of
    # a neutral one whose plain refit is unpredictable (see unpredictable), is done twice, the second time with a
    # growing horizon: first on the leading `horizon` samples of each
    # training record, then on 4x longer leading parts, each stage from the last one's fit, up to the whole
    # records (0: off). A drive with backlash is chaotic: from the chart as given a fit of the gap over whole
    # 3 s records stops in a local minimum (backlash bench: validation RMS 0.127, d +5.6 %); 500 samples are
    # shorter than the time the trajectories take to diverge, and from there the longer stages stay in the
    # right basin (0.0595, every linear parameter within 1 %). In addition to the plain refit, not instead: a
    # learned friction curve bent on the first 0.5 s of a 30 s record ends worse (friction bench: validation
    # RMS 0.079 against 0.056)
    horizon: int = rules.value("horizon")
    lm_tau: float = REFIT_TAU  # see identify.settings: the brief refits start next to a fit
    # an effect's validation MSE gain must exceed floor² + spread_z x the standard error of the gain, read off its
    # spread over the parts of the validation records (loop.refusal, gain_spread); 0: no spread test
    spread_z: float = rules.value("spread_z")
    # judge each round's candidates also against the current chart refitted as briefly without any effect
    # (loop._control): False only to measure what that control prevents
    control_refit: bool = True
    # near the noise, refit only the significant neutral candidates whose one Gauss-Newton step lowers the
    # validation RMS by min_gain (choice.one_step_relevant): False only to measure what that saves and changes
    one_step: bool = True
    # trace only from a converged first fit (False: --allow-unconverged, trace anyway)
    require_converged: bool = True
    # > 0: each validation record's initial state is fitted on its first init_window samples (identify.offline.initstate)
    # and the record is scored from there (the public benchmarks' protocol)
    init_window: int = 0
    # multiple shooting (identify.shooting.multiple) for the full fits (the chart as given, a finished control or
    # candidate: max_iter iterations); the brief refits start next to a fit and stay single shooting
    shooting: str | int = "off"
    # when no refit of the `top` places comes within SECOND_LOOK x the noise (the chart still misses most of what
    # the records hold), the next `top` significant places are refitted too before the round decides (False: off)
    second_look: bool = True
    # the final fit's discretization-bias analysis (identify.assess.floorbias, identify's default; the fits while tracing
    # skip it): REPORT.json's `final` then widens ci95 by the shift the network's step error causes. Without it
    # the three-mass backlash bench's final b1, b2 read +12 %, -21 % with noise-only intervals excluding the truth
    # (seed 2; the shift alone +7.6 %, -16 %: docs/diagnose.md)
    final_bias: bool = True

    def __post_init__(self) -> None:
        if self.rounds < 0:
            raise ValueError("rounds must not be negative")
        if self.top < 1 or self.top_options < 1:
            raise ValueError("top and top_options must be at least 1")
        if self.refit_iter < 1 or self.max_iter < 0:
            raise ValueError("refit_iter must be >= 1 and max_iter >= 0")
        if not 0 < self.alpha < 1:
            raise ValueError("alpha must lie strictly between 0 and 1")
        if self.criterion not in ("aic", "bic"):
            raise ValueError("criterion must be 'aic' or 'bic'")
        if not 0 <= self.min_gain < 1:
            raise ValueError("min_gain must lie in [0, 1)")
        if not (self.spread_z >= 0 and math.isfinite(self.spread_z)):
            raise ValueError("spread_z must be a finite number >= 0")
        if self.horizon < 0:
            raise ValueError("horizon must not be negative")
        if self.split is not None and not 0 < self.split < 1:
            raise ValueError("split must lie strictly between 0 and 1")
        if not (isinstance(self.init_window, int) and self.init_window >= 0):
            raise ValueError(f"init_window must be a whole number >= 0, got {self.init_window!r}")
        if not (self.shooting in ("off", "auto") or (isinstance(self.shooting, int) and not isinstance(self.shooting, bool)
                                           and self.shooting >= 2)):
            raise ValueError(f"shooting must be 'off', 'auto' or a segment length of at least 2 samples, got {self.shooting!r}")
        if self.init_window and self.split is not None:
            raise ValueError("init_window applies to separate validation records, not to a split")


@dataclass(frozen=True, eq=False)
class Fitted:
    """A chart fitted on the training record, with its validation error and information criteria."""

    identification: Identification
    cost: float
    n: int
    k: int
    validation: dict
    start: str = "chart"
    accepted: tuple = ()
    # the discretization floor on the validation records (identify.assess.floor, pooled over outputs as validation_rms):
    # measured for the fits a candidate is compared against (see with_floor), None elsewhere or where skipped
    validation_floor: float | None = None

    @property
    def diagram(self) -> Diagram:
        return self.identification.diagram

    @property
    def rms(self) -> float:
        return math.sqrt(2 * self.cost / self.n) if self.n and math.isfinite(self.cost) else math.inf

    @property
    def validation_rms(self) -> float:
        return self.validation["rms_all"]

    @property
    def validation_median(self) -> float:
        """The RMS (all outputs) of the median validation record: what a typical record shows."""
        each = self.validation.get("rms_records", [])
        return float(np.median(each)) if each else math.nan

    @property
    def validation_segments(self) -> np.ndarray:
        """(parts, 2): rows and squared error (every output) of each part of every validation record, in order."""
        parts = [seg for m in self.validation.get("records", []) for seg in m.get("segments", [])]
        return np.array([[r, math.inf if s is None else s] for r, s in parts], dtype=float).reshape(-1, 2)

    def criterion(self, which: str) -> float:
        if not (self.cost > 0 and math.isfinite(self.cost)):
            return -math.inf if self.cost == 0 else math.inf
        fit = self.n * math.log(2 * self.cost / self.n)
        return fit + (2 * self.k if which == "aic" else self.k * math.log(self.n))

    @property
    def aic(self) -> float:
        return self.criterion("aic")

    @property
    def bic(self) -> float:
        return self.criterion("bic")


def _rms_all(ms: Sequence[dict], n_out: int) -> float:
    sse = cnt = 0.0
    for m in ms:
        if m["cost"] is None:
            return math.inf
        sse += 2 * m["cost"]
        cnt += m["rows"] * n_out
    return math.sqrt(sse / cnt) if cnt else math.nan


def _validate(ident: Identification, records: Sequence[tuple[Dataset, int]], alignment: str,
              init_window: int = 0) -> dict:
    """Free-run metrics on each validation record from its first scored row; with `init_window` each record
    starts from the integrators' state fitted on its first `init_window` rows (parameters fixed) and is scored
    from the later of that row and the record's own first row."""
    return _validate_at(ident.problem.compiled, ident.x, records, alignment, init_window)


def _validate_at(compiled, x: np.ndarray, records: Sequence[tuple[Dataset, int]], alignment: str,
                 init_window: int = 0) -> dict:
    parts = max(2, math.ceil(VALIDATION_SEGMENTS / max(len(records), 1)))
    per = []
    for ds, start in records:
        if init_window:
            state = estimate_initial_state(compiled, x, ds, alignment, init_window, data_init(compiled.net, ds))
            m = metrics(compiled, x, ds, alignment, score_from=max(start, init_window), history=state.history,
                        segments=parts)
            m["initial_state"] = state.to_dict()
        else:
            m = metrics(compiled, x, ds, alignment, score_from=start, segments=parts)
        per.append(m)
    return {"rms_all": _rms_all(per, compiled.n_outputs), "records": per,
            "rms_records": [_rms_all([m], compiled.n_outputs) for m in per]}


def one_step_line(diagram: Diagram, step: Sequence[tuple[str, float]], train: list[Dataset], records,
                  settings: DiagnoseSettings):
    """``(cost, validation)`` along a score's Gauss-Newton `step` ((theta name, change) pairs,
    :class:`~.scored.Score`) from `diagram`'s values, held inside the bounds: ``cost(t)`` the training cost and
    ``validation(t)`` the validation RMS (every output, as :attr:`Fitted.validation_rms`) at t x the step,
    simulated, not linearised (inf where the run diverges); None where the chart does not build."""
    try:
        problem = build_problem(diagram, train[0], settings.alignment, settings.seed, more=tuple(train[1:]))
    except (SdnnError, ValueError, KeyError):
        return None
    x0 = problem.compiled.theta0().copy()
    direction = np.zeros_like(x0)
    index = {n: i for i, n in enumerate(problem.names)}
    for name, change in step:
        if name in index:
            direction[index[name]] += change
    lower, upper = problem.bounds()

    def cost(t: float) -> float:
        e = problem.residual(np.clip(x0 + t * direction, lower, upper))
        return math.inf if e is None else 0.5 * float(e @ e)

    def validation(t: float) -> float:
        return _validate_at(problem.compiled, np.clip(x0 + t * direction, lower, upper), records, settings.alignment,
                            settings.init_window)["rms_all"]

    return cost, validation


def one_step_point(diagram: Diagram, step: Sequence[tuple[str, float]], train: list[Dataset], records,
                   settings: DiagnoseSettings) -> tuple[float, float]:
    """(training cost, validation RMS) at the whole step (:func:`one_step_line` at t = 1); inf where the chart
    does not build."""
    line = one_step_line(diagram, step, train, records, settings)
    return (math.inf, math.inf) if line is None else (line[0](1.0), line[1](1.0))


def fit_chart(diagram: Diagram, train: list[Dataset], records, settings: DiagnoseSettings, max_iter: int,
              extra_dof: int, start: str, progress: Progress | None = None, accepted: tuple = (),
              target: float = math.inf) -> Fitted:
    """Fit `diagram` on the training records and score it on the validation `records` ((Dataset, first row)).
    A finite `target` cuts the fit off once it can no longer reach that training cost (:func:`behind`)."""
    cutoff = behind(target, max_iter) if math.isfinite(target) else None
    return _fitted(_identify(diagram, train, settings, max_iter, progress, cutoff), records, settings, extra_dof,
                   start, accepted)


#: a brief refit is cut off (:func:`behind`) only after this many iterations: its pace is the mean fall of the
#: last CUTOFF_PACE iterations
CUTOFF_PACE = rules.value("cutoff_pace")


def behind(target: float, max_iter: int):
    """``cutoff(iteration, cost)`` for identify: a reason once the cost, falling at the pace of its last
    CUTOFF_PACE iterations for every iteration left, would still end above `target` (the lowest training cost a
    refit of the round reached).

    Why this bound: Levenberg-Marquardt's gains shrink as a fit nears its minimum, so the recent pace carried over
    the whole remaining budget over-estimates what is left; a refit that cannot reach the round's best even so
    cannot take first place on training cost, and its validation RMS is still measured where it stopped."""
    costs: list[float] = []

    def cutoff(it: int, cost: float) -> str | None:
        costs.append(cost)
        if len(costs) <= CUTOFF_PACE:
            return None
        pace = max(costs[-1 - CUTOFF_PACE] - cost, 0.0) / CUTOFF_PACE
        reach = cost - pace * max(max_iter - it, 0)
        if reach > target:
            return (f"at iteration {it} the cost {cost:.6g} falls {pace:.3g} an iteration; over the {max_iter - it} "
                    f"left it cannot reach {target:.6g}, the cost to beat (the round's best refit, or the current fit's)")
        return None
    return cutoff


def _identify(diagram: Diagram, train: list[Dataset], settings: DiagnoseSettings, max_iter: int,
              progress: Progress | None = None, cutoff=None) -> Identification:
    # floor_bias off: diagnose compares costs and validation RMS, never the intervals, over many refits; the
    # floor on the training records only for the full fits (a brief refit's is never read, and the oracle's run of
    # a 30 s record took 9 % of a two-mass diagnose: bench_diagnose_time.py, seed 11, py-spy)
    full = max_iter >= settings.max_iter
    # trainlm's damping and the bound transform: diagnose's decisions were measured with them (identify.settings.
    # LM_DAMPING, LM_BOUNDS); with the box's trust radius a chaotic drive's neutral cogging refit stayed at 10x the
    # noise (tests/test_diagnose_chaotic_refit.py), with Nielsen's damping the tanks bench credited a saturation
    # before the overflow (tests/test_diagnose_overflow.py). Which optimiser a decision needs is a symptom the
    # decision rule itself must remove; until then the measured one stays.
    s = IdentifySettings(max_iter=max_iter, seed=settings.seed, alignment=settings.alignment, lm_tau=settings.lm_tau,
                         floor_bias=False, floor=full, shooting=settings.shooting if full else "off",
                         lm_damping="trainlm", lm_bounds="transform")
    return identify(diagram, train if len(train) > 1 else train[0], None, s, progress, cutoff=cutoff)


def _fitted(ident: Identification, records, settings: DiagnoseSettings, extra_dof: int, start: str,
            accepted: tuple) -> Fitted:
    cost = ident.fit.train.cost
    cost = math.inf if cost is None else float(cost)
    return Fitted(ident, cost, ident.problem.n_residuals, len(ident.problem.names) + extra_dof,
                  _validate(ident, records, settings.alignment, settings.init_window), start, accepted)


def gain_spread(after: Fitted, before: Fitted) -> float | None:
    """The standard error of the validation MSE's fall from `before` to `after`, from its spread over the parts
    of the validation records (:data:`VALIDATION_SEGMENTS`): the fall of each part, paired (the same
    rows), sd / sqrt(parts). None with fewer than 3 parts or where a part is not finite."""
    b, a = before.validation_segments, after.validation_segments
    if len(b) < 3 or b.shape != a.shape or not (np.all(np.isfinite(b)) and np.all(np.isfinite(a))):
        return None
    n_out = max(len(before.validation["records"][0]["rms"]), 1)
    fall = (b[:, 1] - a[:, 1]) / (b[:, 0] * n_out)
    return float(np.std(fall, ddof=1) / math.sqrt(len(fall)))


def with_floor(fitted: Fitted, records, settings: DiagnoseSettings) -> Fitted:
    """`fitted` with its discretization floor on the validation `records` ((Dataset, first row)): the RMS
    difference between its network and its chart simulated continuously (the oracle), what no effect can be
    credited with removing (see loop.refusal)."""
    ident = fitted.identification
    if ident.chart is None or ident.problem is None or not math.isfinite(fitted.validation_rms):
        return fitted
    floor = measure_floor(ident.chart, ident.problem.compiled, ident.x, records, settings.alignment)
    return replace(fitted, validation_floor=pooled_floor(floor))


def horizons(train: Sequence[Dataset], first: int) -> list[int]:
    """The leading lengths (samples) of the growing-horizon stages before the fit on the whole records."""
    longest = max(d.n_rows for d in train)
    out, h = [], first
    while 0 < h < longest:
        out.append(h)
        h *= 4
    return out


def fit_growing(diagram: Diagram, train: list[Dataset], records, settings: DiagnoseSettings, max_iter: int,
                 extra_dof: int, start: str, accepted: tuple = (), target: float = math.inf) -> Fitted:
    """:func:`fit_chart` on the leading parts of the training records (``settings.horizon`` samples, then 4x longer),
    each stage from the last one's fit, and finally on the whole records."""
    for h in horizons(train, settings.horizon):
        try:
            ident = _identify(diagram, [d.slice(0, h) if d.n_rows > h else d for d in train], settings, max_iter)
        except (SdnnError, ValueError, KeyError):
            break  # a stage the short parts cannot support: the fit on the whole records decides
        if ident.status == "interrupted":
            return _fitted(ident, records, settings, extra_dof, start, accepted)
        cost = ident.fit.train.cost
        if cost is None or not math.isfinite(cost):
            break  # diverged on a short stage: continue from where it was
        diagram = ident.diagram
    return fit_chart(diagram, train, records, settings, max_iter, extra_dof, start, None, accepted, target)

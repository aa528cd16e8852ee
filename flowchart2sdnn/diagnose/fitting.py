"""A chart fitted for diagnosis: the settings, the :class:`Fitted` record (training cost, validation error,
information criteria), fits with a growing horizon, and the residual analysis of a fit.

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
from ..fit.effective import effective_samples
from ..identify import (
    NOISE_MARGIN,
    REFIT_TAU,
    SUSPECT_PEAK,
    Identification,
    IdentifySettings,
    Problem,
    build_problem,
    choose_shooting,
    data_init,
    estimate_initial_state,
    identify,
    measure_floor,
    metrics,
    noise_cost,
    pooled_floor,
)
from .effects import Scales
from .residual import signal_correlation, whiteness

__all__ = ["DiagnoseSettings", "Fitted", "fit_chart", "with_floor", "fit_growing", "horizons", "current_problem", "effect_scales",
           "residual_analysis", "DEFAULT_SPLIT", "VALIDATION_SEGMENTS", "gain_spread", "unpredictable",
           "far_above_noise", "still_moving"]

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
    compiled = ident.problem.compiled
    parts = max(2, math.ceil(VALIDATION_SEGMENTS / max(len(records), 1)))
    per = []
    for ds, start in records:
        if init_window:
            state = estimate_initial_state(compiled, ident.x, ds, alignment, init_window,
                                           data_init(ident.problem.network, ds))
            m = metrics(compiled, ident.x, ds, alignment, score_from=max(start, init_window), history=state.history,
                        segments=parts)
            m["initial_state"] = state.to_dict()
        else:
            m = metrics(compiled, ident.x, ds, alignment, score_from=start, segments=parts)
        per.append(m)
    return {"rms_all": _rms_all(per, compiled.n_outputs), "records": per,
            "rms_records": [_rms_all([m], compiled.n_outputs) for m in per]}


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
                    f"left it cannot reach {target:.6g}, the round's best refit")
        return None
    return cutoff


def _identify(diagram: Diagram, train: list[Dataset], settings: DiagnoseSettings, max_iter: int,
              progress: Progress | None = None, cutoff=None) -> Identification:
    # floor_bias off: diagnose compares costs and validation RMS, never the intervals, over many refits
    full = max_iter >= settings.max_iter
    # trainlm's damping and the bound transform: diagnose's decisions were measured with them (identify.settings.
    # LM_DAMPING, LM_BOUNDS); with the box's trust radius a chaotic drive's neutral cogging refit stayed at 10x the
    # noise (tests/test_diagnose_chaotic_refit.py), with Nielsen's damping the tanks bench credited a saturation
    # before the overflow (tests/test_diagnose_overflow.py). Which optimiser a decision needs is a symptom the
    # decision rule itself must remove; until then the measured one stays.
    s = IdentifySettings(max_iter=max_iter, seed=settings.seed, alignment=settings.alignment, lm_tau=settings.lm_tau,
                         floor_bias=False, shooting=settings.shooting if full else "off", lm_damping="trainlm",
                         lm_bounds="transform")
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


def unpredictable(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> bool:
    """Whether the single-shooting fit `fitted` may have stopped where a growing horizon (:func:`fit_growing`)
    goes further: its chart amplifies a moved start more than stable charts do (identify.shooting.auto's probe over
    the training records, peak above SUSPECT_PEAK) and its training residual is off the noise floor (RMS above
    NOISE_MARGIN x the noise read off the records' second differences): identify's rule for its second look
    (identify.shooting.auto.second_look), applied to a brief refit.

    Why: a neutral effect (zero amplitude) starts on the chart's own trajectory, yet the effect it adds may make
    the drive chaotic (motor cogging, two-mass bench, 30 s records at 0.01 rad/s: the brief refits of cogging
    p = 6 at w1 grew a moved start 53- to 3e6-fold and ended at 26-97x the noise, validation RMS 0.086 -> 0.097
    on seed 1; with the growing horizon 0.0129, the amplitude within 0.1 %). The gate keeps stable charts as they
    were: there the growing horizon would only add time, and when it was last measured for every neutral
    candidate, on EMPS a learned friction curve bent on the first 0.5 s won over the physical terms
    (docs/diagnose.md).
    """
    problem = _training_problem(fitted, train, settings)
    if problem is None or not _above_noise(fitted, problem, NOISE_MARGIN):
        return False
    return choose_shooting(problem, problem.compiled.theta0()).peak > SUSPECT_PEAK


def still_moving(fitted: Fitted) -> list[str]:
    """The quantities an unfinished fit would still move by more than their standard error: the undamped
    Gauss-Newton step from where it stopped, against sqrt(sigma² (JᵀJ)⁻¹_ii) with sigma² the residual's variance
    per effective sample (fit.effective). Empty when the fit is at its minimum in that sense, whatever stopped it."""
    ident = fitted.identification
    problem, x = ident.problem, ident.x
    if problem is None or x is None or not problem.names:
        return []
    out = problem.fun(np.asarray(x, dtype=float))
    if out is None:
        return list(problem.names)
    e, J = out
    J = np.asarray(J.toarray() if hasattr(J, "toarray") else J, dtype=float)
    step, *_ = np.linalg.lstsq(J, e, rcond=None)
    sigma2 = float(e @ e) / effective_samples(e, len(problem.compiled.output_names))
    cov = sigma2 * np.linalg.pinv(J.T @ J, rcond=1e-12)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return [n for n, d, s in zip(problem.names, step, se, strict=True) if abs(d) > s]


def far_above_noise(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings, ratio: float) -> bool:
    """Whether the training residual RMS of `fitted` exceeds `ratio` x the noise read off the records' second
    differences (:func:`~flowchart2sdnn.identify.assess.noise.noise_level`); False where that cannot be told."""
    problem = _training_problem(fitted, train, settings)
    return problem is not None and _above_noise(fitted, problem, ratio)


def _training_problem(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> Problem | None:
    """The problem of `fitted`'s chart on the training records, None for a fit without a finite cost or a chart
    that no longer builds."""
    if not math.isfinite(fitted.cost) or getattr(fitted.identification, "problem", None) is None:
        return None
    try:
        return current_problem(fitted, train, settings)
    except (SdnnError, ValueError, KeyError):
        return None


def _above_noise(fitted: Fitted, problem: Problem, ratio: float) -> bool:
    m = sum(s.targets.size for s in problem.segments)
    return fitted.cost / max(1, m) > noise_cost(problem, ratio)


def current_problem(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> Problem:
    return build_problem(fitted.diagram, train[0], settings.alignment, settings.seed, more=tuple(train[1:]))


def _signals(problem: Problem, x: np.ndarray) -> dict[str, np.ndarray]:
    """Every neuron's output over all training records, concatenated like the residual."""
    parts = [problem.compiled.signals(x, s.inputs, s.init) for s in problem.segments]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _inputs(problem: Problem) -> np.ndarray:
    return np.vstack([s.inputs for s in problem.segments])


def effect_scales(problem: Problem) -> Scales:
    x = problem.compiled.theta0()
    sig = _signals(problem, x)
    rms = {k: float(np.sqrt(np.mean(v**2))) for k, v in sig.items() if np.all(np.isfinite(v))}
    # a signal's range: where a state limit (overflow) is scanned
    lo = {k: float(np.min(v)) for k, v in sig.items() if k in rms}
    hi = {k: float(np.max(v)) for k, v in sig.items() if k in rms}
    u_all = _inputs(problem)
    for i, name in enumerate(problem.compiled.input_names):
        u = u_all[:, i]
        rms[name] = float(np.sqrt(np.mean(u**2)))
        lo[name], hi[name] = float(np.min(u)), float(np.max(u))
    return Scales(rms, lo, hi)


def residual_analysis(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> dict:
    """Whiteness, independence from the inputs and the internal signals most correlated with the residual."""
    problem = current_problem(fitted, train, settings)
    x = problem.compiled.theta0()
    e = problem.residual(x)
    if e is None:
        return {"error": "the fitted chart diverges on the training record"}
    e = e.reshape(-1, problem.compiled.n_outputs)
    u = _inputs(problem)
    out = whiteness(e, u, problem.compiled.output_names, problem.compiled.input_names)
    sig = _signals(problem, x)
    inputs = {n: u[:, i] for i, n in enumerate(problem.compiled.input_names)}
    out["signals"] = signal_correlation(e, {**inputs, **sig}, problem.compiled.output_names)
    return out

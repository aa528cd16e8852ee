"""identify(): fit a chart's physical parameters and learned curves to measured data.

Offline: Levenberg-Marquardt (eq. 11) on the cost of eq. (4) with the exact RTRL Jacobian, from one or several
seeded starts. Quasi-online (paper section 3.1): a sliding window and one LM step per sample, the estimate the
mean over the last K steps. Either way the result carries uncertainty, fit metrics and everything needed to
reproduce the run. Never prints: progress goes through `progress(text, fraction)`.
"""

from __future__ import annotations

import platform
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from .. import __version__
from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..fit.lm import LMOptions, LMResult, levenberg_marquardt
from ..fit.multistart import draw_starts, run_multistart
from ..fit.uncertainty import covariance
from .chartio import RESULT_FORMAT, with_values
from .problem import Problem, build_problem, metrics

__all__ = ["IdentifySettings", "Identification", "identify", "RESULT_VERSION"]

RESULT_VERSION = 1
#: Warn when the fitted network is this close to chattering at rest.
CHATTER_WARN = 0.9


@dataclass(frozen=True)
class IdentifySettings:
    starts: int = 1
    seed: int = 0
    max_iter: int = 100
    alignment: str = "zoh"
    split: float | None = None
    online: bool = False
    window: int = 25000
    average: int = 25000
    every: int = 1
    online_start: int = 0
    fixed_from: tuple[str, ...] = ()
    ranges: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.starts < 1:
            raise ValueError("--starts must be at least 1")
        if self.max_iter < 0:
            raise ValueError("--max-iter must not be negative")
        if self.split is not None and not 0 < self.split < 1:
            raise ValueError("--split must lie strictly between 0 and 1")
        if self.window < 2 or self.average < 1 or self.every < 1:
            raise ValueError("--window must be >= 2, --average and --every >= 1")


@dataclass(frozen=True, eq=False)
class Identification:
    """What identify() found: the result document (RESULT.json), the identified chart and the fit itself."""

    result: dict
    diagram: Diagram
    problem: Problem
    x: np.ndarray
    lm: LMResult | None = None
    online: object | None = None


def _bounds(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = [], []
    params = {p.name: p for p in problem.network.parameters}
    for name in problem.names:
        p = params.get(name)
        lo.append(-np.inf if p is None or p.min is None else p.min)
        hi.append(np.inf if p is None or p.max is None else p.max)
    return np.array(lo, dtype=float), np.array(hi, dtype=float)


def _nonlinear_weights(problem: Problem, x: np.ndarray) -> dict[str, dict]:
    _, free = problem.compiled.values(x)
    out: dict[str, dict] = {}
    for fw in problem.network.free_weights:
        if fw.block is None or fw.role is None:
            continue
        entry = out.setdefault(fw.block, {"a": [], "v": [], "b": [], "fixed": fw.fixed})
        entry[fw.role].append(float(free[fw.name]))
    for entry in out.values():
        if not entry["b"]:
            del entry["b"]
    return out


def identify(diagram: Diagram, train: Dataset, validation: Dataset | None = None,
             settings: IdentifySettings = IdentifySettings(),
             progress: Callable[[str, float | None], None] | None = None) -> Identification:
    full = train
    if settings.split is not None:
        if validation is not None:
            raise ValueError("give either a validation file or a split, not both")
        n_train = max(3, int(round(settings.split * train.n_rows)))
        train = full.slice(0, n_train)
    problem = build_problem(diagram, train, settings.alignment, settings.seed)
    names = problem.names
    x0 = problem.compiled.theta0()
    lower, upper = _bounds(problem)
    warnings: list[str] = []
    lm_result: LMResult | None = None
    online_result = None
    multistart_summary = None
    status, message, interrupted = "ok", "", False

    if not names:
        x = x0
        status, message = "nothing_to_fit", "every parameter and curve is fixed; only the fit was evaluated"
    elif settings.online:
        from ..fit.online import OnlineOptions, quasi_online

        opts = OnlineOptions(window=min(settings.window, len(problem.inputs)),
                             average=settings.average, every=settings.every, start=settings.online_start)
        online_result = quasi_online(problem.compiled, problem.inputs, problem.targets, x0, lower, upper, opts,
                                     init=problem.init,
                                     callback=(lambda f: progress("quasi-online", f)) if progress else None)
        x = np.asarray(online_result.theta_mean, dtype=float)
        status, message = online_result.status, online_result.message
        interrupted = status == "interrupted"
    else:
        # stop once an iteration gains less than 1e-10 of the cost: further iterations only polish noise
        options = LMOptions(max_iter=settings.max_iter, min_rel_cost_change=1e-10)
        starts = draw_starts(names, x0, lower, upper, settings.starts, settings.seed,
                             ranges=settings.ranges or None)

        def fit_one(start: np.ndarray) -> LMResult:
            def callback(it, x, cost, mu):
                if progress:
                    progress(f"LM iteration {it}, cost {cost:.6g}, mu {mu:.1e}",
                             min(1.0, it / max(1, settings.max_iter)))
            return levenberg_marquardt(problem.fun, start, names, lower, upper, options, callback=callback,
                                       guard=problem.guard, residual=problem.residual)

        def start_done(i, result):
            if progress and settings.starts > 1:
                progress(f"start {i + 1}/{settings.starts}: cost {result.cost:.6g} ({result.status})",
                         (i + 1) / settings.starts)

        ms = run_multistart(fit_one, starts, callback=start_done)
        lm_result = ms.best
        x = np.asarray(lm_result.x, dtype=float)
        status, message, interrupted = lm_result.status, lm_result.message, ms.interrupted or lm_result.interrupted
        multistart_summary = ms.summary()
        if settings.starts > 1:
            multistart_summary["names"] = list(names)
            if ms.local_minima:
                warnings.append(ms.message)
        if interrupted:
            status = "interrupted"

    # uncertainty at the final point (the Jacobian of the whole training record)
    cov = None
    if names:
        fe = problem.fun(x)
        if fe is not None:
            cov = covariance(fe[1], fe[0], names=names)
            warnings.extend(_identifiability_warnings(cov, problem))
        radius = problem.chatter(x)
        if radius > CHATTER_WARN:
            warnings.append(f"the fitted network is close to chattering at rest (eigenvalue {-radius:.3f}); a "
                            "learned curve is nearly as steep as the sample time allows (about 2*J/T)")

    params, free = problem.compiled.values(x)
    nonlinear = _nonlinear_weights(problem, x)
    index = {n: i for i, n in enumerate(names)}
    parameters = {}
    for p in diagram.parameters:
        i = index.get(p.name)
        stderr = ci = None
        if i is not None and cov is not None and cov.available and np.isfinite(cov.stderr[i]):
            stderr = float(cov.stderr[i])
            ci = [float(params[p.name] - cov.ci95[i]), float(params[p.name] + cov.ci95[i])]
        parameters[p.name] = {"value": float(params[p.name]), "init": float(p.init), "stderr": stderr,
                              "ci95": ci, "unit": p.unit, "fixed": i is None}

    fit = {"train": metrics(problem.compiled, x, train, settings.alignment), "validation": None}
    if settings.split is not None:
        fit["validation"] = metrics(problem.compiled, x, full, settings.alignment, score_from=train.n_rows)
        fit["validation"]["note"] = "free run over the whole record, scored after the split"
    elif validation is not None:
        fit["validation"] = metrics(problem.compiled, x, validation, settings.alignment)

    identified = with_values(diagram, params, nonlinear)
    result = {
        "format": RESULT_FORMAT,
        "version": RESULT_VERSION,
        "status": status,
        "message": message,
        "interrupted": bool(interrupted),
        "parameters": parameters,
        "nonlinear": nonlinear,
        "fit": fit,
        "warnings": warnings,
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(settings).items()},
        "seed": settings.seed,
        "chart": {"name": diagram.name, "file": diagram.file, "sha256": diagram.source_sha256},
        "data": {"train": _data_info(full if settings.split is not None else train),
                 "validation": _data_info(validation) if validation is not None else None},
        "versions": _versions(),
    }
    if lm_result is not None:
        result["optimizer"] = {"iterations": lm_result.iterations, "cost_history": list(lm_result.cost_history),
                               "nfev": lm_result.nfev, "njev": lm_result.njev,
                               "rejected": {"cost": lm_result.rejected_cost,
                                            "diverged": lm_result.rejected_diverged,
                                            "chatter": lm_result.rejected_guard}}
    if multistart_summary is not None:
        result["multistart"] = multistart_summary
    if cov is not None and cov.available:
        corr = np.where(np.isfinite(cov.correlation), cov.correlation, np.nan)
        result["uncertainty"] = {
            "names": list(names),
            "correlation": [[None if not np.isfinite(v) else round(float(v), 12) for v in row] for row in corr],
            "condition_number": float(cov.condition_number) if np.isfinite(cov.condition_number) else None,
            "unidentifiable": [list(g) for g in cov.unidentifiable],
            "sigma2": cov.sigma2,
        }
    if online_result is not None:
        result["online"] = {
            "window": settings.window, "average": settings.average, "every": settings.every,
            "steps": int(online_result.steps), "mean_cost": float(online_result.mean_cost),
            "final": {n: float(v) for n, v in zip(names, online_result.theta_final, strict=True)},
            "trajectory_time": [float(t) for t in online_result.trajectory_time],
            "trajectories": {n: [float(v) for v in online_result.trajectory[:, i]] for i, n in enumerate(names)},
            "cost_time": [float(t) for t in online_result.cost_time],
            "cost": [float(c) for c in online_result.cost],
        }
    return Identification(result, identified, problem, x, lm_result, online_result)


def _identifiability_warnings(cov, problem: Problem) -> list[str]:
    """Groups that cannot be told apart, when they involve a physical parameter.

    The weights of one learned curve trade off against each other all the time (a*v of a nearly linear
    neuron); that says nothing about the physics, so such groups are not reported.
    """
    physical = {p.name for p in problem.network.parameters}
    out = []
    for group in cov.unidentifiable:
        if physical & set(group):
            out.append(f"cannot be told apart from this data: {', '.join(group)} (fix all but one, or excite more)")
    for a, b, r in cov.correlated:
        if {a, b} & physical and not any({a, b} <= set(g) for g in cov.unidentifiable):
            out.append(f"{a} and {b} are almost interchangeable here (correlation {r:+.4f})")
    return out


def _data_info(ds: Dataset) -> dict:
    return {"file": ds.path, "sha256": ds.sha256, "rows": ds.n_rows,
            "max_step_deviation": ds.max_step_deviation}


def _versions() -> dict:
    import networkx
    import numba
    import scipy

    return {"sdnn": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__, "networkx": networkx.__version__}

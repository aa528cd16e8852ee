"""identify(): fit a chart's physical parameters and learned curves to measured data.

Offline: Levenberg-Marquardt (eq. 11) on the cost of eq. (4) with the exact RTRL Jacobian, from one or several
seeded starts. Quasi-online (paper section 3.1): LM iterations on a sliding window as the record streams by,
the estimate the mean over the last K steps; with several starts, the run with the lowest final window cost. Either way the result carries uncertainty, fit metrics and everything needed to
reproduce the run. Never prints: progress goes through `progress(text, fraction)`.
"""

from __future__ import annotations

import functools
import math
import platform
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from .. import __version__
from ..data.csvdata import Dataset
from ..diagram.dump import with_values
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..fit.lm import LMOptions, LMResult, levenberg_marquardt
from ..fit.multistart import draw_starts, run_multistart
from ..fit.uncertainty import covariance
from .chartio import RESULT_FORMAT
from .problem import CHATTER_LIMIT, GROWTH_LIMIT, Problem, build_problem, metrics

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
    # first LM damping = lm_tau * max diag(JᵀJ) (see fit.lm.LMOptions.tau); 0 gives trainlm's fixed 1e-3
    lm_tau: float = 1e-3

    def __post_init__(self):
        if self.starts < 1:
            raise ValueError("--starts must be at least 1")
        if self.max_iter < 0:
            raise ValueError("--max-iter must not be negative")
        if self.split is not None and not 0 < self.split < 1:
            raise ValueError("--split must lie strictly between 0 and 1")
        if self.window < 2 or self.average < 1 or self.every < 1:
            raise ValueError("--window must be >= 2, --average and --every >= 1")
        if not (self.lm_tau >= 0 and math.isfinite(self.lm_tau)):
            raise ValueError("lm_tau must be a finite number >= 0")


@dataclass(frozen=True, eq=False)
class Identification:
    """What identify() found: the result document (RESULT.json), the identified chart and the fit itself."""

    result: dict
    diagram: Diagram
    problem: Problem
    x: np.ndarray
    lm: LMResult | None = None
    online: object | None = None


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


@np.errstate(all="ignore")  # a diverging trial is expected and handled: no RuntimeWarnings on stderr
def identify(diagram: Diagram, train: Dataset | Sequence[Dataset], validation: Dataset | None = None,
             settings: IdentifySettings = IdentifySettings(),
             progress: Callable[[str, float | None], None] | None = None,
             executor=None, stop: Callable[[], bool] | None = None) -> Identification:
    """Identify the chart's free quantities from `train`; see the module docstring.

    `executor` (a :mod:`flowchart2sdnn.executors` executor, optional) runs the multi-start fits in worker
    processes or on a Dask cluster; the result is the same as without it (progress then comes per start).
    `stop` (optional) is polled after each LM iteration, start and online chunk; when it returns True the
    run ends early with status "interrupted" and the best point so far (the CLI's Ctrl-C).
    Several training records (a sequence) are fitted together, each simulated from its own initial state.
    """
    records = [train] if isinstance(train, Dataset) else list(train)
    if not records:
        raise ValueError("identify needs at least one training record")
    train, more = records[0], records[1:]
    if more and (settings.split is not None or settings.online):
        raise SdnnError.at("DATA003", "several training records cannot be combined with --split or --online (yet)",
                           more[0].path, hint="give one record, or drop that option")
    full = train
    if settings.split is not None:
        if validation is not None:
            raise ValueError("give either a validation file or a split, not both")
        n_train = max(3, int(round(settings.split * train.n_rows)))
        train = full.slice(0, n_train)
    problem = build_problem(diagram, train, settings.alignment, settings.seed, more=more)
    names = problem.names
    x0 = problem.compiled.theta0()
    problem, warnings = _start_stability(problem, x0)
    lower, upper = problem.bounds()
    warnings += _on_bound_warnings(names, x0, lower, upper)
    lm_result: LMResult | None = None
    online_result = None
    multistart_summary = None
    status, message, interrupted = "ok", "", False

    if not names:
        x = x0
        status, message = "nothing_to_fit", "every parameter and curve is fixed; only the fit was evaluated"
    elif settings.online:
        online_result, ms = _online(problem, x0, lower, upper, settings, progress, stop, executor)
        x = np.asarray(online_result.theta_mean, dtype=float)
        status, message = online_result.status, online_result.message
        interrupted = status == "interrupted"
        if ms is not None:
            multistart_summary = _multistart_summary(ms, names, warnings)
            multistart_summary["cost"] = "mean window cost over the last K steps of each quasi-online run"
    else:
        # stop once an iteration gains less than 1e-10 of the cost: further iterations only polish noise
        options = LMOptions(max_iter=settings.max_iter, min_rel_cost_change=1e-10, tau=settings.lm_tau)
        starts = draw_starts(names, x0, lower, upper, settings.starts, settings.seed,
                             ranges=settings.ranges or None)

        def fit_one(start: np.ndarray) -> LMResult:
            def callback(it, x, cost, mu):
                if progress:
                    progress(f"LM iteration {it}, cost {cost:.6g}, mu {mu:.1e}",
                             min(1.0, it / max(1, settings.max_iter)))
                return bool(stop and stop())
            own = problem.from_start(start)
            return levenberg_marquardt(own.fun, start, names, lower, upper, options, callback=callback,
                                       guard=own.guard, residual=own.residual)

        def start_done(i, result):
            if progress and settings.starts > 1:
                progress(f"start {i + 1}/{settings.starts}: cost {result.cost:.6g} ({result.status})",
                         (i + 1) / settings.starts)
            return bool(stop and stop())

        if executor is not None:
            from .workers import fit_start, fit_task

            fit_one = functools.partial(fit_start, fit_task(problem, lower, upper, options))
        ms = run_multistart(fit_one, starts, callback=start_done, executor=executor)
        lm_result = ms.best
        x = np.asarray(lm_result.x, dtype=float)
        status, message, interrupted = lm_result.status, lm_result.message, ms.interrupted or lm_result.interrupted
        multistart_summary = _multistart_summary(ms, names, warnings) if settings.starts > 1 else ms.summary()
        if interrupted:
            status = "interrupted"

    if status == "callback_stop" or message.startswith("stopped by the callback"):  # `stop`: the CLI's Ctrl-C
        status, interrupted = "interrupted", True
        message = "interrupted (Ctrl-C); the best point so far is returned" + _detail(message)
    diverged = status == "diverged_at_start"

    # uncertainty at the final point (the Jacobian of the whole training record)
    cov = None
    if names and not diverged:
        fe = problem.fun(x)
        if fe is not None and not np.any(fe[1]):
            if not interrupted:  # nothing was identified: report the start values exactly
                status, message, x = "no_excitation", _no_excitation(problem), x0
        elif fe is not None:
            cov = covariance(fe[1], fe[0], names=names)
            if cov.available and not math.isfinite(cov.sigma2):
                cov = None  # the residual's square overflows: no meaningful uncertainty
            else:
                warnings.extend(_identifiability_warnings(cov, problem))
                rho, inflation = _coloured_residual(fe[0], len(problem.compiled.output_names))
        radius = problem.chatter(x)
        if radius > CHATTER_WARN:
            warnings.append(f"the fitted network is close to chattering at rest (eigenvalue {-radius:.3f}); a "
                            "learned curve is nearly as steep as the sample time allows (about 2*J/T)")

    params, free = problem.compiled.values(x)
    nonlinear = _nonlinear_weights(problem, x)
    if cov is None or not cov.available:
        rho, inflation = None, 1.0
    index = {n: i for i, n in enumerate(names)}
    parameters = {}
    for p in diagram.parameters:
        i = index.get(p.name)
        stderr = ci = None
        if i is not None and cov is not None and cov.available and np.isfinite(cov.stderr[i]):
            stderr = float(cov.stderr[i]) * inflation
            half = float(cov.ci95[i]) * inflation
            ci = [float(params[p.name] - half), float(params[p.name] + half)]
        parameters[p.name] = {"value": float(params[p.name]), "init": float(p.init), "stderr": stderr,
                              "ci95": ci, "unit": p.unit, "fixed": i is None}

    fit = {"train": metrics(problem.compiled, x, train, settings.alignment), "validation": None}
    if more:
        per_record = [fit["train"]] + [metrics(problem.compiled, x, d, settings.alignment) for d in more]
        fit["train"] = _combined(per_record, problem, x, [train] + more, settings.alignment)
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
                 "train_records": [_data_info(d) for d in ([full] if settings.split is not None else [train] + more)],
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
            "residual_lag1": rho,
            "interval_inflation": inflation,
            "note": "stderr and ci95 are widened by interval_inflation = sqrt((1+rho)/(1-rho)) for the residual's "
                    "lag-1 autocorrelation rho (coloured residuals carry fewer independent samples)",
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
    bad: list[str] = []
    result = _json_safe(result, "", bad)
    if bad:
        result["warnings"].append(f"non-finite values stored as null: {', '.join(bad[:5])}"
                                  + (f" (+{len(bad) - 5} more)" if len(bad) > 5 else ""))
    return Identification(result, identified, problem, x, lm_result, online_result)


def _on_bound_warnings(names, x0: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> list[str]:
    """Starts exactly on a bound: allowed, but the bound transform is flat there and such a quantity moves slowly."""
    out = []
    for name, x, lo, hi in zip(names, x0, lower, upper, strict=True):
        side = "lower" if x == lo else "upper" if x == hi else None
        if side:
            out.append(f"{name} starts on its {side} bound ({x:g}); it can move away only slowly (the bound "
                       "transform is flat there): start it inside the bounds")
    return out


def _online(problem: Problem, x0, lower, upper, settings: IdentifySettings, progress, stop, executor):
    """Quasi-online from x0, or from `settings.starts` seeded starts: (the chosen OnlineResult, the
    MultiStartResult or None).

    With several starts each run is a whole quasi-online pass; the one with the lowest mean window cost at
    the end of the record (the paper's error of a run) is reported, as a bank of online estimators would.
    """
    from .online import OnlineOptions, OnlineStart, quasi_online

    opts = OnlineOptions(window=min(settings.window, len(problem.inputs)),
                         average=settings.average, every=settings.every, start=settings.online_start)
    n = settings.starts

    def run_one(start: np.ndarray, label: str = "quasi-online") -> OnlineStart:
        return OnlineStart(quasi_online(problem.compiled, problem.inputs, problem.targets, start, lower, upper,
                                        opts, init=problem.init,
                                        callback=lambda f: _online_tick(progress, stop, f, label)))

    if n == 1:
        return run_one(x0).result, None
    starts = draw_starts(problem.names, x0, lower, upper, n, settings.seed, ranges=settings.ranges or None)
    counter = iter(range(1, n + 1))  # serial runs come in start order

    def fit_one(start: np.ndarray) -> OnlineStart:
        return run_one(start, f"quasi-online, start {next(counter)}/{n}")

    if executor is not None:
        from .workers import fit_task, online_start

        fit_one = functools.partial(online_start, fit_task(problem, lower, upper, opts))

    def start_done(i, run):
        if progress:
            progress(f"start {i + 1}/{n}: mean window cost {run.cost:.6g} ({run.status})", (i + 1) / n)
        return bool(stop and stop())

    ms = run_multistart(fit_one, starts, callback=start_done, executor=executor)
    best = ms.best.result
    if ms.interrupted and best.status not in ("interrupted", "callback_stop"):
        best = replace(best, status="interrupted",
                       message="interrupted: the best of the runs finished so far is returned")
    return best, ms


def _multistart_summary(ms, names, warnings: list[str]) -> dict:
    """The `multistart` entry of the result; a run that ended in a clearly worse minimum is also a warning."""
    summary = ms.summary()
    summary["names"] = list(names)
    if ms.local_minima:
        warnings.append(ms.message)
    return summary


def _online_tick(progress, stop, fraction: float, label: str = "quasi-online") -> bool:
    if progress:
        progress(label, fraction)
    return bool(stop and stop())


def _detail(message: str) -> str:
    """The parenthesised details of a trainer message ("... (iteration 3, cost 1.2, mu 0.1)")."""
    at = message.find(" (")
    return message[at:] if at >= 0 else ""


def _no_excitation(problem: Problem) -> str:
    constant = [spec.name for spec, col in zip(problem.compiled.net.inputs, problem.inputs.T, strict=True)
                if np.ptp(col) == 0] if problem.inputs.size else []
    why = f" (constant input: {', '.join(constant)})" if constant else ""
    return ("the training data do not excite the model: no output depends on any free parameter or curve"
            f"{why}; the start values are returned, nothing was identified")


def _json_safe(obj, path: str, bad: list[str]):
    """`obj` with every NaN/inf float replaced by None (its path noted in `bad`): RESULT.json stays strict JSON."""
    if isinstance(obj, float):
        if math.isfinite(obj):
            return obj
        bad.append(path or "(root)")
        return None
    if isinstance(obj, dict):
        return {k: _json_safe(v, f"{path}.{k}" if path else str(k), bad) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v, f"{path}[{i}]", bad) for i, v in enumerate(obj)]
    return obj


def _start_stability(problem: Problem, x0: np.ndarray) -> tuple[Problem, list[str]]:
    """Check the start at rest. Chatter (a sign flip every sample) cannot be fitted away: an error. A start that
    drifts away from rest can: warn, and let the guard accept steps no worse than the start."""
    if not problem.names:
        return problem, []
    chatter, growth = problem.stability(x0)
    if chatter > CHATTER_LIMIT:
        raise SdnnError.at(
            "FIT001", f"at its initial values (init) the chart's discrete network chatters at rest (eigenvalue "
            f"{-chatter:.3f}): a curve in a feedback loop is too steep for the sample time "
            f"T = {problem.network.sample_time:g} s (limit about 2*J/T)", problem.diagram.file,
            hint="soften the curve (a larger eps of sign_smooth, a smaller k or init) or use a learned `nonlinear` block")
    if growth <= GROWTH_LIMIT:
        return problem, []
    warning = (f"at its initial values the chart's discrete network drifts away from rest (eigenvalue {growth:.3f}): "
               "a curve in a feedback loop has a negative slope at zero; the fit may take long to recover")
    return replace(problem, stability_floor=(chatter, growth)), [warning]


def _coloured_residual(residual: np.ndarray, n_outputs: int) -> tuple[float | None, float]:
    """Lag-1 autocorrelation of the residual and the factor that widens the intervals for it.

    The textbook covariance assumes white residuals; model error makes them coloured and the intervals far
    too narrow. With an AR(1) residual of correlation rho the effective number of samples is
    n (1 - rho) / (1 + rho), so standard errors grow by sqrt((1 + rho) / (1 - rho)).
    """
    e = residual.reshape(-1, n_outputs)
    if len(e) < 3:
        return None, 1.0
    rhos = []
    for i in range(n_outputs):
        ei = e[:, i] - e[:, i].mean()
        denom = float(ei @ ei)
        if denom > 0:
            rhos.append(float(ei[1:] @ ei[:-1]) / denom)
    if not rhos:
        return None, 1.0
    rho = float(np.mean(rhos))
    r = min(max(rho, 0.0), 0.999)
    return rho, float(np.sqrt((1 + r) / (1 - r)))


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


def _combined(per_record: list[dict], problem: Problem, x: np.ndarray, records: list[Dataset],
              alignment: str) -> dict:
    """Training metrics over several records: E summed, RMS and fit % over all their scored samples."""
    from ..network.alignment import fitted_rows, run_aligned
    from .problem import data_init

    names = problem.compiled.output_names
    errors, targets = [], []
    for d in records:
        u = np.column_stack([np.asarray(d.columns[i.name], dtype=float) for i in problem.network.inputs])
        y = np.column_stack([np.asarray(d.columns[n], dtype=float) for n in names])
        rows = fitted_rows(d.n_rows, alignment)
        yhat = run_aligned(problem.compiled, x, u, alignment, data_init(problem.network, d))
        errors.append(y[rows] - yhat[rows])
        targets.append(y[rows])
    e, y = np.vstack(errors), np.vstack(targets)
    costs = [m["cost"] for m in per_record]
    out = {"rows": int(len(e)), "cost": None if None in costs else float(sum(costs)), "rms": {}, "fit_percent": {},
           "records": per_record}
    for i, name in enumerate(names):
        finite = bool(np.all(np.isfinite(e[:, i])))
        spread = np.linalg.norm(y[:, i] - y[:, i].mean())
        out["rms"][name] = float(np.sqrt(np.mean(e[:, i] ** 2))) if finite else None
        out["fit_percent"][name] = (float(100 * (1 - np.linalg.norm(e[:, i]) / spread))
                                    if finite and spread > 0 else None)
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

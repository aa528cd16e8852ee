"""The work units of identification: fit one start, run one quasi-online start, in any executor.

A work unit of a multi-start fit is a :class:`FitTask` (the network file as JSON, the aligned data arrays and
the rest of the fitting problem, the bounds and LM options) plus one start vector; :func:`fit_start` rebuilds the
:class:`~flowchart2sdnn.identify.offline.problem.Problem` in the worker (once per worker: a small cache keyed by the
task's hash) and runs :func:`~flowchart2sdnn.fit.lm.levenberg_marquardt`. The serial path runs the same
function through :class:`~flowchart2sdnn.executors.SerialExecutor`, so every executor gives bit-identical
results for the same seed. Results come back as the same frozen
:class:`~flowchart2sdnn.fit.lm.LMResult` objects (arrays read-only again after unpickling).

Layer: identify (below it: fit, network, executors).
"""

from __future__ import annotations

import dataclasses
import hashlib
import pickle
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...fit.lm import LMResult, levenberg_marquardt
from ..shooting.multiple import shooting_fit

__all__ = ["FitTask", "fit_task", "problem_of", "run_start", "fit_start", "run_quasi_online_start",
           "quasi_online_start"]

# Problems kept per worker process: a multi-start needs one, a batch worker moves from file to file.
_CACHE_SIZE = 4


#: Problem fields a worker rebuilds from the network file instead of receiving them (the chart is not needed).
_REBUILT = ("diagram", "network", "compiled")


@dataclass(frozen=True, eq=False)
class FitTask:
    """Everything a worker needs to run LM from any start: small, picklable, no callbacks.

    Attributes
    ----------
    network_json : str      the network file (:meth:`Network.to_json`)
    problem : dict          every other field of the Problem (aligned inputs and targets, initial states,
                            alignment, the guard's stability floor, further records, ...), as identify built it
    names : tuple of str    theta order (checked against the rebuilt network)
    lower, upper : ndarray (P,) bounds
    options : LMOptions (fit_start) or OnlineOptions (quasi_online_start)
    key : str               sha256 of the network file and the problem fields: the worker's cache key
                            (bounds and options are not cached, they travel with every unit)
    shooting : int          multiple-shooting segment length (0: single shooting; identify.shooting.multiple)
    shooting_starts : str   "data" or "free": the measured states' segment starts (identify.shooting.multiple)
    """

    network_json: str
    problem: dict
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    options: Any  # LMOptions or fit.online.OnlineOptions
    key: str
    shooting: int = 0
    shooting_starts: str = "data"


def fit_task(problem, lower: np.ndarray, upper: np.ndarray, options: Any, shooting: int = 0,
             shooting_starts: str = "data") -> FitTask:
    """The work unit of a multi-start fit of ``problem`` (an identify.offline.problem.Problem).

    Every field of the Problem but the chart and the compiled network travels as it is, so that the worker's
    Problem behaves exactly as the caller's (a field added to Problem later travels too).
    """
    fields = {f.name: getattr(problem, f.name) for f in dataclasses.fields(problem) if f.name not in _REBUILT}
    text = problem.network.to_json()
    h = hashlib.sha256(text.encode())
    h.update(pickle.dumps(fields, protocol=pickle.HIGHEST_PROTOCOL))
    return FitTask(text, fields, tuple(problem.names), np.array(lower, dtype=float), np.array(upper, dtype=float),
                   options, h.hexdigest(), shooting, shooting_starts)


_cache: OrderedDict[str, Any] = OrderedDict()
_cache_lock = threading.Lock()


def problem_of(task: FitTask):
    """The Problem of a task, built once per worker process (thread-safe for in-process Dask workers)."""
    from ...network.model import Network
    from ...network.runtime import CompiledNetwork
    from .problem import Problem

    with _cache_lock:
        problem = _cache.get(task.key)
        if problem is not None:
            _cache.move_to_end(task.key)
            return problem
    network = Network.from_json(task.network_json)
    compiled = CompiledNetwork(network)
    # the chart itself is not needed to run LM; the worker never sees it
    problem = Problem(diagram=None, network=network, compiled=compiled, **task.problem)
    if tuple(problem.names) != task.names:
        raise RuntimeError(f"the rebuilt network fits {problem.names}, the task expects {task.names}")
    with _cache_lock:
        _cache[task.key] = problem
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    return problem


def run_start(problem, start: np.ndarray, lower: np.ndarray, upper: np.ndarray, options,
              callback: Callable | None = None, shooting: int = 0, threads: int = 1,
              shooting_starts: str = "data") -> LMResult:
    """Levenberg-Marquardt from ``start`` on ``problem``: the one way a start is fitted, serial or in a worker.

    Parameters
    ----------
    problem : Problem
    start : ndarray (P,)
    lower, upper : ndarray (P,)
    options : LMOptions
    callback : callable ``callback(iteration, x, cost, mu) -> bool``, optional
        Progress and stop (True stops) after each iteration; only where the caller's process runs the fit.
    shooting : int
        > 0: multiple shooting with segments of this many samples first (identify.shooting.multiple.shooting_fit).
    threads : int
        threads for multiple shooting's segments.
    shooting_starts : str
        "data": measured states start each segment from the data; "free": they are free too (identify.shooting.multiple).
    """
    own = problem.from_start(start)
    if shooting:
        return shooting_fit(own, np.asarray(start, dtype=float), lower, upper, options, shooting,
                            callback=callback, guard=own.guard, threads=threads, starts=shooting_starts)
    return levenberg_marquardt(own.fun, np.asarray(start, dtype=float), problem.names, lower, upper, options,
                               callback=callback, guard=own.guard, residual=own.residual)


def fit_start(task: FitTask, start: np.ndarray) -> LMResult:
    """:func:`run_start` on the task's problem (module-level: runs in any worker).

    Parameters
    ----------
    task : FitTask
    start : ndarray (P,)

    Returns
    -------
    LMResult
    """
    return run_start(problem_of(task), start, task.lower, task.upper, task.options, shooting=task.shooting,
                     shooting_starts=task.shooting_starts)


def run_quasi_online_start(problem, start: np.ndarray, lower: np.ndarray, upper: np.ndarray, options,
                     callback: Callable | None = None):
    """Quasi-online identification from ``start`` (``options`` an OnlineOptions): the one way an online start
    runs, serial or in a worker. ``callback(fraction) -> bool`` reports progress and stops on True.

    Returns
    -------
    flowchart2sdnn.identify.online.run.OnlineStart
    """
    from ..online.run import OnlineStart, quasi_online

    return OnlineStart(quasi_online(problem.compiled, problem.inputs, problem.targets,
                                    np.asarray(start, dtype=float), lower, upper, options, init=problem.init,
                                    callback=callback))


def quasi_online_start(task: FitTask, start: np.ndarray):
    """:func:`run_quasi_online_start` on the task's problem (``task.options`` an OnlineOptions; runs in any worker)."""
    return run_quasi_online_start(problem_of(task), start, task.lower, task.upper, task.options)

"""The fit result as frozen, JSON-exact data.

:class:`FitResult` is what ``sdnn identify`` writes (inside its own envelope).  Everything in it is a
plain finite number, string, bool, None, tuple or read-only mapping; ``to_dict``/``from_dict``/``to_json``
round-trip exactly, and a non-finite number anywhere is refused with the path to it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

import numpy as np

from .lm import LMResult
from .uncertainty import Covariance

__all__ = ["FitResult", "fit_result_from_lm", "FIT_RESULT_FORMAT", "FIT_RESULT_VERSION"]

FIT_RESULT_FORMAT = "flowchart2sdnn-fit-result"
FIT_RESULT_VERSION = 1
_EMPTY: Mapping[str, Any] = MappingProxyType({})


def _plain(obj: Any, path: str) -> Any:
    """Convert to JSON types (dict, list, str, int, float, bool, None); refuse non-finite numbers."""
    if obj is None or isinstance(obj, (str, bool)):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        value = float(obj)
        if not math.isfinite(value):
            raise ValueError(f"`{path}` is {value}: non-finite values cannot be stored in a fit result")
        return value
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, str):
                raise ValueError(f"`{path}` has a non-string key {key!r}")
            out[key] = _plain(value, f"{path}.{key}")
        return out
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v, f"{path}[{i}]") for i, v in enumerate(obj)]
    raise ValueError(f"`{path}` has type {type(obj).__name__}, which is not JSON data")


def _need_number(v: Any, path: str) -> None:
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        raise ValueError(f"`{path}` must be a number, got {v!r}")


def _freeze(obj: Any) -> Any:
    """Plain JSON data -> immutable (tuples, read-only mappings)."""
    if isinstance(obj, dict):
        return MappingProxyType({k: _freeze(v) for k, v in obj.items()})
    if isinstance(obj, list):
        return tuple(_freeze(v) for v in obj)
    return obj


def _thaw(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {k: _thaw(v) for k, v in obj.items()}
    if isinstance(obj, tuple):
        return [_thaw(v) for v in obj]
    return obj


@dataclass(frozen=True)
class FitResult:
    """Fitted quantities with their uncertainty, the optimizer's trace and the settings that produced them.

    Per-quantity tuples all have length P (same order as ``names``): ``values``, ``initial_values``,
    ``units`` (str or None), ``fixed`` (held constant, not fitted), ``stderr`` (None when fixed or not
    determinable), ``ci95`` ((low, high) or None).  ``correlation`` is P x P (None entries where undefined)
    or empty.  ``cost`` is E = 1/2 e^T e at ``values`` (None when unknown).  ``settings``, ``starts`` and
    ``nonlinear_weights`` hold any JSON data; ``trajectories`` maps a name to a sequence of numbers
    (quasi-online mode).  Inputs are normalised (numpy types -> Python, lists -> tuples).
    """

    names: tuple[str, ...]
    values: tuple[float, ...]
    initial_values: tuple[float, ...]
    status: str
    message: str = ""
    units: tuple[str | None, ...] = ()
    fixed: tuple[bool, ...] = ()
    stderr: tuple[float | None, ...] = ()
    ci95: tuple[tuple[float, float] | None, ...] = ()
    correlation: tuple[tuple[float | None, ...], ...] = ()
    cost: float | None = None
    iterations: int = 0
    cost_history: tuple[float, ...] = ()
    mu_history: tuple[float, ...] = ()
    warnings: tuple[str, ...] = ()
    seed: int | None = None
    settings: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    starts: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)
    trajectories: Mapping[str, tuple[float, ...]] = field(default_factory=lambda: _EMPTY)
    nonlinear_weights: Mapping[str, Any] = field(default_factory=lambda: _EMPTY)

    def __post_init__(self) -> None:
        def put(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        names = tuple(str(n) for n in self.names)
        p = len(names)
        if len(set(names)) != p:
            raise ValueError("`names` are not unique")
        put("names", names)
        defaults = {"units": (None,) * p, "fixed": (False,) * p, "stderr": (None,) * p, "ci95": (None,) * p}
        for name in ("values", "initial_values", "units", "fixed", "stderr", "ci95"):
            value = _plain(getattr(self, name), name)
            if name in defaults and len(value) == 0:
                value = list(defaults[name])
            if len(value) != p:
                raise ValueError(f"`{name}` has {len(value)} entries, `names` has {p}")
            put(name, _freeze(value))
        for i, n in enumerate(names):
            _need_number(self.values[i], f"values[{n}]")
            _need_number(self.initial_values[i], f"initial_values[{n}]")
            if self.stderr[i] is not None:
                _need_number(self.stderr[i], f"stderr[{n}]")
                if self.stderr[i] < 0:
                    raise ValueError(f"`stderr[{n}]` is negative")
            if self.ci95[i] is not None:
                if not isinstance(self.ci95[i], tuple) or len(self.ci95[i]) != 2:
                    raise ValueError(f"`ci95[{n}]` must be (low, high) or None")
                for v in self.ci95[i]:
                    _need_number(v, f"ci95[{n}]")
            if self.units[i] is not None and not isinstance(self.units[i], str):
                raise ValueError(f"`units[{n}]` must be a string or None")
        put("values", tuple(float(v) for v in self.values))
        put("initial_values", tuple(float(v) for v in self.initial_values))
        if not all(isinstance(v, bool) for v in self.fixed):
            raise ValueError("`fixed` must hold booleans")
        corr = _freeze(_plain(self.correlation, "correlation"))
        if corr and (len(corr) != p or any(len(row) != p for row in corr)):
            raise ValueError(f"`correlation` must be {p} x {p} or empty")
        for row in corr:
            for v in row:
                if v is not None:
                    _need_number(v, "correlation")
        put("correlation", corr)
        for name in (
            "cost",
            "iterations",
            "seed",
            "cost_history",
            "mu_history",
            "warnings",
            "settings",
            "starts",
            "trajectories",
            "nonlinear_weights",
        ):
            put(name, _freeze(_plain(getattr(self, name), name)))
        if self.cost is not None:
            _need_number(self.cost, "cost")
            put("cost", float(self.cost))
        for name in ("cost_history", "mu_history"):
            for v in getattr(self, name):
                _need_number(v, name)
            put(name, tuple(float(v) for v in getattr(self, name)))
        for name in ("iterations", "seed"):
            v = getattr(self, name)
            if not (v is None and name == "seed") and (not isinstance(v, int) or isinstance(v, bool)):
                raise ValueError(f"`{name}` must be an int, got {v!r}")
        if not all(isinstance(w, str) for w in self.warnings):
            raise ValueError("`warnings` must be strings")
        for key, series in self.trajectories.items():
            if not isinstance(series, tuple):
                raise ValueError(f"`trajectories.{key}` must be a sequence of numbers")
            for v in series:
                _need_number(v, f"trajectories.{key}")
        put("status", str(self.status))
        put("message", str(self.message))

    # ------------------------------------------------------------------ serialization
    def to_dict(self) -> dict:
        """Plain JSON data, with ``format`` and ``version`` keys."""
        out: dict[str, Any] = {"format": FIT_RESULT_FORMAT, "version": FIT_RESULT_VERSION}
        for f in fields(self):
            out[f.name] = _thaw(getattr(self, f.name))
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"

    @classmethod
    def from_dict(cls, data: Mapping) -> FitResult:
        """Inverse of :meth:`to_dict`; keys other than the fields, ``format`` and ``version`` are ignored."""
        if data.get("format") != FIT_RESULT_FORMAT:
            raise ValueError(
                f"not a fit result: 'format' is {data.get('format')!r}, expected {FIT_RESULT_FORMAT!r}"
            )
        if data.get("version") != FIT_RESULT_VERSION:
            raise ValueError(
                f"unsupported fit result version {data.get('version')!r}, expected {FIT_RESULT_VERSION}"
            )
        known = {f.name for f in fields(cls)}
        missing = [k for k in ("names", "values", "initial_values", "status") if k not in data]
        if missing:
            raise ValueError(f"fit result lacks {', '.join(missing)}")
        return cls(**{k: v for k, v in data.items() if k in known})

    @classmethod
    def from_json(cls, text: str) -> FitResult:
        return cls.from_dict(json.loads(text))

    def value(self, name: str) -> float:
        """The fitted value of ``name``."""
        return self.values[self.names.index(name)]


def fit_result_from_lm(
    lm: LMResult,
    *,
    initial_values: Sequence[float],
    covariance: Covariance | None = None,
    units: Mapping[str, str | None] | None = None,
    fixed_values: Mapping[str, float] | None = None,
    order: Sequence[str] | None = None,
    warnings: Sequence[str] = (),
    seed: int | None = None,
    settings: Mapping[str, Any] | None = None,
    starts: Mapping[str, Any] | None = None,
    trajectories: Mapping[str, Sequence[float]] | None = None,
    nonlinear_weights: Mapping[str, Any] | None = None,
) -> FitResult:
    """Assemble a :class:`FitResult` from a trainer result, its covariance and the quantities held fixed.

    Parameters
    ----------
    lm : LMResult
        Result over the fitted quantities ``lm.names``.
    initial_values : sequence of float
        Start values of ``lm.names``.
    covariance : Covariance, optional
        From :func:`~flowchart2sdnn.fit.uncertainty.covariance` at ``lm.x``; its warning/reason is added to
        ``warnings``; infinite standard errors become None.
    units : mapping name -> unit, optional
    fixed_values : mapping name -> value, optional
        Quantities not fitted (``fixed`` = True, no stderr).
    order : sequence of str, optional
        Output order of all names; default the fitted names, then the fixed ones.
    warnings, seed, settings, starts, trajectories, nonlinear_weights
        Passed through (``warnings`` first, then the ones added here).
    """
    fixed_values = dict(fixed_values or {})
    units = dict(units or {})
    free = list(lm.names)
    clash = sorted(set(free) & set(fixed_values))
    if clash:
        raise ValueError(f"quantities both fitted and fixed: {', '.join(clash)}")
    everything = free + list(fixed_values)
    order = list(order) if order is not None else everything
    if sorted(order) != sorted(everything):
        raise ValueError("`order` must list each fitted and fixed quantity exactly once")
    if len(initial_values) != len(free):
        raise ValueError(f"`initial_values` has {len(initial_values)} entries, the fit has {len(free)}")
    index = {n: i for i, n in enumerate(free)}

    notes = list(warnings)
    if not lm.converged:
        notes.append(f"the fit stopped before converging: {lm.message}")
    have_cov = covariance is not None and covariance.available
    if covariance is not None:
        if covariance.reason:
            notes.append(f"no confidence intervals: {covariance.reason}")
        if covariance.warning:
            notes.append(covariance.warning)

    def finite(v: float) -> float | None:
        return float(v) if math.isfinite(v) else None

    values, initial, stderr, ci95 = [], [], [], []
    for name in order:
        if name in index:
            i = index[name]
            x = float(lm.x[i])
            values.append(x)
            initial.append(float(initial_values[i]))
            se = finite(covariance.stderr[i]) if have_cov else None
            half = finite(covariance.ci95[i]) if have_cov else None
            stderr.append(se)
            ci95.append((x - half, x + half) if half is not None else None)
        else:
            values.append(float(fixed_values[name]))
            initial.append(float(fixed_values[name]))
            stderr.append(None)
            ci95.append(None)
    correlation = []
    if have_cov:
        for a in order:
            correlation.append(
                [
                    finite(covariance.correlation[index[a], index[b]]) if a in index and b in index else None
                    for b in order
                ]
            )
    return FitResult(
        names=tuple(order),
        values=tuple(values),
        initial_values=tuple(initial),
        status=lm.status,
        message=lm.message,
        units=tuple(units.get(n) for n in order),
        fixed=tuple(n not in index for n in order),
        stderr=tuple(stderr),
        ci95=tuple(ci95),
        correlation=tuple(tuple(r) for r in correlation),
        cost=finite(lm.cost),
        iterations=lm.iterations,
        cost_history=lm.cost_history,
        mu_history=lm.mu_history,
        warnings=tuple(notes),
        seed=seed,
        settings=settings or {},
        starts=starts or {},
        trajectories=trajectories or {},
        nonlinear_weights=nonlinear_weights or {},
    )

"""A record's initial state estimated from its first n samples (``--init-window n``).

The public nonlinear benchmarks score a model on a test record whose initial state is unknown: the model may
use the record's first n samples (EMPS 20, CED 4, Cascaded Tanks 5) to set its state, then runs free; the
scored rows start at n. Here the identified parameters stay fixed and only the states are fitted: the value
before the first step of every integrator neuron (a neuron fed back to itself through a delay: w1, dphi, w2 of
the two-mass chart), by Levenberg-Marquardt on the first n rows of the aligned record.

The Jacobian of those few rows with respect to the few states comes from central finite differences (two
short simulations per state; relative step 1e-6, truncation and rounding errors about 1e-10 relative), not from
RTRL: the kernel differentiates with respect to weights only. Tests compare the estimate with the known state
of a continuous plant started in motion and with scipy's least_squares on the same residual.
Per-record parameters (`per_record: true`) have no value of their own on a validation record: they are fitted
here with the states (same LM, same finite differences), the shared parameters staying fixed.
Other delayed neurons (a friction or torque read one step late) keep the chart's history: their one-step
inconsistency with the fitted states is absorbed by the fit of the states.

Layer: identify (below it: fit, network, data).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ... import rules
from ...data.csvdata import Dataset
from ...errors import SdnnError
from ...fit.lm import LMOptions, levenberg_marquardt
from ...fit.uncertainty import covariance
from ...network.alignment import run_aligned
from ...network.flat import KIND_NEURON, signal_names
from .problem import columns_of

__all__ = ["InitialStateFit", "state_neurons", "estimate_initial_state", "FD_STEP"]

#: Relative step of the central differences (times max(1, |state|)).
FD_STEP = rules.value("fd_step")
# the states' own fit: few unknowns and few rows, converged long before this
_OPTIONS = LMOptions(max_iter=rules.value("initstate_max_iter"), tau=rules.value("initstate_tau"), scale="jac",
                     min_rel_cost_change=rules.value("initstate_min_rel_cost_change"))


@dataclass(frozen=True, eq=False)
class InitialStateFit:
    """The fitted initial state of one record.

    Attributes
    ----------
    window : int                 rows fitted (the record's first `window` rows); scored rows start there
    values : {state: float}      each integrator's value before the first step
    stderr : {state: float|None} standard errors from the window's residual variance (None: not determined)
    history : ndarray            every neuron's value before the first step, for CompiledNetwork.simulate
    cost : float                 1/2 sum of squared errors on the window
    status : str                 the LM status of the states' fit
    parameters : {name: float}   per-record parameters fitted on the window with the states (else empty)
    parameter_stderr : {name: float|None}
    theta : ndarray|None         the theta the record runs with (the fitted per-record values in it)
    """

    window: int
    values: dict[str, float]
    stderr: dict[str, float | None]
    history: np.ndarray
    cost: float
    status: str
    parameters: dict[str, float] = field(default_factory=dict)
    parameter_stderr: dict[str, float | None] = field(default_factory=dict)
    theta: np.ndarray | None = None

    def to_dict(self) -> dict:
        out = {"window": self.window, "values": dict(self.values), "stderr": dict(self.stderr),
               "cost": self.cost, "status": self.status,
               "method": "Levenberg-Marquardt on the window, central finite differences, parameters fixed"}
        if self.parameters:
            out["parameters"] = dict(self.parameters)
            out["parameter_stderr"] = dict(self.parameter_stderr)
            out["method"] = ("Levenberg-Marquardt on the window, central finite differences, shared parameters "
                             "fixed, per-record parameters fitted with the states")
        return out


def state_neurons(compiled) -> list[tuple[int, str]]:
    """(global neuron, signal name) of every neuron fed back to itself through a delay: the integrators."""
    flat = compiled.flat
    names = signal_names(compiled.net)
    out = []
    for k in range(flat.n_neurons):
        s = slice(flat.conn_ptr[k], flat.conn_ptr[k + 1])
        if np.any((flat.conn_kind[s] == KIND_NEURON) & (flat.conn_src[s] == k) & (flat.conn_delay[s] > 0)):
            out.append((k, names[k]))
    return out


def estimate_initial_state(compiled, theta, data: Dataset, alignment: str, window: int,
                           init=None, params=()) -> InitialStateFit:
    """Fit the integrators' initial values of `data` on its first `window` rows with `theta` fixed.

    The start is the chart's initial state (`init`: the data-initialised outputs), with every measured output
    that is itself an integrator started at its first sample. `params` (names in ``compiled.names``: the
    per-record parameters) are fitted together with the states, from their values in `theta`.
    """
    if window > data.n_rows or window < 1:
        raise SdnnError.at("DATA004", f"the initial-state window of {window} samples needs at least {window} rows "
                           f"of data, the record has {data.n_rows}", data.path,
                           hint="give a smaller --init-window")
    theta = np.asarray(theta, dtype=float)
    states = state_neurons(compiled)
    u = columns_of(data, compiled.input_names)[:window]
    y = columns_of(data, compiled.output_names)[:window]
    base = compiled.initial_history(init, theta)
    measured = {int(k): i for i, k in enumerate(compiled.flat.output_index)}
    for k, _ in states:
        if k in measured:
            base[k] = y[0, measured[k]]
    names = tuple(name for _, name in states)
    index = np.array([k for k, _ in states], dtype=np.int64)
    params = tuple(params)
    where = np.array([compiled.names.index(p) for p in params], dtype=np.int64)
    n = len(names)

    def history(s: np.ndarray) -> np.ndarray:
        h = base.copy()
        h[index] = s[:n]
        return h

    def theta_of(s: np.ndarray) -> np.ndarray:
        t = theta.copy()
        t[where] = s[n:]
        return t

    def residual(s: np.ndarray):
        with np.errstate(all="ignore"):
            yhat = run_aligned(compiled, theta_of(s), u, alignment, history=history(s))
        e = (y - yhat).ravel()
        return e if np.all(np.isfinite(e)) else None

    def fun(s: np.ndarray):
        e = residual(s)
        if e is None:
            return None
        jac = np.empty((e.size, s.size))
        for i in range(s.size):
            step = FD_STEP * max(1.0, abs(s[i]))
            up, down = s.copy(), s.copy()
            up[i] += step
            down[i] -= step
            eu, ed = residual(up), residual(down)
            if eu is None or ed is None:
                return None
            jac[:, i] = (ed - eu) / (2 * step)  # d yhat / d s = -d e / d s
        return e, jac

    s0 = np.concatenate([base[index], theta[where]])
    if not names and not params:
        e = residual(s0)
        cost = float("nan") if e is None else 0.5 * float(e @ e)
        return InitialStateFit(window, {}, {}, base, cost, "nothing_to_fit", theta=theta)
    r = levenberg_marquardt(fun, s0, names + params, options=_OPTIONS, residual=residual)
    stderr = _stderr(r.jac, r.residual, names + params)
    x = np.asarray(r.x, dtype=float)
    return InitialStateFit(window, dict(zip(names, (float(v) for v in x[:n]), strict=True)),
                           {k: stderr[k] for k in names}, history(x), float(r.cost), r.status,
                           dict(zip(params, (float(v) for v in x[n:]), strict=True)), {k: stderr[k] for k in params},
                           theta_of(x))


def _stderr(jac: np.ndarray, e: np.ndarray, names) -> dict[str, float | None]:
    """sigma^2 (JᵀJ)⁻¹ as for the parameters (fit.uncertainty); None where the window cannot tell."""
    if jac.shape[0] <= len(names):
        return dict.fromkeys(names)
    cov = covariance(jac, e, names=names)
    if not cov.available:
        return dict.fromkeys(names)
    return {n: (float(v) if np.isfinite(v) else None) for n, v in zip(names, cov.stderr, strict=True)}

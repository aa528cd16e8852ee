"""Quasi-online Levenberg-Marquardt with a sliding window (paper section 3.1, Tables 1-2, Figs. 8-9).

The model runs free alongside the record with the current parameters; RTRL gives each new sample's Jacobian
row; a FIFO window keeps the last Q rows and the running sums of the normal equations; one LM step every
``every`` samples. The whole time loop is one numba kernel (:mod:`flowchart2sdnn.network.online_kernel`,
whose docstring states the algorithm, the first-order correction of the stale window errors and the mu
rule); this module validates the arguments, runs the kernel in chunks (progress callback, Ctrl-C between
chunks) and packs the result. Memory is O(Q P + K P) whatever the record length, plus the decimated records.

The reported estimate is the mean of the parameters over the last K = ``average`` LM steps and the reported
error the mean window cost over the same steps, as in the paper's tables.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..network import online_kernel as ok
from ..network.runtime import CompiledNetwork
from .transforms import Bounds

__all__ = ["OnlineOptions", "OnlineResult", "quasi_online", "STATUS_MESSAGES"]

#: Status code -> message; ``OnlineResult.message`` starts with one of these.
STATUS_MESSAGES: dict[str, str] = {
    "completed": "the record was processed to its end",
    "not_started": "the record ended before `start`: no LM step was taken",
    "diverged_at_start": "the model diverged (no finite output) at the start values before identification "
    "began; choose other start values",
    "callback_stop": "stopped by the callback",
    "interrupted": "interrupted (KeyboardInterrupt); the estimate so far is returned",
}


@dataclass(frozen=True)
class OnlineOptions:
    """Settings of :func:`quasi_online` (sizes in samples).

    window : Q, samples in the sliding window (paper: 25000).
    every : one LM step every `every` samples (paper: 1).
    average : K, the estimate is the mean over the last K LM steps (paper: 25000).
    start : first sample with an LM step (paper: 5 s = 5000); rows are collected from sample 0.
    mu0, mu_inc, mu_dec, mu_min, mu_max : damping schedule (trainlm names), applied once per `block`.
    record_every : decimation of the parameter and cost records.
    block : samples per accept/reject test of the mu rule (see :mod:`flowchart2sdnn.network.online_kernel`).
    chunk : samples per kernel call (progress callback and Ctrl-C act between chunks).
    """

    window: int = 25000
    every: int = 1
    average: int = 25000
    start: int = 0
    mu0: float = 1e-3
    mu_inc: float = 10.0
    mu_dec: float = 0.1
    mu_max: float = 1e10
    mu_min: float = 1e-12
    record_every: int = 100
    block: int = 1000
    chunk: int = 5000

    def __post_init__(self) -> None:
        for name, low in (("window", 1), ("every", 1), ("average", 1), ("start", 0), ("record_every", 1),
                          ("block", 1), ("chunk", 1)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
                raise ValueError(f"`{name}` must be an int >= {low}, got {value!r}")
        for name in ("mu0", "mu_inc", "mu_dec", "mu_min", "mu_max"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"`{name}` must be finite, got {getattr(self, name)}")
        if not 0 < self.mu_min <= self.mu0 <= self.mu_max:
            raise ValueError("need 0 < `mu_min` <= `mu0` <= `mu_max`")
        if not self.mu_inc > 1:
            raise ValueError(f"`mu_inc` must be > 1, got {self.mu_inc}")
        if not 0 < self.mu_dec < 1:
            raise ValueError(f"`mu_dec` must be in (0, 1), got {self.mu_dec}")


@dataclass(frozen=True, eq=False)
class OnlineResult:
    """Outcome of :func:`quasi_online`; arrays are read-only and never hold NaN.

    Attributes
    ----------
    names : tuple of str                 theta order
    theta_mean : ndarray (P,)            mean of the external parameters over the last `averaged_steps` steps
    theta_final : ndarray (P,)           parameters after the last processed sample
    steps : int                          LM steps taken
    status, message : str                a key of ``STATUS_MESSAGES`` and a sentence with details
    trajectory_time : ndarray (n_rec,)   s, samples ``0, record_every, ...`` times the sample time
    trajectory : ndarray (n_rec, P)      parameters after each recorded sample
    cost_time, cost : ndarray (n_rec,)   window cost E = 1/2 sum of the window's a-priori errors squared
    mean_cost : float                    mean of E over the last `averaged_steps` steps
    mu_trajectory : ndarray (n_rec,)     mu at the recorded samples
    samples : int                        samples processed
    averaged_steps : int                 min(steps, K)
    accepted_blocks, rejected_blocks : int      outcomes of the mu rule
    diverged : int                       divergences (non-finite model or weights) handled
    divergence_time : ndarray            s, the first (at most 1000) divergence times
    chol_fallbacks, skipped_steps : int  steps solved with a larger mu / not solvable at any mu <= mu_max
    mu_final : float
    """

    names: tuple[str, ...]
    theta_mean: np.ndarray
    theta_final: np.ndarray
    steps: int
    status: str
    message: str
    trajectory_time: np.ndarray
    trajectory: np.ndarray
    cost_time: np.ndarray
    cost: np.ndarray
    mean_cost: float
    mu_trajectory: np.ndarray
    samples: int
    averaged_steps: int
    accepted_blocks: int
    rejected_blocks: int
    diverged: int
    divergence_time: np.ndarray
    chol_fallbacks: int
    skipped_steps: int
    mu_final: float


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _check_targets(targets, n_samples: int, compiled: CompiledNetwork) -> np.ndarray:
    try:
        y = np.ascontiguousarray(targets, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"targets must be a numeric array: {exc}") from None
    if y.ndim == 1 and compiled.n_outputs == 1:
        y = y[:, None].copy()
    if y.shape != (n_samples, compiled.n_outputs):
        raise ValueError(f"targets has shape {y.shape}, expected ({n_samples}, {compiled.n_outputs}) with "
                         f"columns {list(compiled.output_names)}")
    bad = ~np.isfinite(y)
    if bad.any():
        q, i = np.argwhere(bad)[0]
        raise ValueError(f"targets contain {int(bad.sum())} non-finite value(s), first at sample {q} of "
                         f"{compiled.output_names[i]!r}")
    return y


def _bound_codes(bounds: Bounds) -> np.ndarray:
    lo, hi = np.isfinite(bounds.lower), np.isfinite(bounds.upper)
    codes = np.where(lo & hi, 3, np.where(lo, 1, np.where(hi, 2, 0)))
    return codes.astype(np.int64)


def quasi_online(
    compiled: CompiledNetwork,
    inputs: np.ndarray,
    targets: np.ndarray,
    theta0: Sequence[float] | np.ndarray | None = None,
    lower: Sequence[float] | np.ndarray | float | None = None,
    upper: Sequence[float] | np.ndarray | float | None = None,
    options: OnlineOptions = OnlineOptions(),
    init: Mapping[str, float] | None = None,
    callback: Callable[[float], bool | None] | None = None,
) -> OnlineResult:
    """Identify theta quasi-online: sliding-window LM with RTRL rows (paper section 3.1).

    Parameters
    ----------
    compiled : CompiledNetwork
        The model; theta is ``compiled.names``.
    inputs : (L, n_inputs) array_like
        The record's inputs.
    targets : (L, n_outputs) array_like
        The measured outputs (a 1-D array for one output).
    theta0 : (P,) array_like, optional
        Start values (external); default ``compiled.theta0()``.
    lower, upper : (P,) array_like, scalar or None
        Bounds (``-inf``/``inf``/None for none), enforced by the transform of :mod:`.transforms`.
    options : OnlineOptions
    init : mapping, optional
        Output name -> value for states initialised from data.
    callback : callable ``callback(progress_fraction) -> bool | None``, optional
        Called after each chunk with the fraction of the record processed; True stops the run.

    Returns
    -------
    OnlineResult
        Whatever happens (divergence, Ctrl-C between chunks), finite values within bounds.
    """
    opt = options
    u_in = compiled._check_inputs(inputs)
    n_samples = u_in.shape[0]
    y = _check_targets(targets, n_samples, compiled)
    names = compiled.names
    x0 = compiled.theta0() if theta0 is None else np.array(theta0, dtype=float).reshape(-1)
    if x0.shape != (compiled.n_theta,):
        raise ValueError(f"`theta0` has {x0.size} entries, expected {compiled.n_theta} for {list(names)}")
    bounds = Bounds.make(names, lower, upper)
    bounds.check(x0, "theta0")
    history = compiled._history(init)
    flat = compiled._flat
    prog = ok.weight_program(compiled)
    state = ok.new_state(bounds.start(x0), prog.n_connections, prog.n_slots, history, flat.ring, opt.window,
                         compiled.n_outputs, opt.average, opt.mu0)
    net = (flat.conn_ptr, flat.conn_kind, flat.conn_src, flat.conn_delay, flat.transfer, compiled._dptr,
           compiled._dtheta, flat.output_index)
    bnd = (_bound_codes(bounds), np.array(bounds.lower, dtype=float), np.array(bounds.upper, dtype=float))
    fopt = np.array([opt.mu_inc, opt.mu_dec, opt.mu_min, opt.mu_max], dtype=float)
    iopt = np.array([opt.start, opt.every, opt.block, opt.record_every, prog.stack], dtype=np.int64)
    n_rec = -(-n_samples // opt.record_every)
    rec_x = np.zeros((n_rec, compiled.n_theta))
    rec_cost = np.zeros(n_rec)
    rec_mu = np.zeros(n_rec)

    status = None
    done = 0
    if not ok.set_params(state.model(), bnd, prog.exprs, np.empty(prog.stack)):
        status = "diverged_at_start"
    try:
        while status is None and done < n_samples:
            end = min(done + opt.chunk, n_samples)
            code = ok.online_chunk(done, end, u_in, y, net, prog.exprs, bnd, fopt, iopt, state.model(),
                                   state.window(), (state.avg_x, state.avg_cost), state.fs, state.its,
                                   state.div_t, rec_x, rec_cost, rec_mu)
            done = int(state.its[ok.I_NEXT])  # from the state: exact even if Ctrl-C lands right here
            if code == ok.STATUS_DIVERGED_BEFORE_START:
                status = "diverged_at_start"
                break
            if callback is not None and callback(done / n_samples) and done < n_samples:
                status = "callback_stop"
        if status is None:
            status = "completed" if n_samples > opt.start else "not_started"
    except KeyboardInterrupt:
        status = "interrupted"
        done = int(state.its[ok.I_NEXT])
    return _result(compiled, bounds, x0, state, status, done, rec_x, rec_cost, rec_mu, opt)


def _result(compiled, bounds, x0, state, status, done, rec_x, rec_cost, rec_mu, opt) -> OnlineResult:
    its = state.its
    steps = int(its[ok.I_STEPS])
    n_avg = min(steps, opt.average)
    if status == "diverged_at_start":
        x_final = np.array(x0, dtype=float)
    else:
        x_final = bounds.to_external(state.u)
    if n_avg > 0:
        theta_mean = state.avg_x[:n_avg].mean(axis=0)
        mean_cost = float(state.avg_cost[:n_avg].mean())
    else:
        theta_mean = x_final
        mean_cost = 0.5 * max(float(state.fs[ok.F_EE]), 0.0)
    # the bounds hold for every averaged value, hence for the mean; clip only the rounding of the average
    theta_mean = np.clip(theta_mean, bounds.lower, bounds.upper)
    n_rec = -(-done // opt.record_every)
    T = float(compiled.net.sample_time)
    times = np.arange(n_rec) * opt.record_every * T
    mu = float(state.fs[ok.F_MU])
    message = (f"{STATUS_MESSAGES[status]} ({steps} LM steps over {done} samples; mean window cost "
               f"{mean_cost:.6g} over the last {n_avg} steps; mu {mu:.3g}; blocks accepted "
               f"{int(its[ok.I_ACCEPTED])}, rejected {int(its[ok.I_REJECTED])}; divergences "
               f"{int(its[ok.I_DIVERGED])})")
    return OnlineResult(
        names=compiled.names,
        theta_mean=_readonly(theta_mean),
        theta_final=_readonly(x_final),
        steps=steps,
        status=status,
        message=message,
        trajectory_time=_readonly(times),
        trajectory=_readonly(rec_x[:n_rec]),
        cost_time=_readonly(times),
        cost=_readonly(rec_cost[:n_rec]),
        mean_cost=mean_cost,
        mu_trajectory=_readonly(rec_mu[:n_rec]),
        samples=done,
        averaged_steps=n_avg,
        accepted_blocks=int(its[ok.I_ACCEPTED]),
        rejected_blocks=int(its[ok.I_REJECTED]),
        diverged=int(its[ok.I_DIVERGED]),
        divergence_time=_readonly(state.div_t[: int(its[ok.I_N_DIV_T])] * T),
        chol_fallbacks=int(its[ok.I_CHOL_FALLBACK]),
        skipped_steps=int(its[ok.I_SKIPPED]),
        mu_final=mu,
    )

"""Quasi-online Levenberg-Marquardt with a sliding window (paper section 3.1, Tables 1-2, Figs. 8-9).

The model runs free alongside the record with the accepted parameters; RTRL gives each new sample's
Jacobian row; a FIFO window keeps the last Q rows and the running sums of the normal equations. Two ways to
step (the numba kernel :mod:`.kernel` states both and why):

* window mode (``tries >= 1``, default): every ``block`` samples one trainlm iteration on the window, each
  trial judged by simulating the window's samples again at it, an accepted trial relinearising the window
  (so every iteration is an exact LM iteration on the last Q samples, from past data only);
* trial mode (``tries = 0``, the earlier algorithm): one LM step every ``every`` samples on the rows as they
  were linearised (corrected to first order), a second network copy simulating the trial, accepted or
  refused every ``block`` samples by a linearity test.

This module validates the arguments, runs the kernel in chunks (progress callback, Ctrl-C between chunks) and
packs the result. Memory is O(Q (P + N) + K P) whatever the record length (N: the network's nodes), plus the
decimated records and, with sub-steps, the inputs held per network step (substeps x the record's inputs).

Sub-steps (a network of ``substeps`` > 1, issue 13): every sample runs that many network steps with its input
held (as :meth:`~flowchart2sdnn.network.runtime.CompiledNetwork.simulate`), RTRL through all of them; the
sample's row (J, e) is read at its last step, the window stores the state at sample boundaries and simulates
its samples again step by step. Sizes and times (window, block, start, ...) stay in samples.

The reported estimate is the mean of the accepted parameters over the last K = ``average`` steps (window
mode: samples) and the reported error the mean window cost over the same steps, as in the paper's Tables 1
and 2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ...errors import SdnnError
from ...fit.damping import TRAINLM_MU0
from ...fit.transforms import Bounds
from ...network.runtime import CompiledNetwork
from ..settings import ONLINE_TAU
from . import kernel as ok

__all__ = ["OnlineOptions", "OnlineResult", "OnlineRun", "OnlineStart", "quasi_online", "STATUS_MESSAGES"]

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
    every : trial mode: one LM step every `every` samples (paper: 1).
    average : K, the estimate is the mean over the last K steps (paper: 25000); window mode: samples.
    start : first sample with an LM step (paper: 5 s = 5000); rows are collected from sample 0.
    mu0, mu_inc, mu_dec, mu_min, mu_max : damping schedule (trainlm names): mu is multiplied by mu_dec when a
        trial is accepted, by mu_inc when it is refused or diverges.
    record_every : decimation of the parameter and cost records.
    block : window mode: samples between LM iterations once the window is full (while it fills,
        ``max(min_block, block * rows / window)``); trial mode: samples per accept/refuse test of the trial,
        at most one accepted LM iterate per block.
    chunk : samples per kernel call (progress callback and Ctrl-C act between chunks).
    tries : window mode: LM trials per iteration (trainlm retries with mu *= mu_inc after a refusal);
        0 selects the trial mode.
    min_block : window mode: fewest samples between two iterations while the window fills.
    tau : window mode: the first damping is ``max(mu0, tau * max diag(JᵀJ))`` on the window (as
        ``LMOptions.tau`` of fit/lm.py); 0 keeps mu0.

    The defaults of the window mode (tries 2, block 500, min_block 200, tau 1) are those that met the paper
    experiment's acceptance from three of its four starts (docs/paper_experiment.md).
    """

    window: int = 25000
    every: int = 1
    average: int = 25000
    start: int = 0
    mu0: float = TRAINLM_MU0
    mu_inc: float = 10.0
    mu_dec: float = 0.1
    mu_max: float = 1e10
    mu_min: float = 1e-12
    record_every: int = 100
    block: int = 500
    chunk: int = 5000
    tries: int = 2
    min_block: int = 200
    tau: float = ONLINE_TAU

    def __post_init__(self) -> None:
        for name, low in (("window", 1), ("every", 1), ("average", 1), ("start", 0), ("record_every", 1),
                          ("block", 1), ("chunk", 1), ("tries", 0), ("min_block", 1)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
                raise ValueError(f"`{name}` must be an int >= {low}, got {value!r}")
        for name in ("mu0", "mu_inc", "mu_dec", "mu_min", "mu_max", "tau"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"`{name}` must be finite, got {getattr(self, name)}")
        if not 0 < self.mu_min <= self.mu0 <= self.mu_max:
            raise ValueError("need 0 < `mu_min` <= `mu0` <= `mu_max`")
        if not self.tau >= 0:
            raise ValueError(f"`tau` must be >= 0, got {self.tau}")
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
    theta_mean : ndarray (P,)            mean of the accepted parameters (external) over the last
                                         `averaged_steps` LM steps
    theta_final : ndarray (P,)           accepted parameters after the last processed sample
    steps : int                          trial mode: LM steps (solves) attempted, one per `every` samples
                                         from `start`; window mode: samples from `start`
    status, message : str                a key of ``STATUS_MESSAGES`` and a sentence with details
    trajectory_time : ndarray (n_rec,)   s, samples ``0, record_every, ...`` times the sample time
    trajectory : ndarray (n_rec, P)      accepted parameters after each recorded sample
    cost_time, cost : ndarray (n_rec,)   window cost E = 1/2 sum of the window's a-priori errors squared
    mean_cost : float                    mean of E over the last `averaged_steps` steps
    mu_trajectory : ndarray (n_rec,)     mu at the recorded samples
    samples : int                        samples processed
    averaged_steps : int                 min(steps, K)
    accepted_blocks, rejected_blocks : int      trials accepted / refused (a diverged trial counts as refused)
    diverged : int                       divergences handled (non-finite model, trial or weights)
    divergence_time : ndarray            s, the first (at most 1000) divergence times
    chol_fallbacks, skipped_steps : int  steps solved with a larger damping (rounding) / not solvable
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


@dataclass(frozen=True, eq=False)
class OnlineStart:
    """One quasi-online run of a multi-start, seen as :func:`~flowchart2sdnn.fit.multistart.run_multistart`
    compares runs: its cost is the mean window cost over the last K steps (the paper's error of a run, known
    online at the end of the record), its point the averaged estimate.
    """

    result: OnlineResult

    @property
    def cost(self) -> float:
        return math.inf if self.result.status == "diverged_at_start" else float(self.result.mean_cost)

    @property
    def x(self) -> np.ndarray:
        return self.result.theta_mean

    @property
    def names(self) -> tuple[str, ...]:
        return self.result.names

    @property
    def status(self) -> str:
        return self.result.status

    @property
    def interrupted(self) -> bool:
        return self.result.status in ("interrupted", "callback_stop")

    @property
    def cost_history(self) -> tuple[float, ...]:
        # the scale below which costs count as an exact fit: the largest window cost of the run
        return (float(self.result.cost.max()),) if self.result.cost.size else ()


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _checked(a, what: str, columns: tuple[str, ...], n_samples: int | None) -> np.ndarray:
    """`a` as a C-contiguous float (L, len(columns)) array (a view when possible), finite.

    The finiteness check runs in slices so that no temporary grows with the record length.
    """
    try:
        arr = np.ascontiguousarray(a, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} must be a numeric array: {exc}") from None
    if arr.ndim == 1 and len(columns) == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] != len(columns) or (n_samples is not None and arr.shape[0] != n_samples):
        rows = "L" if n_samples is None else str(n_samples)
        raise ValueError(f"{what} has shape {arr.shape}, expected ({rows}, {len(columns)}) with columns "
                         f"{list(columns)}")
    if arr.shape[0] == 0:
        raise ValueError(f"{what} has no samples")
    for start in range(0, arr.shape[0], _SLICE):
        part = arr[start:start + _SLICE]
        bad = ~np.isfinite(part)
        if bad.any():
            q, i = np.argwhere(bad)[0]
            raise ValueError(f"{what} contain a non-finite value at sample {start + q} of {columns[i]!r}")
    return arr


_SLICE = 65536


def _bound_codes(bounds: Bounds) -> np.ndarray:
    lo, hi = np.isfinite(bounds.lower), np.isfinite(bounds.upper)
    codes = np.where(lo & hi, 3, np.where(lo, 1, np.where(hi, 2, 0)))
    return codes.astype(np.int64)


class OnlineRun:
    """A quasi-online run that can be advanced sample by sample (what :func:`quasi_online` drives).

    Validates the arguments (see :func:`quasi_online`) and allocates the state; :meth:`advance` runs the
    kernel, :meth:`result` packs an :class:`OnlineResult`. Exposed for tests and tools that inspect the
    window (:attr:`state`) or the current trial (:meth:`trial_theta`); :attr:`net` holds the flat network's
    arrays in the order the kernel takes them, then its sub-steps N; :attr:`step_inputs` the input of every
    network step (:attr:`inputs` itself when N = 1), which the kernel functions take as `inputs`.
    """

    def __init__(self, compiled: CompiledNetwork, inputs, targets, theta0=None, lower=None, upper=None,
                 options: OnlineOptions = OnlineOptions(), init: Mapping[str, float] | None = None) -> None:
        opt = options
        self.compiled = compiled
        self.options = opt
        self.inputs = _checked(inputs, "inputs", compiled.input_names, None)
        self.n_samples = self.inputs.shape[0]
        # sub-steps: the kernel reads one input row per network step, each sample held over its N steps (the
        # zero-order hold of Runtime.simulate); N = 1 passes the record itself
        n_sub = compiled.substeps
        if compiled.fitted_delays:
            raise SdnnError.at("FIT007", "quasi-online identification cannot fit an input's dead time (its "
                               "sensitivity enters through the input, which the window kernel does not carry)",
                               compiled.net.name, hint="identify offline, or give the delay as a number")
        # a linear or delayed input: each step's mean over it (network.inputsignal), as the offline kernels see it
        self.step_inputs = compiled.step_inputs(self.inputs) if compiled.shaped_inputs else \
            self.inputs if n_sub == 1 else np.repeat(self.inputs, n_sub, axis=0)
        self.targets = _checked(targets, "targets", compiled.output_names, self.n_samples)
        names = compiled.names
        x0 = compiled.theta0() if theta0 is None else np.array(theta0, dtype=float).reshape(-1)
        if x0.shape != (compiled.n_theta,):
            raise ValueError(f"`theta0` has {x0.size} entries, expected {compiled.n_theta} for {list(names)}")
        self.bounds = Bounds.make(names, lower, upper)
        self.bounds.check(x0, "theta0")
        self.x0 = x0
        flat = compiled.flat
        self.program = ok.weight_program(compiled)
        prog = self.program
        self.state = ok.new_state(self.bounds.start(x0), prog.n_connections, prog.n_slots,
                                  compiled.initial_history(init), flat.ring, opt.window, compiled.n_outputs,
                                  opt.average, opt.mu0, replay=opt.tries > 0)
        self.net = (flat.conn_ptr, flat.conn_kind, flat.conn_src, flat.conn_delay, flat.transfer,
                     compiled.weights.conn_slots, compiled.weights.slot_theta, flat.output_index,
                    np.array([n_sub], dtype=np.int64))  # an array: the tuple stays uniform
        self._bnd = (_bound_codes(self.bounds), np.array(self.bounds.lower, dtype=float),
                     np.array(self.bounds.upper, dtype=float))
        self._fopt = np.array([opt.mu_inc, opt.mu_dec, opt.mu_min, opt.mu_max, opt.tau], dtype=float)
        self._iopt = np.array([opt.start, opt.every, opt.block, opt.record_every, prog.stack, opt.tries,
                               opt.min_block], dtype=np.int64)
        n_rec = -(-self.n_samples // opt.record_every)
        self._rec_x = np.zeros((n_rec, compiled.n_theta))
        self._rec_cost = np.zeros(n_rec)
        self._rec_mu = np.zeros(n_rec)
        self.diverged_at_start = not ok.prepare(self.state.model(), self.state.trial(), self._bnd, prog.exprs,
                                                np.empty(prog.stack))

    @property
    def done(self) -> int:
        """Samples processed so far."""
        return int(self.state.its[ok.I_NEXT])

    def advance(self, end: int) -> bool:
        """Process the samples up to `end` (exclusive). False when the model diverged before `start`."""
        if self.diverged_at_start:
            return False
        st = self.state
        code = ok.online_chunk(self.done, min(int(end), self.n_samples), self.step_inputs, self.targets, self.net,
                               self.program.exprs, self._bnd, self._fopt, self._iopt, st.model(), st.trial(),
                               st.window(), st.replay(), (st.avg_x, st.avg_cost), st.fs, st.its, st.div_t, self._rec_x,
                               self._rec_cost, self._rec_mu)
        if code == ok.STATUS_DIVERGED_BEFORE_START:
            self.diverged_at_start = True
            return False
        return True

    def theta(self) -> np.ndarray:
        """The accepted parameters (external)."""
        return self.x0.copy() if self.diverged_at_start else self.bounds.to_external(self.state.u)

    def trial_theta(self) -> np.ndarray:
        """Trial mode: the current trial parameters (external), one LM step from :meth:`theta` on the current
        window (window mode: :meth:`theta` between iterations)."""
        return self.bounds.to_external(self.state.u_tr)

    def result(self, status: str) -> OnlineResult:
        """Pack the run so far as an :class:`OnlineResult` with `status` (a key of ``STATUS_MESSAGES``)."""
        return _result(self, status)


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
        Called after each chunk of ``options.chunk`` samples with the fraction of the record processed;
        returning True stops the run.

    Returns
    -------
    OnlineResult
        Whatever happens (divergence, Ctrl-C between chunks), finite values within bounds.

    Raises
    ------
    ValueError
        Bad shapes, non-finite data, `theta0` outside the bounds, a missing data-initialised state.
    """
    run = OnlineRun(compiled, inputs, targets, theta0, lower, upper, options, init)
    status = None
    try:
        while status is None and run.done < run.n_samples:
            if not run.advance(run.done + options.chunk):
                status = "diverged_at_start"
            elif callback is not None and callback(run.done / run.n_samples) and run.done < run.n_samples:
                status = "callback_stop"
        if run.diverged_at_start:
            status = "diverged_at_start"
        elif status is None:
            status = "completed" if run.n_samples > options.start else "not_started"
    except KeyboardInterrupt:
        status = "interrupted"
    return run.result(status)


def _result(run: OnlineRun, status: str) -> OnlineResult:
    st, opt, bounds = run.state, run.options, run.bounds
    its = st.its
    done = run.done
    steps = int(its[ok.I_STEPS])
    n_avg = min(steps, opt.average)
    x_final = run.theta()
    if n_avg > 0:
        theta_mean = st.avg_x[:n_avg].mean(axis=0)
        mean_cost = float(st.avg_cost[:n_avg].mean())
    else:
        theta_mean = x_final
        mean_cost = 0.5 * max(float(st.fs[ok.F_EE]), 0.0)
    # every averaged value lies within the bounds, so does the mean; clip only the rounding of the average
    theta_mean = np.clip(theta_mean, bounds.lower, bounds.upper)
    n_rec = -(-done // opt.record_every)
    T = float(run.compiled.net.sample_time)
    times = np.arange(n_rec) * opt.record_every * T
    mu = float(st.fs[ok.F_MU])
    what = "LM steps" if opt.tries == 0 else "samples with LM iterations on the window"
    message = (f"{STATUS_MESSAGES[status]} ({steps} {what} over {done} samples; mean window cost "
               f"{mean_cost:.6g} over the last {n_avg} steps; mu {mu:.3g}; trials accepted "
               f"{int(its[ok.I_ACCEPTED])}, refused {int(its[ok.I_REJECTED])}; divergences "
               f"{int(its[ok.I_DIVERGED])})")
    return OnlineResult(
        names=run.compiled.names,
        theta_mean=_readonly(theta_mean),
        theta_final=_readonly(x_final),
        steps=steps,
        status=status,
        message=message,
        trajectory_time=_readonly(times),
        trajectory=_readonly(run._rec_x[:n_rec]),
        cost_time=_readonly(times),
        cost=_readonly(run._rec_cost[:n_rec]),
        mean_cost=mean_cost,
        mu_trajectory=_readonly(run._rec_mu[:n_rec]),
        samples=done,
        averaged_steps=n_avg,
        accepted_blocks=int(its[ok.I_ACCEPTED]),
        rejected_blocks=int(its[ok.I_REJECTED]),
        diverged=int(its[ok.I_DIVERGED]),
        divergence_time=_readonly(st.div_t[: int(its[ok.I_N_DIV_T])] * T),
        chol_fallbacks=int(its[ok.I_CHOL_FALLBACK]),
        skipped_steps=int(its[ok.I_SKIPPED]),
        mu_final=mu,
    )

"""Run a :class:`Network`: simulation and the exact Jacobian of its outputs by RTRL.

theta and the connection values with their sparse derivatives come from :class:`~.theta.ThetaNetwork` (the
chain rule through each weight's coef, taken once), which the kernels of :mod:`.kernels` consume.
:attr:`CompiledNetwork.weights` publishes these tables (:class:`WeightTable`) for other evaluators of the
weights (:mod:`.weight_program`).
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Mapping, Sequence

import numpy as np

from .flat import FlatNetwork, signal_names
from .inputsignal import step_inputs
from .kernels import jacobian_kernel, jacobian_pieces_kernel, simulate_kernel, simulate_pieces_kernel
from .model import Network
from .theta import ThetaNetwork, WeightTable

__all__ = ["CompiledNetwork", "WeightTable"]

#: step-input arrays of shaped inputs kept per network (records x recent dead times)
STEP_CACHE = 8


class CompiledNetwork(ThetaNetwork):
    """A network ready to simulate and differentiate.

    Parameters
    ----------
    net : Network
        The network file.
    free : sequence of str, optional
        Names of the quantities to put in theta (parameters and/or free weights, none fixed). Default: every
        non-fixed parameter, then every non-fixed free weight.

    Attributes
    ----------
    net : Network
    names : tuple of str
        theta order.
    n_inputs, n_outputs : int
    input_names, output_names : tuple of str
    weights : WeightTable
        How the connection values and their derivatives follow from theta.
    """

    def __init__(self, net: Network, free: Sequence[str] | None = None) -> None:
        super().__init__(net, free)
        self.n_inputs = len(net.inputs)
        self.n_outputs = len(net.outputs)
        self.input_names = tuple(i.name for i in net.inputs)
        self.output_names = tuple(o.name for o in net.outputs)
        self._signal_names = signal_names(net)
        # states started at a free parameter (`init: <parameter>`): (global neuron, theta index)
        offsets = self._flat.layer_offset
        self._theta_starts = tuple((int(offsets[s.layer]) + s.neuron, self._theta_param[s.parameter])
                                   for s in net.initial_states if s.parameter in self._theta_param)
        self._step_cache: dict = {}
        self._step_lock = threading.Lock()
        self._linear = np.array([i.intersample == "linear" for i in net.inputs], dtype=bool)
        self._delays = tuple(i.delay for i in net.inputs)
        # input i's dead time is theta[_delay_theta[i]] when fitted (-1: fixed or none)
        self._delay_theta = np.array([self._theta_param.get(d, -1) if d is not None else -1 for d in self._delays],
                                     dtype=np.int64)

    def __getstate__(self) -> dict:
        """Picklable as before the step-input cache: the lock and the cache stay behind."""
        state = self.__dict__.copy()
        state.pop("_step_lock", None)
        state["_step_cache"] = {}
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._step_lock = threading.Lock()

    # ------------------------------------------------------------------ checks
    def _check_inputs(self, inputs) -> np.ndarray:
        try:
            u = np.ascontiguousarray(inputs, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"inputs must be a numeric array: {exc}") from None
        if u.ndim != 2 or u.shape[1] != self.n_inputs:
            raise ValueError(
                f"inputs has shape {u.shape}, expected (Q, {self.n_inputs}) with columns {list(self.input_names)}"
            )
        if u.shape[0] == 0:
            raise ValueError("inputs has no samples (Q = 0)")
        bad = ~np.isfinite(u)
        if bad.any():
            q, i = np.argwhere(bad)[0]
            raise ValueError(
                f"inputs contain {int(bad.sum())} non-finite value(s), first at sample {q} of {self.input_names[i]!r}"
            )
        return u

    @property
    def flat(self) -> FlatNetwork:
        """The flattened network the kernels walk (index arrays, ring buffer length, output rows)."""
        return self._flat

    def initial_history(self, init: Mapping[str, float] | None, theta=None) -> np.ndarray:
        """The delay ring buffer before the first sample: the chart's initial states, the given initial outputs
        (name -> value) for states started from data, and, with `theta`, the states started at a parameter
        (`init: <parameter>`) at theta's value (without it: the parameter's chart value)."""
        if init is not None:
            unknown = sorted(set(init) - set(self.output_names))
            if unknown:
                raise ValueError(
                    f"init: {unknown} are not outputs of {self.net.name!r} ({list(self.output_names)})"
                )
        hist = self._flat.history_with(init)
        if theta is not None:
            theta = np.asarray(theta, dtype=float)
            for k, i in self._theta_starts:
                hist[k] = theta[i]
        return hist

    @property
    def estimates_starts(self) -> bool:
        """Some state starts at a free parameter: a caller that passes its own history must set it."""
        return bool(self._theta_starts)

    # ------------------------------------------------------------------ running
    @property
    def substeps(self) -> int:
        """Network steps per input sample (the network file's `substeps`)."""
        return self.net.substeps

    @property
    def shaped_inputs(self) -> bool:
        """Some input is not simply held over its sample: `intersample: linear` or a dead time."""
        return bool(self._linear.any()) or any(d is not None for d in self._delays)

    @property
    def fitted_delays(self) -> bool:
        """Some input's dead time is a free parameter (its sensitivity enters RTRL through the input)."""
        return bool(np.any(self._delay_theta >= 0))

    def _shifts(self, theta) -> np.ndarray:
        """Each input's dead time in samples at theta."""
        if all(d is None for d in self._delays):
            return np.zeros(self.n_inputs)
        params, _ = self.values(theta) if theta is not None else (self.net.parameter_values(), None)
        out = np.zeros(self.n_inputs)
        for i, d in enumerate(self._delays):
            if d is not None:
                out[i] = (params[d] if d in params else float(d)) / self.net.sample_time
        return out

    def step_inputs(self, u: np.ndarray, theta=None) -> np.ndarray:
        """The input of every network step for samples u (Q, n_inputs) at theta (None: the file's values)."""
        return self._steps(self._check_inputs(u), theta)

    def _steps(self, u: np.ndarray, theta=None, with_derivative: bool = False):
        """The input of every network step: each sample held over its `substeps` steps (zero-order hold), or
        for shaped inputs the signal's mean over the step (network.inputsignal). With `with_derivative`, also
        (in_theta, in_dval) for the kernels: d input / d theta of the inputs whose dead time is fitted.

        The kernels keep the last step of each sample, so outputs, residuals and Jacobian rows exist only at
        the data's samples while RTRL runs through every step.
        """
        if not self.shaped_inputs:
            p = u if self.net.substeps == 1 else np.repeat(u, self.net.substeps, axis=0)
            return (p, None, None) if with_derivative else p
        fitted = with_derivative and self.fitted_delays
        shifts = self._shifts(theta)
        # the trainer asks for the same record at the same dead times many times (simulate, Jacobian, trial
        # steps); building the step inputs cost 0.19 s per call at 30000 samples x 32 sub-steps
        key = (hashlib.blake2b(np.ascontiguousarray(u).tobytes(), digest_size=16).digest(), u.shape,
               shifts.tobytes(), fitted)
        with self._step_lock:  # multiple shooting runs segments on threads
            found = self._step_cache.get(key)
        if found is None:
            found = step_inputs(u, self.net.substeps, self._linear, shifts, with_derivative=fitted)
            with self._step_lock:
                if len(self._step_cache) >= STEP_CACHE:
                    self._step_cache.pop(next(iter(self._step_cache)))
                self._step_cache[key] = found
        p, dp = found
        if not with_derivative:
            return p
        if not fitted:
            return p, None, None
        return p, self._delay_theta, np.ascontiguousarray(dp / self.net.sample_time)

    def _history(self, init, history, theta=None) -> np.ndarray:
        if history is None:
            return self.initial_history(init, theta)
        hist = np.array(history, dtype=float)
        if hist.shape != (self._flat.n_neurons,) or not np.all(np.isfinite(hist)):
            raise ValueError(f"history must be {self._flat.n_neurons} finite values (one per neuron), "
                             f"got shape {hist.shape}")
        return hist

    def _recorded(self, states) -> np.ndarray:
        """The neurons a kernel records: the outputs, then `states` (None: none)."""
        if states is None:
            return self._flat.output_index
        return np.concatenate([self._flat.output_index, np.asarray(states, dtype=np.int64)]).astype(np.int64)

    def _state_sensitivities(self, states) -> tuple[int, np.ndarray | None]:
        """(columns, d history / d (theta, history[states])): theta's P columns, then one per state whose
        history value is a quantity (identity there); None when there are no states."""
        if states is None:
            return self.n_theta, None
        states = np.asarray(states, dtype=np.int64)
        n_theta = self.n_theta + len(states)
        s_init = np.zeros((self._flat.n_neurons, n_theta))
        s_init[states, self.n_theta + np.arange(len(states))] = 1.0
        return n_theta, s_init

    def _run(self, theta, inputs, init, record: np.ndarray, history=None) -> np.ndarray:
        u = self._steps(self._check_inputs(inputs), theta)
        hist = self._history(init, history, theta)
        conn_val, _ = self.connection_values(theta, with_derivatives=False)
        f = self._flat
        return simulate_kernel(
            u, f.conn_ptr, f.conn_kind, f.conn_src, f.conn_delay, conn_val, f.transfer, hist, f.ring, record,
            self.net.substeps,
        )

    def simulate(self, theta, inputs: np.ndarray, init: Mapping[str, float] | None = None,
                 history: np.ndarray | None = None, states: np.ndarray | None = None) -> np.ndarray:
        """Network outputs for `inputs`.

        Parameters
        ----------
        theta : (P,) array_like
        inputs : (Q, n_inputs) array_like
        init : mapping, optional
            Output name -> value, for states initialised from data.
        history : (n_neurons,) array_like, optional
            Every neuron's output before the first step (replaces the file's initial states and `init`):
            an initial state estimated from data (identify.offline.initstate).
        states : (S,) int64, optional
            Neurons whose values follow the outputs' (as in :meth:`jacobian`).

        Returns
        -------
        (Q, n_outputs [+ S]) ndarray, possibly non-finite when theta makes the network unstable.
        """
        return self._run(theta, inputs, init, self._recorded(states), history)

    def jacobian(
        self, theta, inputs: np.ndarray, init: Mapping[str, float] | None = None,
        history: np.ndarray | None = None, states: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs and their exact derivatives with respect to theta (RTRL).

        `history` (every neuron's value before the first step) replaces the initial states as in
        :meth:`simulate`. `states` (S,) int64, optional: neurons whose history values are quantities too (free
        initial states): the derivatives then have P + S columns, the last S with respect to
        ``history[states]``, and the outputs are followed by those neurons' values (the end state of a
        multiple-shooting segment and its sensitivities).

        Returns
        -------
        yhat : (Q, n_outputs [+ S]) ndarray
        dyhat : (Q, n_outputs [+ S], P [+ S]) ndarray
            ``dyhat[t, o, i] = d yhat[t, o] / d theta[i]``.
        """
        u, in_theta, in_dval = self._steps(self._check_inputs(inputs), theta, with_derivative=True)
        hist = self._history(init, history, theta)
        conn_val, dval = self.connection_values(theta, with_derivatives=True)
        f = self._flat
        record = self._recorded(states)
        n_theta, s_init = self._state_sensitivities(states)
        if history is None and self._theta_starts:  # d history / d theta: 1 where a state is a parameter
            if s_init is None:
                s_init = np.zeros((f.n_neurons, n_theta))
            for k, i in self._theta_starts:
                s_init[k, i] = 1.0
        return jacobian_kernel(
            u,
            f.conn_ptr,
            f.conn_kind,
            f.conn_src,
            f.conn_delay,
            conn_val,
            self._dptr,
            self._dtheta,
            dval,
            f.transfer,
            hist,
            f.ring,
            record,
            n_theta,
            self.net.substeps,
            s_init,
            in_theta,
            in_dval,
        )

    def run_pieces(self, theta, inputs: np.ndarray, first, last, histories, states: np.ndarray | None = None,
                   with_jac: bool = False):
        """:meth:`simulate` (or with `with_jac` :meth:`jacobian`) of the samples ``first[i]:last[i]`` of
        `inputs`, each piece from its own ``histories[i]``, stacked row after row: multiple shooting's segments
        of one record in one kernel call. With `states`, the sensitivities' last S columns are with respect to
        each piece's ``histories[i][states]``.

        Returns
        -------
        yhat : (sum(last - first), n_outputs [+ S]) ndarray
        dyhat : (sum(last - first), n_outputs [+ S], P [+ S]) ndarray, or None without `with_jac`
        """
        u, in_theta, in_dval = self._steps(self._check_inputs(inputs), theta, with_derivative=True) if with_jac \
            else (self._steps(self._check_inputs(inputs), theta), None, None)
        first, last = np.asarray(first, dtype=np.int64), np.asarray(last, dtype=np.int64)
        if first.shape != last.shape or first.ndim != 1 or np.any(first < 0) or np.any(last <= first) \
                or np.any(last > u.shape[0] // self.net.substeps):
            raise ValueError(f"pieces must be 0 <= first < last <= {u.shape[0] // self.net.substeps}, "
                             f"got first {first} and last {last}")
        hist = np.ascontiguousarray(histories, dtype=float)
        if hist.shape != (first.size, self._flat.n_neurons) or not np.all(np.isfinite(hist)):
            raise ValueError(f"histories must be ({first.size}, {self._flat.n_neurons}) finite values (one row "
                             f"per piece), got shape {hist.shape}")
        f = self._flat
        record = self._recorded(states)
        conn_val, dval = self.connection_values(theta, with_derivatives=with_jac)
        if not with_jac:
            return simulate_pieces_kernel(u, first, last, hist, f.conn_ptr, f.conn_kind, f.conn_src, f.conn_delay,
                                          conn_val, f.transfer, f.ring, record, self.net.substeps), None
        n_theta, s_init = self._state_sensitivities(states)
        if s_init is None:  # the kernel takes one array type: zeros, as a history that depends on nothing
            s_init = np.zeros((f.n_neurons, n_theta))
        return jacobian_pieces_kernel(u, first, last, hist, f.conn_ptr, f.conn_kind, f.conn_src, f.conn_delay,
                                      conn_val, self._dptr, self._dtheta, dval, f.transfer, f.ring, record, n_theta,
                                      self.net.substeps, s_init, in_theta, in_dval)

    def signals(
        self, theta, inputs: np.ndarray, init: Mapping[str, float] | None = None
    ) -> dict[str, np.ndarray]:
        """Every neuron's output over time, keyed "layer" (1-neuron layers) or "layer[k]"; each (Q,)."""
        record = np.arange(self._flat.n_neurons, dtype=np.int64)
        a = self._run(theta, inputs, init, record)
        return {name: a[:, k].copy() for k, name in enumerate(self._signal_names)}

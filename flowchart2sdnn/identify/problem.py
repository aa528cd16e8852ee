"""The fitting problem: a compiled chart, aligned measured data, and residual/Jacobian callbacks for LM."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..alignment import fitted_rows, network_inputs, run_aligned
from ..compiler import compile_diagram
from ..data.csvdata import Dataset
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..network.model import Network
from ..network.runtime import CompiledNetwork
from ..network.stability import chatter_radius

__all__ = ["Problem", "build_problem", "metrics", "data_init", "required_columns", "CHATTER_LIMIT"]

#: A trial step whose network chatters at rest (see network.stability) by more than this is rejected.
CHATTER_LIMIT = 1.0 + 1e-9


def required_columns(diagram: Diagram) -> list[str]:
    return list(diagram.input_names) + [n for n in diagram.output_names if n not in diagram.input_names]


def data_init(network: Network, data: Dataset) -> dict[str, float]:
    """Initial states taken from the first measured sample (integrators with `init: data`)."""
    return {s.data: float(data.columns[s.data][0]) for s in network.initial_states if s.data}


@dataclass(frozen=True, eq=False)
class Problem:
    diagram: Diagram
    network: Network
    compiled: CompiledNetwork
    inputs: np.ndarray  # network input sequence (after alignment)
    targets: np.ndarray  # measured outputs on the fitted rows (Q', n_out)
    init: Mapping[str, float]
    alignment: str

    @property
    def names(self) -> tuple[str, ...]:
        return self.compiled.names

    @property
    def n_residuals(self) -> int:
        return int(self.targets.size)

    def fun(self, x: np.ndarray):
        """(e, J) for LM: e = y - yhat flattened, J = d yhat / d x. None when the simulation diverges."""
        yhat, jac = self.compiled.jacobian(x, self.inputs, self.init)
        if not np.all(np.isfinite(yhat)) or not np.all(np.isfinite(jac)):
            return None
        return (self.targets - yhat).ravel(), jac.reshape(-1, jac.shape[-1])

    def residual(self, x: np.ndarray):
        yhat = self.compiled.simulate(x, self.inputs, self.init)
        if not np.all(np.isfinite(yhat)):
            return None
        return (self.targets - yhat).ravel()

    def chatter(self, x: np.ndarray) -> float:
        params, free = self.compiled.values(x)
        return chatter_radius(self.network, self.network.weight_values(params, free))

    def guard(self, x: np.ndarray) -> str | None:
        r = self.chatter(x)
        if r > CHATTER_LIMIT:
            return (f"the network would chatter at rest (eigenvalue {-r:.3f}): a learned curve is steeper than the "
                    "sample time allows (about 2*J/T)")
        return None


def _stack(data: Dataset, names) -> np.ndarray:
    return np.column_stack([np.asarray(data.columns[n], dtype=float) for n in names])


def build_problem(diagram: Diagram, data: Dataset, alignment: str = "zoh", seed: int = 0,
                  network: Network | None = None) -> Problem:
    """Compile `diagram` (unless `network` is given) and align `data` to it."""
    if network is None:
        network = compile_diagram(diagram, seed=seed).network
    compiled = CompiledNetwork(network)
    u = _stack(data, network_input_names(network))
    y = _stack(data, compiled.output_names)
    rows = fitted_rows(data.n_rows, alignment)
    p = network_inputs(u, alignment)
    if len(p) < 2:
        raise SdnnError.at("DATA001", f"only {data.n_rows} rows: too few samples to identify anything", data.path)
    return Problem(diagram, network, compiled, p, y[rows], data_init(network, data), alignment)


def network_input_names(network: Network) -> list[str]:
    return [i.name for i in network.inputs]


def metrics(compiled: CompiledNetwork, x: np.ndarray, data: Dataset, alignment: str, init=None,
            score_from: int = 0) -> dict:
    """Free-run fit metrics on a record: cost E (eq. 4), RMS and fit % per output, on rows >= score_from."""
    network = compiled.net
    u = _stack(data, network_input_names(network))
    y = _stack(data, compiled.output_names)
    init = data_init(network, data) if init is None else init
    yhat = run_aligned(compiled, x, u, alignment, init)
    start = max(score_from, fitted_rows(data.n_rows, alignment).start)
    e = y[start:] - yhat[start:]
    finite = bool(np.all(np.isfinite(e)))
    out = {"rows": int(len(e)), "cost": float(0.5 * np.sum(e**2)) if finite else None, "rms": {}, "fit_percent": {}}
    for i, name in enumerate(compiled.output_names):
        ei = e[:, i]
        yi = y[start:, i]
        if not finite or len(ei) == 0:
            out["rms"][name] = None
            out["fit_percent"][name] = None
            continue
        out["rms"][name] = float(np.sqrt(np.mean(ei**2)))
        spread = np.linalg.norm(yi - yi.mean())
        out["fit_percent"][name] = float(100.0 * (1.0 - np.linalg.norm(ei) / spread)) if spread > 0 else None
    return out

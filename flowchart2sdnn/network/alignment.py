"""How measured samples meet the network: the input alignment at the data interface.

Data logged as zero-order hold (`zoh`, the default): input sample k acts on [t_k, t_k+1), so output sample k
depends on inputs up to k-1. Sample 0 is the initial state; the network runs for samples 1..Q-1 with its input
at step k being u(k-1). With `direct`, the network's input at step k is u(k) and it runs for samples 0..Q-1
(its history stands for the sample before the record). The shift happens here, never inside the network.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .model import Network

__all__ = ["ALIGNMENTS", "network_inputs", "fitted_rows", "history_outputs", "run_aligned"]

ALIGNMENTS = ("zoh", "direct")


def _check(alignment: str) -> None:
    if alignment not in ALIGNMENTS:
        raise ValueError(f"alignment must be one of {ALIGNMENTS}, not {alignment!r}")


def network_inputs(u: np.ndarray, alignment: str = "zoh") -> np.ndarray:
    """The network's input sequence for measured inputs u (Q, n_inputs)."""
    _check(alignment)
    return u[:-1] if alignment == "zoh" else u


def fitted_rows(n_rows: int, alignment: str = "zoh") -> slice:
    """Rows of the measured record that the network's outputs correspond to."""
    _check(alignment)
    return slice(1, n_rows) if alignment == "zoh" else slice(0, n_rows)


def history_outputs(net: Network, init: Mapping[str, float] | None = None) -> np.ndarray:
    """Each output neuron's value before the first network step (its initial state, 0 when none is set)."""
    states = {(s.layer, s.neuron): s for s in net.initial_states}
    out = np.zeros(len(net.outputs))
    for i, o in enumerate(net.outputs):
        s = states.get((o.layer, o.neuron))
        if s is None:
            continue
        out[i] = (init or {}).get(s.data, 0.0) if s.data else s.value
    return out


def run_aligned(compiled, theta, u: np.ndarray, alignment: str = "zoh", init=None, history=None) -> np.ndarray:
    """Model outputs for every row of the record (Q, n_outputs); with zoh, row 0 is the initial state.

    `history` (every neuron's value before the first step, see CompiledNetwork.simulate) replaces the network's
    initial states and `init`.
    """
    p = network_inputs(u, alignment)
    first = (history_outputs(compiled.net, init) if history is None
             else np.asarray(history, dtype=float)[compiled.flat.output_index])
    if len(p) == 0:
        return first[None, :]
    y = compiled.simulate(theta, p, init, history=history)
    if alignment == "zoh":
        y = np.vstack([first[None, :], y])
    return y

"""Flatten a :class:`Network` into the integer/float arrays the numba kernels read.

Every neuron gets a global index (layer offset + row); since layers are evaluated in order and a delay-free
connection always comes from an earlier layer, evaluating neurons in global order at each time step respects
every dependency. The incoming connections of each neuron are stored in CSR form. A *connection* is one
distinct (target neuron, source kind, source index, delay): several :class:`WeightSpec` that hit the same
matrix cell are merged into one connection whose value is the sum of theirs, so the kernels visit each cell
once -- except into a product neuron, where every weight is a factor of its own (x*x is not 2*x).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .model import Network

__all__ = [
    "KIND_NEURON",
    "KIND_INPUT",
    "KIND_BIAS",
    "TRANSFER_CODES",
    "PRODUCT_CODE",
    "FlatNetwork",
    "flatten",
    "signal_names",
]

KIND_NEURON = 0
KIND_INPUT = 1
KIND_BIAS = 2
TRANSFER_CODES = {"linear": 0, "tanh": 1, "sin": 2, "cos": 3, "sat": 4, "sqrt": 5, "abs": 6, "exp": 7, "square": 8,
                  "signed_square": 9}
#: the kernels' code of a product neuron (net input prod, linear transfer): the net input decides how the
#: connections combine, so it travels with the transfer code rather than in an array of its own
PRODUCT_CODE = 10


@dataclass(frozen=True, eq=False)
class FlatNetwork:
    """A network as flat arrays (all integer arrays are int64, C-contiguous).

    Attributes
    ----------
    n_neurons, n_inputs : int
        N neurons in global order, R scalar inputs.
    layer_offset : (M + 1,) int64
        Global index of the first neuron of each layer; ``layer_offset[M] == N``.
    transfer : (N,) int64
        Transfer code per neuron (see ``TRANSFER_CODES``).
    conn_ptr : (N + 1,) int64
        Connections of neuron k are ``conn_ptr[k]:conn_ptr[k + 1]``.
    conn_kind, conn_src, conn_delay : (C,) int64
        Source kind (neuron / input / bias), source index (global neuron or input index; 0 for biases), delay.
    weight_conn : (W,) int64
        Connection that each WeightSpec (in ``net.weights`` order) adds to.
    history : (N,) float64
        Output of each neuron before t = 0; entries initialised from data are 0 here (see ``data_init``).
    data_init : tuple of (int, str)
        (global neuron, output name) of the states whose history is the caller's value for that output.
    output_index : (n_out,) int64
        Global neuron of each network output, in ``net.outputs`` order.
    ring : int
        Ring buffer length, max delay + 1.
    """

    n_neurons: int
    n_inputs: int
    layer_offset: np.ndarray
    transfer: np.ndarray
    conn_ptr: np.ndarray
    conn_kind: np.ndarray
    conn_src: np.ndarray
    conn_delay: np.ndarray
    weight_conn: np.ndarray
    history: np.ndarray
    data_init: tuple[tuple[int, str], ...]
    output_index: np.ndarray
    ring: int

    @property
    def n_connections(self) -> int:
        return int(self.conn_kind.shape[0])

    def connection_values(self, weight_values: np.ndarray) -> np.ndarray:
        """Sum the WeightSpec values (``net.weights`` order) into connection values, shape (C,)."""
        return np.bincount(self.weight_conn, weights=weight_values, minlength=self.n_connections)

    def history_with(self, init: Mapping[str, float] | None) -> np.ndarray:
        """The history vector with the data-initialised states taken from `init` (keyed by output name).

        Raises
        ------
        ValueError
            When a data-initialised state has no (finite) value in `init`.
        """
        hist = self.history.copy()
        for k, name in self.data_init:
            if init is None or name not in init:
                raise ValueError(
                    f"the initial state of neuron {k} comes from data: pass init={{{name!r}: value}} "
                    f"(the first measured sample of output {name!r})"
                )
            value = float(init[name])
            if not np.isfinite(value):
                raise ValueError(f"init[{name!r}] is not finite: {value!r}")
            hist[k] = value
        return hist


def flatten(net: Network) -> FlatNetwork:
    """Turn `net` into a :class:`FlatNetwork`.

    Raises
    ------
    ValueError
        When the network breaks an invariant (see :meth:`Network.verify`) or lists a neuron's initial
        state twice.
    """
    net.verify()
    sizes = [la.size for la in net.layers]
    layer_offset = np.zeros(len(sizes) + 1, dtype=np.int64)
    layer_offset[1:] = np.cumsum(sizes)
    n_neurons = int(layer_offset[-1])
    neurons = [n for la in net.layers for n in la.neurons]
    transfer = np.array(
        [PRODUCT_CODE if n.net_input == "prod" else TRANSFER_CODES[n.transfer] for n in neurons], dtype=np.int64
    ).reshape(n_neurons)

    # Distinct connections, keyed (target, kind, source, delay, factor); sorted so each neuron's block is
    # contiguous. `factor` is the weight's index into a product neuron (each weight a factor), else -1 (merged).
    keys: list[tuple[int, int, int, int, int]] = []
    for j, w in enumerate(net.weights):
        target = int(layer_offset[w.layer]) + w.row
        factor = j if transfer[target] == PRODUCT_CODE else -1
        if w.matrix == "LW":
            keys.append((target, KIND_NEURON, int(layer_offset[w.source]) + w.col, w.delay, factor))
        elif w.matrix == "IW":
            keys.append((target, KIND_INPUT, w.source, w.delay, factor))
        else:
            keys.append((target, KIND_BIAS, 0, 0, factor))
    unique = sorted(set(keys))
    index = {key: c for c, key in enumerate(unique)}
    conn = np.array(unique, dtype=np.int64).reshape(len(unique), 5)
    weight_conn = np.array([index[key] for key in keys], dtype=np.int64)
    conn_ptr = np.searchsorted(conn[:, 0], np.arange(n_neurons + 1)).astype(np.int64)

    history = np.zeros(n_neurons)
    data_init: list[tuple[int, str]] = []
    seen: set[int] = set()
    for s in net.initial_states:
        k = int(layer_offset[s.layer]) + s.neuron
        if k in seen:
            raise ValueError(
                f"initial state of neuron {s.neuron} of layer {net.layers[s.layer].name!r} given twice"
            )
        seen.add(k)
        if s.data is not None:
            data_init.append((k, s.data))
        else:
            history[k] = float(s.value)

    output_index = np.array([int(layer_offset[o.layer]) + o.neuron for o in net.outputs], dtype=np.int64)
    return FlatNetwork(
        n_neurons=n_neurons,
        n_inputs=len(net.inputs),
        layer_offset=layer_offset,
        transfer=transfer,
        conn_ptr=np.ascontiguousarray(conn_ptr),
        conn_kind=np.ascontiguousarray(conn[:, 1]),
        conn_src=np.ascontiguousarray(conn[:, 2]),
        conn_delay=np.ascontiguousarray(conn[:, 3]),
        weight_conn=weight_conn,
        history=history,
        data_init=tuple(data_init),
        output_index=output_index,
        ring=net.max_delay + 1,
    )


def signal_names(net: Network) -> tuple[str, ...]:
    """Name of every neuron's output in global order: "layer" for 1-neuron layers, else "layer[k]"."""
    names = []
    for la in net.layers:
        if la.size == 1:
            names.append(la.name)
        else:
            names.extend(f"{la.name}[{k}]" for k in range(la.size))
    return tuple(names)

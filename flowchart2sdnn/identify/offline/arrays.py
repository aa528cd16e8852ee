"""A record as the network's arrays: its columns, the network's input names, the initial states it gives.

The helpers every reader of records shares (the problem, the curves' spans, the comparison); a module of its
own so that problem.py and curvespan.py, which both read records, need not import each other.

Layer: identify.
"""

from __future__ import annotations

import numpy as np

from ...data.csvdata import Dataset
from ...network.model import Network

__all__ = ["columns_of", "data_init", "network_input_names"]


def data_init(network: Network, data: Dataset) -> dict[str, float]:
    """Initial states taken from the first measured sample (integrators with `init: data`)."""
    return {s.data: float(data.columns[s.data][0]) for s in network.initial_states if s.data}


def columns_of(data: Dataset, names) -> np.ndarray:
    """The record's columns `names` as one (Q, len(names)) float array: the one way a record becomes arrays."""
    return np.column_stack([np.asarray(data.columns[n], dtype=float) for n in names])


def network_input_names(network: Network) -> list[str]:
    return [i.name for i in network.inputs]

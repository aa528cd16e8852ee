"""One linear neuron with feedback, y(t) = w y(t-1) + k u(t), and its hand-derived recursion (quasi-online tests)."""

from __future__ import annotations

import numpy as np
from randomnet import hand_network

from flowchart2sdnn.network.model import WeightSpec
from flowchart2sdnn.network.runtime import CompiledNetwork


def feedback_neuron(w0=0.3, k0=0.5) -> CompiledNetwork:
    """The network: a free weight w and a parameter k (theta = (k, w))."""
    net = hand_network(
        layers=[("y", "linear")],
        weights=[
            WeightSpec("LW", 0, 0, source=0, delay=1, coef="1", free="w"),
            WeightSpec("IW", 0, 0, source=0, delay=0, coef="k"),
        ],
        outputs=[("y", 0)],
        parameters={"k": k0},
        free_weights={"w": w0},
    )
    return CompiledNetwork(net)


def hand_run(k, w, u, y_prev=0.0):
    """Outputs and dy/dk, dy/dw by the recursion S(t) = d/dtheta [w y(t-1) + k u(t)], from y(-1) = y_prev with
    zero sensitivities there."""
    y, dk, dw = np.zeros(u.size), np.zeros(u.size), np.zeros(u.size)
    prev, prev_k, prev_w = y_prev, 0.0, 0.0
    for t in range(u.size):
        y[t] = w * prev + k * u[t]
        dk[t] = u[t] + w * prev_k
        dw[t] = prev + w * prev_w
        prev, prev_k, prev_w = y[t], dk[t], dw[t]
    return y, dk, dw

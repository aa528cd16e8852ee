"""Is the discrete network stable at rest? The guard against chatter of delayed feedback.

A learned friction curve steeper than about 2*J/T at zero speed makes its one-sample-delayed feedback
unstable: w(t) = w(t-1) + T/J*(M - f(w(t-1))) has the eigenvalue 1 - T*f'(0)/J, below -1 when f'(0) > 2J/T.
No continuous system does that at this sample time, so a trial step that produces it is rejected.

Generic form: linearize eq. (1)-(2) around rest (zero inputs, zero history) and build the companion matrix of
a(t) = sum_d A_d a(t-d) with A_d = (I - D L_0)^-1 D L_d, D = diag f'(n_rest). Chatter = an eigenvalue with a
negative real part outside the unit circle (a sign flip every sample).
"""

from __future__ import annotations

import numpy as np

from .model import Network

__all__ = ["rest_eigenvalues", "chatter_radius", "rest_radii"]


def _value(transfer: str, n: float) -> float:
    if transfer == "sqrt":  # see network.model.TRANSFERS
        return float(np.sign(n) * np.sqrt(abs(n))) if abs(n) >= 1.0 else (5.0 * n - n**3) / 4.0
    if transfer == "signed_square":
        return n * abs(n)
    return {"tanh": np.tanh, "sin": np.sin, "cos": np.cos, "sat": lambda x: np.clip(x, -1.0, 1.0),
            "abs": abs, "exp": np.exp, "square": lambda x: x * x}.get(transfer, lambda x: x)(n)


def _derivative(transfer: str, n: float) -> float:
    if transfer == "tanh":
        return 1.0 - np.tanh(n) ** 2
    if transfer == "sin":
        return np.cos(n)
    if transfer == "cos":
        return -np.sin(n)
    if transfer == "sat":
        return 1.0 if abs(n) < 1.0 else 0.0
    if transfer == "sqrt":
        return 0.5 / np.sqrt(abs(n)) if abs(n) >= 1.0 else (5.0 - 3.0 * n * n) / 4.0
    if transfer == "abs":
        return float(np.sign(n))
    if transfer == "exp":
        return np.exp(n)
    if transfer == "square":
        return 2.0 * n
    if transfer == "signed_square":
        return 2.0 * abs(n)
    return 1.0


@np.errstate(all="ignore")  # overflowing weights are handled: they give an unbounded radius, not warnings
def rest_eigenvalues(net: Network, values: np.ndarray, slopes: dict[int, float] | None = None) -> np.ndarray:
    """Eigenvalues of the network linearized at rest, for weight values `values` (Network.weights order).

    A product neuron's row holds its partial derivatives at rest, w_c times the other factors (zero when two
    factors are signals at rest: a product of two states has no linear part there). `slopes` (flat neuron
    index -> f') replaces the transfer's slope at rest for those neurons: the network linearized in another
    region of a piecewise function (a dead zone in contact), as the sub-steps' auto reads it.
    """
    offsets = np.cumsum([0] + [la.size for la in net.layers])
    n = int(offsets[-1])
    dmax = max([w.delay for w in net.weights if w.matrix == "LW"] + [1])
    L = np.zeros((dmax + 1, n, n))
    bias = np.zeros(n)
    neurons = [nr for la in net.layers for nr in la.neurons]
    transfers = [nr.transfer for nr in neurons]
    factors: dict[int, list[tuple[str, int, int, float]]] = {}  # product neuron -> (matrix, source, delay, w)
    for w, v in zip(net.weights, values, strict=True):
        row = offsets[w.layer] + w.row
        if neurons[row].net_input == "prod":
            source = offsets[w.source] + w.col if w.matrix == "LW" else w.source
            factors.setdefault(row, []).append((w.matrix, int(source), w.delay, float(v)))
        elif w.matrix == "LW":
            L[w.delay, row, offsets[w.source] + w.col] += v
        elif w.matrix == "b":
            bias[row] += v
    # operating point: inputs and history zero, delay-free part evaluated in layer order
    a = np.zeros(n)
    nrest = np.zeros(n)
    for k in range(n):
        if k in factors:
            terms = [v * (1.0 if m == "b" else a[src] if m == "LW" and d == 0 else 0.0)
                     for m, src, d, v in factors[k]]
            nrest[k] = float(np.prod(terms))
            for i, (m, src, d, v) in enumerate(factors[k]):
                if m == "LW":
                    L[d, k, src] += v * float(np.prod(terms[:i] + terms[i + 1:]))
        else:
            nrest[k] = bias[k] + L[0, k] @ a
        a[k] = _value(transfers[k], nrest[k])
    D = np.array([_derivative(t, float(x)) for t, x in zip(transfers, nrest, strict=True)], dtype=float)
    for k, slope in (slopes or {}).items():
        D[k] = slope
    M = np.eye(n) - D[:, None] * L[0]
    unbounded = np.array([np.inf])  # what a network without a finite linearisation at rest is treated as
    try:
        blocks = [np.linalg.solve(M, D[:, None] * L[d]) for d in range(1, dmax + 1)]
    except np.linalg.LinAlgError:  # an algebraic loop with gain 1 at rest: no unique operating point
        return unbounded
    companion = np.zeros((n * dmax, n * dmax))
    companion[:n, :] = np.hstack(blocks)
    if dmax > 1:
        companion[n:, :-n] = np.eye(n * (dmax - 1))
    if not np.all(np.isfinite(companion)):  # weights so large that the linearisation overflows
        return unbounded
    return np.linalg.eigvals(companion)


def chatter_radius(net: Network, values: np.ndarray) -> float:
    """Largest modulus among rest eigenvalues with a negative real part (> 1: the network chatters)."""
    eig = rest_eigenvalues(net, values)
    neg = eig[eig.real < -1e-12]
    return float(np.max(np.abs(neg))) if neg.size else 0.0


def rest_radii(net: Network, values: np.ndarray) -> tuple[float, float]:
    """(chatter, growth): the largest modulus among rest eigenvalues with a negative real part, and among
    the others. Chatter > 1 flips sign every sample; growth > 1 drifts away from rest (e.g. a learned friction
    curve with a negative slope at zero speed, which feeds energy in)."""
    eig = rest_eigenvalues(net, values)
    neg = eig.real < -1e-12
    chatter = float(np.max(np.abs(eig[neg]))) if neg.any() else 0.0
    growth = float(np.max(np.abs(eig[~neg]))) if (~neg).any() else 0.0
    return chatter, growth

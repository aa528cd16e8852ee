"""The continuous state-space model of a chart at an operating point: A, B, C, D, poles, damping ratios.

The chart is read as the continuous system it describes (the semantics of the continuous oracle,
:mod:`flowchart2sdnn.simulate.continuous`): the states are the integrators, the inputs the chart's inputs,
the outputs its measured outputs. Each block is replaced by its slope at the operating point:

* ``gain`` k; ``sum`` its signs; ``constant`` 0 (it shifts the operating point, not the dynamics);
* ``nonlinear`` (a learned curve sum v_i tanh(a_i x + b_i)): its slope sum v_i a_i (1 - tanh^2(a_i x + b_i))
  there; a curve that learned Coulomb friction is steep at zero speed, so at rest it acts as a stiff damper
  (the axis stuck); its slope is reported in the notes, and ``--at w=...`` linearises at a moving point;
* ``function`` f(k x): k f'(k x) for tanh, sin, cos and sat (0 outside the clip);
* **the Coulomb kink**, ``sign_smooth`` = tanh(k x / eps): with ``kink="zero"`` (the default) its slope is 0:
  it stands for sign(x), whose derivative is 0 everywhere but at the kink, where none exists; Coulomb
  friction is then a constant force while moving (it moves the operating point, not the poles), and at rest
  the linear model describes the axis as free, not stuck. ``kink="smooth"`` takes the slope of the smoothed
  function instead (k / eps at zero: the stuck axis as a very stiff viscous damper);
* ``delay`` n samples: taken as no delay (a pure delay has no finite state-space model; its phase lag
  n T omega is named in the notes).

The operating point gives each state (integrator output) and input a value (default 0: at rest, no input);
the algebraic signals follow from them. It need not be an equilibrium: ``xdot`` holds the state derivatives
there (zero at an equilibrium), and A, B are the Jacobians of the state derivatives at that point.

Layer: analysis (reads the chart model only).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from ..diagram.blocks import core_diagram
from ..diagram.model import Block, Diagram
from ..errors import SdnnError

__all__ = ["KINKS", "LinearModel", "linearize", "parse_operating_point", "write_state_space"]

KINKS = ("zero", "smooth")
_DEFAULT_EPS = 1e-3  # as the continuous oracle


@dataclass(frozen=True, eq=False)
class LinearModel:
    """dx/dt = A x + B u, y = C x + D u about the operating point (deviations from it)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    units: Mapping[str, str | None]
    at: Mapping[str, float]
    xdot: np.ndarray
    notes: tuple[str, ...] = ()
    name: str = ""
    slopes: Mapping[str, float] = field(default_factory=dict)

    def poles(self) -> np.ndarray:
        """Eigenvalues of A (rad/s), sorted by natural frequency."""
        p = np.linalg.eigvals(self.A) if self.A.size else np.zeros(0, complex)
        return p[np.lexsort((p.imag, np.abs(p)))]

    def damp(self) -> list[dict]:
        """Per pole (one of each complex pair), as MATLAB's `damp`: the pole, natural frequency wn = |p| (rad/s)
        and f = wn / 2 pi (Hz), damping ratio zeta = -Re(p) / |p| (None for a pole at 0) and the damped
        frequency |Im p| / 2 pi (Hz)."""
        out = []
        for p in self.poles():
            if p.imag < -1e-12 * max(1.0, abs(p)):
                continue  # the conjugate of one already listed
            wn = float(abs(p))
            zeta = float(-p.real / wn) if wn > 0 else None
            out.append({"pole": complex(p), "wn": wn, "f_hz": wn / (2 * math.pi), "zeta": zeta,
                        "damped_hz": abs(float(p.imag)) / (2 * math.pi)})
        return out

    def frequency_response(self, f_hz: np.ndarray) -> np.ndarray:
        """H(j 2 pi f) = C (j 2 pi f I - A)^-1 B + D, shape (len(f), n_outputs, n_inputs)."""
        f = np.atleast_1d(np.asarray(f_hz, dtype=float))
        n = self.A.shape[0]
        out = np.empty((f.size, len(self.outputs), len(self.inputs)), dtype=complex)
        for i, fi in enumerate(f):
            s = 2j * math.pi * fi
            out[i] = self.C @ np.linalg.solve(s * np.eye(n) - self.A, self.B) + self.D if n else self.D
        return out

    def to_dict(self) -> dict:
        """JSON-ready: the matrices as nested lists, names, units, operating point, poles."""
        return {"format": "sdnn-statespace", "version": 1, "name": self.name, "A": self.A.tolist(),
                "B": self.B.tolist(), "C": self.C.tolist(), "D": self.D.tolist(), "states": list(self.states),
                "inputs": list(self.inputs), "outputs": list(self.outputs), "units": dict(self.units),
                "operating_point": dict(self.at), "xdot": self.xdot.tolist(), "notes": list(self.notes),
                "poles": [[float(p.real), float(p.imag)] for p in self.poles()]}

    def to_control(self):
        """The model as a python-control ``StateSpace`` (needs ``pip install control``)."""
        try:
            import control
        except ImportError:
            raise SdnnError.at("LIN004", "python-control is not installed: pip install control",
                               hint="or load the --control file: control.ss(*(np.load(f)[k] for k in 'ABCD'))"
                               ) from None
        return control.ss(self.A, self.B, self.C, self.D, states=list(self.states), inputs=list(self.inputs),
                          outputs=list(self.outputs), name=self.name or None)


def parse_operating_point(items) -> dict[str, float]:
    """``["w1=0,w2=5", "M1=1"]`` -> {"w1": 0.0, "w2": 5.0, "M1": 1.0}; ValueError naming a bad item."""
    out: dict[str, float] = {}
    for item in items or ():
        for part in str(item).split(","):
            if not part.strip():
                continue
            name, eq, value = (t.strip() for t in part.partition("="))
            try:
                number = float(value) if eq and name else math.nan
            except ValueError:
                number = math.nan
            if not math.isfinite(number):
                raise ValueError(f"operating point item {part.strip()!r} is not NAME=NUMBER (e.g. w1=0)")
            out[name] = number
    return out


def _curve_slope(b: Block, x: float) -> tuple[float, float]:
    w = b.weights
    a, v = np.asarray(w.a, float), np.asarray(w.v, float)
    bias = np.asarray(w.b, float) if w.b is not None else np.zeros_like(a)
    t = np.tanh(a * x + bias)
    c = w.c or 0.0
    return float(v @ t) + c * x, float(np.sum(v * a * (1 - t**2))) + c


def _function_slope(b: Block, k: float, x: float, kink: str) -> tuple[float, float]:
    z = k * x
    if b.f == "tanh":
        return math.tanh(z), k * (1 - math.tanh(z) ** 2)
    if b.f == "sin":
        return math.sin(z), k * math.cos(z)
    if b.f == "cos":
        return math.cos(z), -k * math.sin(z)
    if b.f == "sat":
        return min(1.0, max(-1.0, z)), k if abs(z) < 1 else 0.0
    if b.f == "abs":  # the kink at 0 taken as its subgradient 0, like the Coulomb kink
        return abs(z), k * float(np.sign(z))
    if b.f == "exp":
        return math.exp(z), k * math.exp(z)
    if b.f == "square":
        return z * z, 2 * k * z
    if b.f == "signed_square":
        return z * abs(z), 2 * k * abs(z)
    if b.f == "sqrt":  # the chart's regularised square root (simulate.continuous): finite slope at 0
        eps = _DEFAULT_EPS if b.eps is None else float(b.eps)
        if abs(z) >= eps:
            return math.copysign(math.sqrt(abs(z)), z), k * 0.5 / math.sqrt(abs(z))
        u = z / eps
        return math.sqrt(eps) * (5 * u - u**3) / 4, k * (5 - 3 * u * u) / (4 * math.sqrt(eps))
    eps = _DEFAULT_EPS if b.eps is None else float(b.eps)  # sign_smooth
    value = math.tanh(z / eps)
    return value, (k / eps * (1 - value**2) if kink == "smooth" else 0.0)


def _order(diagram: Diagram) -> list[Block]:
    """Non-integrator blocks in an order where every operand is known (integrator outputs are states)."""
    g = nx.DiGraph()
    blocks = {b.name: b for b in diagram.blocks}
    for b in diagram.blocks:
        g.add_node(b.name)
        if b.kind == "integrator":
            continue
        for s in b.signals_in:
            if s in blocks:
                g.add_edge(s, b.name)
    try:
        order = list(nx.topological_sort(g))
    except nx.NetworkXUnfeasible:
        cycle = [u for u, _ in nx.find_cycle(g)]
        raise SdnnError.at("LIN001", f"the loop {' -> '.join(cycle + cycle[:1])} closes through a delay without "
                           "an integrator: with the delay taken as none it is algebraic, no linear model",
                           diagram.file, hint="add the integrator the loop stands for") from None
    return [blocks[n] for n in order if blocks[n].kind != "integrator"]


def linearize(diagram: Diagram, at: Mapping[str, float] | None = None, kink: str = "zero") -> LinearModel:
    """The chart's continuous state-space model at the operating point `at` (state and input name -> value).

    Parameters are the chart's values (``init``: the identified ones in an identified chart); every learned
    curve must hold weights (an identified chart does).
    """
    if kink not in KINKS:
        raise ValueError(f"kink must be one of {KINKS}, not {kink!r}")
    diagram = core_diagram(diagram)  # a registered kind means the core block it lowers to
    at = dict(at or {})
    states = tuple(b.name for b in diagram.blocks if b.kind == "integrator")
    inputs = diagram.input_names
    unknown = sorted(set(at) - set(states) - set(inputs))
    if unknown:
        raise ValueError(f"the operating point names {', '.join(unknown)}, which are neither states nor inputs "
                         f"(states: {', '.join(states) or 'none'}; inputs: {', '.join(inputs)})")
    for b in diagram.blocks:
        if b.kind == "nonlinear" and b.weights is None:
            raise SdnnError.at("LIN002", f"learned curve '{b.name}' has no weights: linearise an identified chart "
                               "(RESULT.chart.yaml) or a RESULT.json", diagram.file, block=b.name)
    params = diagram.parameter_values()
    n, m = len(states), len(inputs)
    value: dict[str, float] = {}
    row: dict[str, np.ndarray] = {}
    for i, name in enumerate((*states, *inputs)):
        value[name] = float(at.get(name, 0.0))
        row[name] = np.eye(n + m)[i]
    notes, slopes = [], {}

    def operand(b: Block) -> tuple[float, np.ndarray]:
        x, r = 0.0, np.zeros(n + m)
        for t in b.inputs:
            x += t.sign * value[t.signal]
            r = r + t.sign * row[t.signal]
        return x, r

    for b in _order(diagram):
        x, r = operand(b)
        k = 1.0
        if b.k is not None:
            try:
                k = float(b.k.evaluate(params))
            except (ArithmeticError, ValueError) as exc:
                raise SdnnError.at("LIN003", f"block '{b.name}': k = {b.k} cannot be evaluated ({exc})",
                                   diagram.file, block=b.name) from None
        if b.kind == "sum":
            y, g = x, 1.0
        elif b.kind == "gain":
            y, g = k * x, k
        elif b.kind == "constant":
            y, g = k, 0.0
        elif b.kind == "product":  # the product rule: each factor's row times the others' values
            xs = [t.sign * value[t.signal] for t in b.inputs]
            y, g, r = k * float(np.prod(xs)), 1.0, np.zeros(n + m)
            for i, t in enumerate(b.inputs):
                r = r + k * float(np.prod(xs[:i] + xs[i + 1:])) * t.sign * row[t.signal]
        elif b.kind == "delay":
            y, g = x, 1.0
            notes.append(f"delay '{b.name}' ({b.n or 1} samples) taken as no delay: it lags the phase by "
                         f"{(b.n or 1) * diagram.sample_time:g} s times omega")
        elif b.kind == "nonlinear":
            y, g = _curve_slope(b, x)
            slopes[b.name] = g
            notes.append(f"learned curve '{b.name}': slope {g:.6g} at {' '.join(map(str, b.inputs))} = {x:g}")
        else:
            y, g = _function_slope(b, k, x, kink)
            if b.f == "sign_smooth":
                slopes[b.name] = g
                notes.append(f"Coulomb kink '{b.name}' (sign_smooth) at {x:g}: slope {g:.6g} "
                             + ("(taken as the sign function: 0)" if kink == "zero" else "(of the smoothed sign)"))
        value[b.name], row[b.name] = y, g * r
    A, B = np.zeros((n, n)), np.zeros((n, m))
    xdot = np.zeros(n)
    for i, name in enumerate(states):
        xdot[i], r = operand(diagram.block(name))
        A[i], B[i] = r[:n], r[n:]
    outputs = diagram.output_names
    C = np.array([row[o][:n] for o in outputs]).reshape(len(outputs), n)
    D = np.array([row[o][n:] for o in outputs]).reshape(len(outputs), m)
    declared = {s.name: s.unit for s in (*diagram.inputs, *diagram.outputs)}
    units = {name: declared.get(name) or diagram.block(name).unit for name in states}
    units.update({name: declared.get(name) for name in (*inputs, *outputs)})
    point = {name: value[name] for name in (*states, *inputs)}
    return LinearModel(A, B, C, D, states, inputs, outputs, units, point, xdot, tuple(notes), diagram.name, slopes)


def write_state_space(model: LinearModel, path) -> None:
    """Write the model for python-control: ``.npz`` (arrays A, B, C, D, states, inputs, outputs; load with
    ``d = np.load(f); control.ss(d["A"], d["B"], d["C"], d["D"])``), else JSON (:meth:`LinearModel.to_dict`).
    Written atomically."""
    import io
    import json
    from pathlib import Path

    from ..atomic import atomic_write_bytes, atomic_write_text
    from ..strictjson import strict_json

    if Path(path).suffix.lower() == ".npz":
        buffer = io.BytesIO()
        np.savez(buffer, A=model.A, B=model.B, C=model.C, D=model.D, states=np.array(model.states, dtype=str),
                 inputs=np.array(model.inputs, dtype=str), outputs=np.array(model.outputs, dtype=str))
        atomic_write_bytes(path, buffer.getvalue())
    else:
        atomic_write_text(path, json.dumps(strict_json(model.to_dict()), indent=1) + "\n")

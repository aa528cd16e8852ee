"""The network file: a General Dynamic Neural Network with administration matrices and a parameter map.

This is the contract between the compiler and the runtime/trainer: they consume only a :class:`Network`
(or its JSON file), never a chart. The notation follows De Jesús & Hagan (2007) and the paper, eq. (1)-(3):

    n^m(t) = sum_{l, d} LW^{m,l}(d) a^l(t-d) + sum_{l, d} IW^{m,l}(d) p^l(t-d) + b^m,   a^m(t) = f^m(n^m(t))

Layers and inputs are numbered from 0 in the file (the paper counts from 1). Every existing weight is one
:class:`WeightSpec`; its value is ``coef(parameters) * (free weight or 1)``. The matrices LW, IW, b and the
administration matrices AL, AI, Ab of eq. (3) are derived from the weight list and written into the file for
readers; on load they are checked against it.

History (values before the first sample): a neuron's output before t = 0 is its initial state (0 unless
listed in `initial_states`); inputs before t = 0 are held at their first sample.

Sub-steps: the network may step at h = sample_time / substeps (the weights carry h, a delay block of n samples
is n * substeps steps); the runtime holds each input sample over its `substeps` steps and reads the outputs at
the last one. `sample_time` stays the data's; the file records both and `step` = h.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

import numpy as np

from .specs import (
    DelayedEdge,
    FreeWeightSpec,
    InitialState,
    InputSpec,
    LayerSpec,
    NeuronSpec,
    OutputSpec,
    ParameterSpec,
    WeightSpec,
)

__all__ = [
    "NETWORK_FORMAT",
    "NETWORK_VERSION",
    "TRANSFERS",
    "NET_INPUTS",
    "NeuronSpec",
    "LayerSpec",
    "InputSpec",
    "ParameterSpec",
    "FreeWeightSpec",
    "WeightSpec",
    "OutputSpec",
    "InitialState",
    "DelayedEdge",
    "Network",
]

NETWORK_FORMAT = "sdnn-network"
NETWORK_VERSION = 1
# sat: hard clip to [-1, 1]; sqrt: sqrt(n) for n >= 1, -sqrt(-n) for n <= -1, (5 n - n^3) / 4 in between (the
# odd C1 continuation with a finite slope 5/4 at 0; the compiler scales a chart's eps to 1); square: n^2;
# signed_square: n |n|; abs: |n| (slope sign(n), 0 at 0); exp
TRANSFERS = ("linear", "tanh", "sin", "cos", "sat", "sqrt", "abs", "exp", "square", "signed_square")
#: net input functions: "sum" of weighted inputs (eq. 1), or their "prod"uct (MATLAB's netprod)
NET_INPUTS = ("sum", "prod")


@dataclass(frozen=True)
class Network:
    name: str
    sample_time: float
    inputs: tuple[InputSpec, ...]
    layers: tuple[LayerSpec, ...]
    weights: tuple[WeightSpec, ...]
    outputs: tuple[OutputSpec, ...]
    parameters: tuple[ParameterSpec, ...] = ()
    free_weights: tuple[FreeWeightSpec, ...] = ()
    initial_states: tuple[InitialState, ...] = ()
    delayed_edges: tuple[DelayedEdge, ...] = ()
    substeps: int = 1  # network steps per data sample
    source: Mapping = field(default_factory=dict, compare=False, hash=False)

    # ------------------------------------------------------------------ values
    def parameter_values(self) -> dict[str, float]:
        return {p.name: float(p.init) for p in self.parameters}

    def free_weight_values(self) -> dict[str, float]:
        return {f.name: float(f.init) for f in self.free_weights}

    def weight_values(
        self,
        parameters: Mapping[str, float] | None = None,
        free: Mapping[str, float] | None = None,
    ) -> np.ndarray:
        """Value of every weight (in `weights` order) at the given parameter and free-weight values."""
        from ..expr import parse_expr  # local: the network file only needs it to evaluate

        env = self.parameter_values()
        if parameters:
            env.update(parameters)
        fv = self.free_weight_values()
        if free:
            fv.update(free)
        out = np.empty(len(self.weights))
        cache: dict[str, object] = {}
        for j, w in enumerate(self.weights):
            expr = cache.get(w.coef)
            if expr is None:
                expr = cache[w.coef] = parse_expr(w.coef)
            value = expr.evaluate(env)
            if w.free is not None:
                value *= fv[w.free]
            out[j] = value
        return out

    @property
    def step(self) -> float:
        """The network's time step h = sample_time / substeps (what the integrator weights carry)."""
        return self.sample_time / self.substeps

    @property
    def max_delay(self) -> int:
        return max([w.delay for w in self.weights] + [0])

    # ------------------------------------------------------------------ matrices (eq. 1-3)
    def matrices(self, values: np.ndarray | None = None) -> dict[tuple, tuple[np.ndarray, np.ndarray]]:
        """(values, administration) of every LW^{m,l}(d), IW^{m,l}(d) and b^m that has a weight.

        Keys are ("LW", m, l, d), ("IW", m, l, d) and ("b", m).
        """
        if values is None:
            values = self.weight_values()
        out: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        for w, value in zip(self.weights, values, strict=True):
            rows = self.layers[w.layer].size
            if w.matrix == "LW":
                key = ("LW", w.layer, w.source, w.delay)
                shape = (rows, self.layers[w.source].size)
            elif w.matrix == "IW":
                key = ("IW", w.layer, w.source, w.delay)
                shape = (rows, 1)
            else:
                key = ("b", w.layer)
                shape = (rows, 1)
            if key not in out:
                out[key] = (np.zeros(shape), np.zeros(shape, dtype=np.int8))
            mat, adm = out[key]
            mat[w.row, w.col] += value
            adm[w.row, w.col] = 1
        return out

    # ------------------------------------------------------------------ serialization
    def to_dict(self) -> dict:
        values = self.weight_values()
        matrices = []
        for key, (mat, adm) in sorted(self.matrices(values).items(), key=lambda kv: _matrix_sort_key(kv[0])):
            entry = {"matrix": key[0], "layer": key[1]}
            if key[0] != "b":
                entry.update({"source": key[2], "delay": key[3]})
            entry["values"] = mat.tolist()
            entry["admin"] = adm.tolist()
            matrices.append(entry)
        return {
            "format": NETWORK_FORMAT,
            "version": NETWORK_VERSION,
            "name": self.name,
            "sample_time": self.sample_time,
            "substeps": self.substeps,
            "step": self.step,
            "inputs": [i.to_dict() for i in self.inputs],
            "layers": [
                {"name": la.name, "block": la.block, "kind": la.kind, "neurons": [n.to_dict() for n in la.neurons]}
                for la in self.layers
            ],
            "parameters": [asdict(p) for p in self.parameters],
            "free_weights": [asdict(f) for f in self.free_weights],
            "weights": [asdict(w) for w in self.weights],
            "outputs": [asdict(o) for o in self.outputs],
            "initial_states": [asdict(s) for s in self.initial_states],
            "delayed_edges": [asdict(e) for e in self.delayed_edges],
            "matrices": matrices,
            "source": dict(self.source),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"

    @classmethod
    def from_dict(cls, data: Mapping) -> Network:
        if data.get("format") != NETWORK_FORMAT:
            raise ValueError(f"not a network file: 'format' is {data.get('format')!r}, expected {NETWORK_FORMAT!r}")
        if data.get("version") != NETWORK_VERSION:
            raise ValueError(f"unsupported network file version {data.get('version')!r}, expected {NETWORK_VERSION}")
        layers = tuple(
            LayerSpec(
                name=la["name"],
                block=la.get("block"),
                kind=la.get("kind"),
                neurons=tuple(NeuronSpec(**n) for n in la["neurons"]),
            )
            for la in data["layers"]
        )
        net = cls(
            name=data["name"],
            sample_time=float(data["sample_time"]),
            inputs=tuple(InputSpec(**i) for i in data["inputs"]),
            layers=layers,
            weights=tuple(WeightSpec(**w) for w in data["weights"]),
            outputs=tuple(OutputSpec(**o) for o in data["outputs"]),
            parameters=tuple(ParameterSpec(**p) for p in data.get("parameters", ())),
            free_weights=tuple(FreeWeightSpec(**f) for f in data.get("free_weights", ())),
            initial_states=tuple(InitialState(**s) for s in data.get("initial_states", ())),
            delayed_edges=tuple(
                DelayedEdge(e["source"], e["target"], e["delay"], tuple(e.get("loop", ())))
                for e in data.get("delayed_edges", ())
            ),
            substeps=data.get("substeps", 1),  # files before sub-steps: one step per sample
            source=dict(data.get("source", {})),
        )
        net.verify()
        if "matrices" in data:
            _check_matrices(net, data["matrices"])
        return net

    @classmethod
    def from_json(cls, text: str) -> Network:
        return cls.from_dict(json.loads(text))

    # ------------------------------------------------------------------ invariants
    def verify(self) -> None:
        """Raise ValueError when the network breaks an invariant the runtime relies on."""
        if not (self.sample_time > 0 and math.isfinite(self.sample_time)):
            raise ValueError("sample_time must be a positive number")
        if not isinstance(self.substeps, int) or isinstance(self.substeps, bool) or self.substeps < 1:
            raise ValueError(f"substeps must be a whole number >= 1, not {self.substeps!r}")
        params = {p.name for p in self.parameters}
        for i in self.inputs:
            if i.intersample not in ("hold", "linear"):
                raise ValueError(f"input {i.name!r}: intersample must be hold or linear, not {i.intersample!r}")
            if i.delay is not None and i.delay not in params:
                try:
                    float(i.delay)
                except ValueError:
                    raise ValueError(f"input {i.name!r}: delay {i.delay!r} is neither a parameter nor a number") from None
        nl = len(self.layers)
        free_names = {f.name for f in self.free_weights}
        for la in self.layers:
            if la.size == 0:
                raise ValueError(f"layer {la.name!r} has no neurons")
            for n in la.neurons:
                if n.transfer not in TRANSFERS:
                    raise ValueError(f"neuron {n.name!r}: unknown transfer {n.transfer!r}")
                if n.net_input not in NET_INPUTS:
                    raise ValueError(f"neuron {n.name!r}: unknown net input {n.net_input!r}")
                if n.net_input == "prod" and n.transfer != "linear":
                    raise ValueError(f"neuron {n.name!r}: a product neuron has a linear transfer")
        for j, w in enumerate(self.weights):
            if w.matrix not in ("LW", "IW", "b"):
                raise ValueError(f"weight {j}: unknown matrix {w.matrix!r}")
            if not 0 <= w.layer < nl or not 0 <= w.row < self.layers[w.layer].size:
                raise ValueError(f"weight {j}: layer/row out of range")
            if w.delay < 0:
                raise ValueError(f"weight {j}: negative delay")
            if w.matrix == "LW":
                if not 0 <= w.source < nl or not 0 <= w.col < self.layers[w.source].size:
                    raise ValueError(f"weight {j}: source layer/column out of range")
                if w.delay == 0 and w.source >= w.layer:
                    raise ValueError(
                        f"weight {j}: a delay-free connection must come from an earlier layer "
                        f"(layer {w.source} -> {w.layer})"
                    )
            elif w.matrix == "IW":
                if not 0 <= w.source < len(self.inputs) or w.col != 0:
                    raise ValueError(f"weight {j}: input index out of range")
            if w.free is not None and w.free not in free_names:
                raise ValueError(f"weight {j}: unknown free weight {w.free!r}")
        for o in self.outputs:
            if not 0 <= o.layer < nl or not 0 <= o.neuron < self.layers[o.layer].size:
                raise ValueError(f"output {o.name!r}: layer/neuron out of range")
        for s in self.initial_states:
            if not 0 <= s.layer < nl or not 0 <= s.neuron < self.layers[s.layer].size:
                raise ValueError("initial state: layer/neuron out of range")
            if s.data is not None and s.data not in {o.name for o in self.outputs}:
                raise ValueError(f"initial state from data: {s.data!r} is not an output")
            if s.parameter is not None and s.parameter not in {p.name for p in self.parameters}:
                raise ValueError(f"initial state from parameter {s.parameter!r}: no such parameter")


def _matrix_sort_key(key: tuple) -> tuple:
    order = {"LW": 0, "IW": 1, "b": 2}[key[0]]
    return (key[1], order) + tuple(key[2:])


def _check_matrices(net: Network, matrices) -> None:
    derived = net.matrices()
    for entry in matrices:
        key = (entry["matrix"], entry["layer"]) + (
            () if entry["matrix"] == "b" else (entry["source"], entry["delay"])
        )
        if key not in derived:
            raise ValueError(f"matrix {key} in file has no weights in the weight list")
        if not np.array_equal(np.asarray(entry["admin"]), derived[key][1]):
            raise ValueError(f"administration matrix {key} disagrees with the weight list")

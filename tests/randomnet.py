"""Test fixtures: plain (unstructured) GDNNs as :class:`Network` files, and a helper to build networks by hand.

:func:`random_gdnn` follows the layout of pyrenn's ``CreateNN(nn, dIn, dIntern, dOut)``: inputs (with
``input_delays``) feed layer 0; layer m feeds layer m + 1 without delay; every layer m receives recurrent
connections from itself and from every later layer l >= m with ``internal_delays``, except that the output
layer feeds layer 0 with ``feedback_delays``; every neuron has a bias. With the defaults (1 input, delays
{0, 1}; 5 tanh neurons; 1 linear output; output feedback {1, 2}; internal delay {1}) that is

    IW 5*1*2 = 10, LW^{0,0}(1) 25, LW^{0,1}(1,2) 5*2 = 10, b^0 5, LW^{1,0}(0) 5, LW^{1,1}(1) 1, b^1 1  -> 57

weights, the count pyrenn reports for ``CreateNN([1, 5, 1], dIn=[0, 1], dIntern=[1], dOut=[1, 2])``. (The
output layer's own recurrence LW^{1,1}(1) is part of pyrenn's rule "from itself and every later layer".)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from flowchart2sdnn.network.model import (
    FreeWeightSpec,
    InitialState,
    InputSpec,
    LayerSpec,
    Network,
    NeuronSpec,
    OutputSpec,
    ParameterSpec,
    WeightSpec,
)

__all__ = ["random_gdnn", "hand_network"]


def random_gdnn(
    seed: int,
    n_inputs: int = 1,
    layers: Sequence[int] = (5, 1),
    input_delays: Sequence[int] = (0, 1),
    feedback_delays: Sequence[int] = (1, 2),
    internal_delays: Sequence[int] = (1,),
    transfers: Sequence[str] = ("tanh", "linear"),
) -> Network:
    """A fully connected GDNN in pyrenn's layout; every weight is a free weight with coef "1".

    Parameters
    ----------
    seed : int
        Seed of the numpy Generator that draws the initial free weights, uniform in [-0.5, 0.5].
    n_inputs : int
        Number of scalar inputs ("u0", "u1", ...).
    layers : sequence of int
        Neurons per layer; the last layer is the output ("y0", "y1", ...).
    input_delays, feedback_delays, internal_delays : sequence of int
        Delays of the input taps, of the output -> layer 0 feedback and of the other recurrences (>= 1).
    transfers : sequence of str
        Transfer function per layer.

    Returns
    -------
    Network
    """
    if len(transfers) != len(layers):
        raise ValueError(f"transfers has {len(transfers)} entries for {len(layers)} layers")
    if any(d < 1 for d in (*feedback_delays, *internal_delays)):
        raise ValueError("feedback and internal delays must be >= 1")
    rng = np.random.default_rng(seed)
    n_layers = len(layers)
    weights: list[WeightSpec] = []
    free: list[str] = []

    def add(name: str, **kw) -> None:
        free.append(name)
        weights.append(WeightSpec(free=name, origin=name, **kw))

    for m, size in enumerate(layers):
        if m == 0:
            for i in range(n_inputs):
                for d in input_delays:
                    for k in range(size):
                        add(f"IW0_{i}_d{d}[{k}]", matrix="IW", layer=0, row=k, source=i, delay=d)
        else:
            for k in range(size):
                for i in range(layers[m - 1]):
                    add(f"LW{m}_{m - 1}_d0[{k},{i}]", matrix="LW", layer=m, row=k, source=m - 1, col=i)
        for src in range(m, n_layers):
            delays = feedback_delays if (m == 0 and src == n_layers - 1) else internal_delays
            for d in delays:
                for k in range(size):
                    for i in range(layers[src]):
                        add(
                            f"LW{m}_{src}_d{d}[{k},{i}]",
                            matrix="LW",
                            layer=m,
                            row=k,
                            source=src,
                            col=i,
                            delay=d,
                        )
        for k in range(size):
            add(f"b{m}[{k}]", matrix="b", layer=m, row=k)

    init = rng.uniform(-0.5, 0.5, size=len(free))
    out = n_layers - 1
    net = Network(
        name=f"random_gdnn_{seed}",
        sample_time=1.0,
        inputs=tuple(InputSpec(f"u{i}") for i in range(n_inputs)),
        layers=tuple(
            LayerSpec(f"L{m}", tuple(NeuronSpec(f"L{m}[{k}]", transfers[m]) for k in range(size)))
            for m, size in enumerate(layers)
        ),
        weights=tuple(weights),
        outputs=tuple(OutputSpec(f"y{k}", out, k) for k in range(layers[-1])),
        free_weights=tuple(FreeWeightSpec(n, float(v)) for n, v in zip(free, init, strict=True)),
    )
    net.verify()
    return net


def hand_network(
    layers: Sequence[tuple[str, str | Sequence[str]]],
    weights: Iterable[WeightSpec],
    outputs: Sequence[tuple[str, int] | tuple[str, int, int]],
    inputs: Sequence[str] = ("u",),
    parameters: Mapping[str, float | ParameterSpec] | None = None,
    free_weights: Mapping[str, float | FreeWeightSpec] | None = None,
    initial_states: Iterable[InitialState] = (),
    sample_time: float = 1.0,
    name: str = "hand",
) -> Network:
    """Build a small network by hand (tests, examples).

    Parameters
    ----------
    layers : sequence of (name, transfer or transfers)
        One entry per layer; a single transfer makes a 1-neuron layer.
    weights : iterable of WeightSpec
    outputs : sequence of (name, layer) or (name, layer, neuron)
    inputs : sequence of str
    parameters, free_weights : mapping name -> initial value (or a full spec)
    initial_states : iterable of InitialState
    sample_time : float
    name : str

    Returns
    -------
    Network
        Verified.
    """
    layer_specs = []
    for lname, tr in layers:
        trs = (tr,) if isinstance(tr, str) else tuple(tr)
        neurons = tuple(NeuronSpec(lname if len(trs) == 1 else f"{lname}[{k}]", t) for k, t in enumerate(trs))
        layer_specs.append(LayerSpec(lname, neurons))
    params = tuple(
        v if isinstance(v, ParameterSpec) else ParameterSpec(k, float(v))
        for k, v in (parameters or {}).items()
    )
    fws = tuple(
        v if isinstance(v, FreeWeightSpec) else FreeWeightSpec(k, float(v))
        for k, v in (free_weights or {}).items()
    )
    net = Network(
        name=name,
        sample_time=sample_time,
        inputs=tuple(InputSpec(i) for i in inputs),
        layers=tuple(layer_specs),
        weights=tuple(weights),
        outputs=tuple(OutputSpec(*o) for o in outputs),
        parameters=params,
        free_weights=fws,
        initial_states=tuple(initial_states),
    )
    net.verify()
    return net

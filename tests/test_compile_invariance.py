"""Shuffling and renaming the blocks of a chart gives the same network up to the reported permutation.

In the style of networkx's tests: a seeded random reordering of the YAML (blocks, parameters, inputs) and a
seeded random bijection of names (blocks, inputs, parameters), so a lucky ordering or a lucky name cannot
make the test pass. Networks are compared through a canonical form keyed by (renamed) names, never by the
position of a layer, an input or a parameter.
"""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.network.model import Network

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
EXAMPLES = sorted(p.stem for p in DIAGRAMS.glob("*.yaml"))
SEEDS = [0, 1, 2, 3]
_TOKEN = re.compile(r"(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[A-Za-z_][A-Za-z0-9_]*")


def _load(name: str) -> dict:
    return yaml.safe_load((DIAGRAMS / f"{name}.yaml").read_text())


def _compile(doc: dict, name: str = "chart.yaml") -> Network:
    return compile_diagram(diagram_from_text(yaml.safe_dump(doc, sort_keys=False), name)).network


def _shuffled(doc: dict, rng: np.random.Generator, sections=("blocks",)) -> dict:
    out = dict(doc)
    for key in sections:
        items = list(doc.get(key) or {})
        order = rng.permutation(len(items))
        out[key] = {items[i]: doc[key][items[i]] for i in order}
    return out


def _rename_text(text: str, mapping: dict[str, str]) -> str:
    """Rename whole identifiers in an expression (numbers such as 1e3 are consumed whole, never renamed)."""
    return _TOKEN.sub(lambda m: mapping.get(m.group(), m.group()), text)


def _renaming(doc: dict, rng: np.random.Generator) -> dict[str, str]:
    """A seeded random bijection of every block, input and parameter name to fresh names in random order."""
    names = list(doc["blocks"]) + list(doc["inputs"]) + list(doc.get("parameters") or {})
    fresh = [f"n{int(k):03d}_{int(rng.integers(1000))}" for k in rng.permutation(len(names))]
    return dict(zip(names, fresh, strict=True))


def _renamed(doc: dict, mapping: dict[str, str]) -> dict:
    def term(t: str) -> str:
        sign = t[0] if t[0] in "+-" else ""
        return sign + mapping[t[len(sign):].strip()]

    blocks = {}
    for name, spec in doc["blocks"].items():
        spec = dict(spec)
        if "in" in spec:
            spec["in"] = [term(t) for t in spec["in"]] if isinstance(spec["in"], list) else term(spec["in"])
        if isinstance(spec.get("k"), str):
            spec["k"] = _rename_text(spec["k"], mapping)
        blocks[mapping[name]] = spec
    out = dict(doc)
    out["blocks"] = blocks
    out["inputs"] = {mapping[k]: v for k, v in doc["inputs"].items()}
    out["outputs"] = {mapping[k]: v for k, v in doc["outputs"].items()}
    out["parameters"] = {mapping[k]: v for k, v in (doc.get("parameters") or {}).items()}
    return out


def _rename_layer(name: str, mapping: dict[str, str]) -> str:
    """Layer names are block names, or 'block__out' for the read-out of a folded output block."""
    base, sep, tail = name.partition("__out")
    return mapping[base] + sep + tail


def _rename_free(name: str | None, mapping: dict[str, str]) -> str | None:
    if name is None:
        return None
    block, _, role = name.rpartition(".")
    return f"{mapping[block]}.{role}"


def canonical(net: Network, mapping: dict[str, str] | None = None, loops: bool = True) -> dict:
    """Everything structural about a network, keyed by names (renamed through `mapping`), not positions.

    loops=False keeps only the length of the loop each delayed edge breaks: among equally short loops through
    symmetric blocks, the one shown may follow the names (but never the YAML order).
    """
    ident = mapping or {}

    def ren(n: str) -> str:
        return ident.get(n, n)

    layer = [_rename_layer(la.name, ident) if mapping else la.name for la in net.layers]
    layers = {layer[m]: (la.kind, ren(la.block), tuple(n.transfer for n in la.neurons))
              for m, la in enumerate(net.layers)}
    weights = Counter()
    for w in net.weights:
        if w.matrix == "LW":
            source = layer[w.source]
        elif w.matrix == "IW":
            source = ren(net.inputs[w.source].name)
        else:
            source = None
        free = _rename_free(w.free, ident) if mapping else w.free
        weights[(w.matrix, layer[w.layer], w.row, source, w.col, w.delay, _rename_text(w.coef, ident), free)] += 1
    return {
        "layers": layers,
        "weights": weights,
        "delayed": {(ren(e.source), ren(e.target), e.delay, tuple(ren(n) for n in e.loop) if loops else len(e.loop))
                    for e in net.delayed_edges},
        "outputs": {ren(o.name): (layer[o.layer], o.neuron, o.unit) for o in net.outputs},
        "inputs": {ren(i.name): i.unit for i in net.inputs},
        "parameters": {ren(p.name): (p.init, p.unit, p.min, p.max, p.fixed) for p in net.parameters},
        "free": {(_rename_free(f.name, ident) if mapping else f.name, ren(f.block), f.role, f.fixed)
                 for f in net.free_weights},
        "initial": {(layer[s.layer], s.neuron, s.value, ren(s.data) if s.data else None)
                    for s in net.initial_states},
        "sample_time": net.sample_time,
    }


def _check_reported_permutation(a: Network, b: Network, mapping: dict[str, str]) -> None:
    """source['layer_of_block'] is the permutation: layer of block X in `a` is layer of mapping[X] in `b`."""
    pa, pb = a.source["layer_of_block"], b.source["layer_of_block"]
    assert set(pb) == {_rename_layer(n, mapping) for n in pa}
    for name, m in pa.items():
        mb = pb[_rename_layer(name, mapping)]
        assert b.layers[mb].name == _rename_layer(a.layers[m].name, mapping)
        assert b.layers[mb].neurons and len(b.layers[mb].neurons) == len(a.layers[m].neurons)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", EXAMPLES)
def test_shuffling_blocks_gives_an_identical_network(name, seed):
    doc = _load(name)
    base = _compile(doc)
    other = _compile(_shuffled(doc, np.random.default_rng(seed)))
    assert other == base  # every field: layers in the same order, the same weights, delays and initial values
    assert other.source["layer_of_block"] == base.source["layer_of_block"]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", EXAMPLES)
def test_shuffling_parameters_and_inputs_too_changes_nothing_but_their_order(name, seed):
    doc = _load(name)
    base = _compile(doc)
    other = _compile(_shuffled(doc, np.random.default_rng(seed), ("blocks", "parameters", "inputs")))
    assert canonical(other) == canonical(base)
    assert other.layers == base.layers
    assert other.delayed_edges == base.delayed_edges
    assert {f.name: f.init for f in other.free_weights} == {f.name: f.init for f in base.free_weights}


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", EXAMPLES)
def test_renaming_gives_the_same_network_up_to_the_reported_permutation(name, seed):
    rng = np.random.default_rng(100 + seed)
    doc = _load(name)
    mapping = _renaming(doc, rng)
    base = _compile(doc)
    renamed = _compile(_shuffled(_renamed(doc, mapping), rng, ("blocks", "parameters", "inputs")))
    assert canonical(renamed) == canonical(base, mapping)
    _check_reported_permutation(base, renamed, mapping)


def test_canonical_form_notices_a_changed_delay():
    """The comparison can fail: moving the feedback delay of the engine changes the canonical form."""
    doc = _load("engine")
    base = canonical(_compile(doc))
    moved = _load("engine")
    moved["blocks"]["MR1"]["in"] = "w1d"
    moved["blocks"]["w1d"] = {"type": "delay", "in": "w1", "n": 1}
    assert canonical(_compile(moved)) != base


def test_renaming_ties_are_broken_by_structure_not_by_yaml_order():
    """Two identical masses hanging off one input: their layers may swap, the network may not change."""
    text = """\
sdnn: 1
name: twins
sample_time: 0.001
inputs: {F: {}}
outputs: {xa: {}, xb: {}}
parameters: {m: {init: 2.0}, k: {init: 50.0}}
blocks:
  sa: {type: sum, in: [F, -ka]}
  va: {type: integrator, in: sa}
  xa: {type: integrator, in: va}
  ka: {type: gain, in: xa, k: k/m}
  sb: {type: sum, in: [F, -kb]}
  vb: {type: integrator, in: sb}
  xb: {type: integrator, in: vb}
  kb: {type: gain, in: xb, k: k/m}
"""
    doc = yaml.safe_load(text)
    base = _compile(doc)
    for seed in range(6):
        rng = np.random.default_rng(seed)
        mapping = _renaming(doc, rng)
        renamed = _compile(_shuffled(_renamed(doc, mapping), rng, ("blocks",)))
        assert canonical(renamed) == canonical(base, mapping)
        _check_reported_permutation(base, renamed, mapping)


DIAMOND = """\
sdnn: 1
name: diamond
sample_time: 0.001
inputs: {F: {}}
outputs: {v: {}}
parameters: {c1: {init: 2.0}, c2: {init: 3.0}, d: {init: 0.5}}
blocks:
  s:  {type: sum, in: [F, -fb]}
  v:  {type: integrator, in: s}
  g1: {type: gain, in: v, k: c1}
  g2: {type: gain, in: v, k: c2}
  t:  {type: sum, in: [g1, g2]}
  fb: {type: gain, in: t, k: d}
"""


@pytest.mark.parametrize("seed", SEEDS)
def test_the_loop_shown_for_a_delayed_edge_does_not_depend_on_yaml_order(seed):
    """Two equally short ways round the loop (via g1 or g2): the one reported must not follow the YAML."""
    doc = yaml.safe_load(DIAMOND)
    base = _compile(doc)
    rng = np.random.default_rng(seed)
    assert _compile(_shuffled(doc, rng)) == base
    mapping = _renaming(doc, rng)
    renamed = _compile(_shuffled(_renamed(doc, mapping), rng))
    assert canonical(renamed, loops=False) == canonical(base, mapping, loops=False)
    chart = yaml.safe_load(DIAMOND)["blocks"]
    inverse = {v: k for k, v in mapping.items()}
    for e in renamed.delayed_edges:  # still a loop of the chart, through the delayed edge
        loop = [inverse[n] for n in e.loop]
        for a, b in zip(loop, loop[1:] + loop[:1], strict=True):
            ins = chart[b]["in"] if isinstance(chart[b]["in"], list) else [chart[b]["in"]]
            assert a in [t.lstrip("+-") for t in ins]

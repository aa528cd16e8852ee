"""Text renderings of a compiled network: every weight as an equation, the neuron graph as DOT. Pure functions."""

from __future__ import annotations

from .model import Network

__all__ = ["explain_network", "network_dot"]


def _weight_label(net: Network, j: int) -> str:
    w = net.weights[j]
    m = w.layer + 1
    if w.matrix == "b":
        return f"b{{{m}}}[{w.row + 1}]"
    return f"{w.matrix}{{{m},{w.source + 1}}}({w.delay})[{w.row + 1},{w.col + 1}]"


def explain_network(net: Network) -> str:
    """Every layer, every weight as an equation of physical parameters, every delayed edge and its loop."""
    values = net.weight_values()
    n_neurons = sum(la.size for la in net.layers)
    lines = [
        f"network {net.name}: {len(net.layers)} layers, {n_neurons} neurons, {len(net.inputs)} input(s), "
        f"{len(net.weights)} weights, sample time T = {net.sample_time:g} s"
        + (f", {net.substeps} steps per sample (h = {net.step:g} s; delays count steps)" if net.substeps > 1 else ""),
        "numbering as in the paper: layer m, neuron m.k, both from 1; LW{m,l}(d)[k,i] is the weight from neuron l.i "
        "delayed d samples to neuron m.k",
        "",
        "layers:",
    ]
    for m, la in enumerate(net.layers):
        transfers = ",".join(sorted({n.transfer for n in la.neurons}))
        if any(n.net_input == "prod" for n in la.neurons):  # MATLAB's name for a product net input
            transfers = "netprod (n = product of the weighted inputs), " + transfers
        lines.append(f"  {m + 1:>3}  {la.name:<14} {la.kind or '':<11} {la.size} neuron(s)  {transfers}")
    lines += ["", "inputs:"]
    lines += [f"  p{i + 1} = {s.name}" + (f" [{s.unit}]" if s.unit else "")
              + (", linear between samples" if s.intersample == "linear" else "")
              + (f", delayed by {s.delay} s (each step its mean over the step)" if s.delay is not None else "")
              for i, s in enumerate(net.inputs)]
    lines += ["", "weights (value = coefficient x learned weight; chart path in brackets):"]
    for j, w in enumerate(net.weights):
        rhs = w.coef if w.free is None else (w.free if w.coef == "1" else f"({w.coef}) * {w.free}")
        kind = "fixed"
        if w.free is not None:
            kind = "learned"
        elif any(p.name in _names(w.coef) and not p.fixed for p in net.parameters):
            kind = "parameter"
        lines.append(f"  {_weight_label(net, j):<22} = {rhs:<28} = {values[j]:<12.6g} {kind:<9} [{w.origin or ''}]")
    lines += ["", "outputs:"]
    for o in net.outputs:
        lines.append(f"  {o.name} = neuron {o.layer + 1}.{o.neuron + 1}" + (f" [{o.unit}]" if o.unit else ""))
    if net.initial_states:
        lines += ["", "initial states (value before the first sample):"]
        for s in net.initial_states:
            value = f"first measured sample of {s.data}" if s.data else f"{s.value:g}"
            lines.append(f"  neuron {s.layer + 1}.{s.neuron + 1} ({net.layers[s.layer].name}) = {value}")
    lines += ["", "delayed edges (explicit Euler in feedback paths; forward paths stay implicit):"]
    if not net.delayed_edges:
        lines.append("  none")
    for e in net.delayed_edges:
        loop = " -> ".join(e.loop + (e.loop[0],)) if e.loop else ""
        lines.append(f"  {e.source} -> {e.target} delayed {e.delay} sample(s); breaks loop {loop}")
    return "\n".join(lines) + "\n"


def _names(expr_text: str) -> set[str]:
    import re

    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", expr_text))


def network_dot(net: Network) -> str:
    """Graphviz drawing of the discrete network, neurons numbered layer.position as in the paper's Fig. 5."""
    lines = [f'digraph "{_dot_text(net.name)}" {{', "  rankdir=LR;", '  node [shape=circle, fontsize=10];']
    for i, s in enumerate(net.inputs):
        lines.append(f'  "p{i + 1}" [shape=box, label="{s.name}"];')
    for m, la in enumerate(net.layers):
        for k, n in enumerate(la.neurons):
            shape = "doublecircle" if n.transfer != "linear" or n.net_input == "prod" else "circle"
            lines.append(f'  "{m + 1}.{k + 1}" [shape={shape}, label="{m + 1}.{k + 1}\\n{n.name}\\n{n.transfer}"];')
    for w in net.weights:
        target = f"{w.layer + 1}.{w.row + 1}"
        label = w.coef if w.free is None else (w.free if w.coef == "1" else f"{w.coef}*{w.free}")
        if w.delay:
            label += f" z^-{w.delay}"
        if w.matrix == "LW":
            source = f"{w.source + 1}.{w.col + 1}"
        elif w.matrix == "IW":
            source = f"p{w.source + 1}"
        else:
            source = f"bias_{target}"
            lines.append(f'  "{source}" [shape=point];')
        style = ", style=dashed" if w.delay else ""
        lines.append(f'  "{source}" -> "{target}" [label="{label}"{style}];')
    for o in net.outputs:
        lines.append(f'  "out_{o.name}" [shape=box, label="{o.name}"];')
        lines.append(f'  "{o.layer + 1}.{o.neuron + 1}" -> "out_{o.name}";')
    lines.append("}")
    return "\n".join(lines) + "\n"


def _dot_text(text: str) -> str:
    """Text inside a DOT double-quoted string: a chart name may hold quotes, backslashes or line breaks."""
    return text.replace("\\", "\\\\").replace('"', '\\"').replace("\r", "").replace("\n", "\\n")

"""The chart as a block diagram in SVG, as the user wrote it: no Graphviz needed.

Blocks are placed in columns by their distance from the chart's inputs along the forward paths (edges that
close a loop are found by a depth-first search from the inputs and drawn as feedback, bending below the
diagram), ordered within a column by the mean row of their sources (one barycentre sweep, which is enough
for the charts of a drive). Each block is a box with its name, its kind and its factor or function; a sum
shows the signs of its inputs on the arrows. Blocks named in ``highlight`` (e.g. what diagnose added) are
drawn in another colour. The layout depends only on the chart's structure and names, never on YAML order.

Layer: analysis (below it: the chart).
"""

from __future__ import annotations

from collections.abc import Iterable
from xml.sax.saxutils import escape

import networkx as nx

from ..diagram.blocks import block_type
from ..diagram.model import Block, Diagram
from .graph import chart_graph

__all__ = ["chart_svg"]

_W, _H, _DX, _DY, _M = 150, 46, 70, 26, 30  # box width/height, gaps between columns/rows, margin


def _label(b: Block) -> str:
    return block_type(b.kind).label(b)


def _feedback_edges(g: nx.DiGraph, roots: list[str]) -> set[tuple[str, str]]:
    """Edges that close a cycle in a depth-first search from the inputs (then from any node left), in name
    order: removing them leaves a DAG that orders the columns."""
    back: set[tuple[str, str]] = set()
    state: dict[str, int] = {}
    for root in roots + sorted(g.nodes):
        if root in state:
            continue
        stack = [(root, iter(sorted(g.successors(root))))]
        state[root] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
            elif state.get(nxt) == 1:
                back.add((node, nxt))
            elif nxt not in state:
                state[nxt] = 1
                stack.append((nxt, iter(sorted(g.successors(nxt)))))
    return back


def _layout(diagram: Diagram) -> tuple[dict[str, tuple[int, int]], set[tuple[str, str]], nx.DiGraph]:
    g = chart_graph(diagram)
    back = _feedback_edges(g, sorted(s.name for s in diagram.inputs))
    dag = nx.DiGraph(g)
    dag.remove_edges_from(back)
    column: dict[str, int] = {}
    for node in nx.lexicographical_topological_sort(dag):
        column[node] = max((column[p] + 1 for p in dag.predecessors(node)), default=0)
    columns: dict[int, list[str]] = {}
    for node in sorted(column, key=lambda n: (column[n], n)):
        columns.setdefault(column[node], []).append(node)
    row: dict[str, float] = {}
    for c in sorted(columns):
        nodes = columns[c]
        for i, n in enumerate(nodes):
            srcs = [row[p] for p in dag.predecessors(n) if p in row]
            row[n] = sum(srcs) / len(srcs) if srcs else float(i)
        for i, n in enumerate(sorted(nodes, key=lambda n: (row[n], n))):
            row[n] = float(i)
    return {n: (column[n], int(row[n])) for n in column}, back, g


def chart_svg(diagram: Diagram, highlight: Iterable[str] = ()) -> str:
    """The chart as a standalone SVG document (text).

    Parameters
    ----------
    diagram : Diagram
    highlight : names of blocks to draw in the highlight colour (e.g. the effects diagnose added)
    """
    place, back, g = _layout(diagram)
    marked = set(highlight)
    blocks = {b.name: b for b in diagram.blocks}
    outputs = set(diagram.output_names)
    n_cols = max((c for c, _ in place.values()), default=0) + 1
    n_rows = max((r for _, r in place.values()), default=0) + 1
    width = 2 * _M + n_cols * _W + (n_cols - 1) * _DX
    height = 2 * _M + n_rows * _H + (n_rows - 1) * _DY + 20 * (len(back) + 1)
    bottom = _M + n_rows * (_H + _DY)

    def xy(name: str) -> tuple[float, float]:
        c, r = place[name]
        return _M + c * (_W + _DX), _M + r * (_H + _DY)

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">',
           f"<title>{escape(diagram.name)}</title>",
           '<defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" markerHeight="7" '
           'orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="#444"/></marker></defs>']
    signs = {(t.signal, b.name): t.sign for b in diagram.blocks for t in b.inputs}
    for k, (u, v) in enumerate(sorted(g.edges)):
        (x1, y1), (x2, y2) = xy(u), xy(v)
        sign = signs.get((u, v), 1)
        colour = "#444"
        if (u, v) in back:
            # feedback: out of the source's right side, down the gap after its column, back along a lane below
            # the diagram, up the gap before the target's column and into its left side: gaps hold no boxes
            lane = bottom + 12 * (k % 6)
            jog = 10 + 5 * (k % 8)
            sy, ty = y1 + _H * 0.75, y2 + _H * 0.75
            gx1, gx2 = x1 + _W + jog, x2 - jog
            path = (f"M {x1 + _W} {sy} L {gx1} {sy} L {gx1} {lane} L {gx2} {lane} L {gx2} {ty} L {x2} {ty}")
            colour = "#1f5fa8"
            lx, ly = x2 - 12, ty + 12
        else:
            sx, sy, tx, ty = x1 + _W, y1 + _H / 2, x2, y2 + _H / 2
            mid = (sx + tx) / 2
            path = f"M {sx} {sy} C {mid} {sy}, {mid} {ty}, {tx} {ty}"
            lx, ly = tx - 12, ty - 4
        out.append(f'<path d="{path}" fill="none" stroke="{colour}" stroke-width="1.2" marker-end="url(#arrow)" '
                   f'data-edge="{escape(u)}->{escape(v)}"/>')
        if blocks.get(v) is not None and blocks[v].kind == "sum":
            out.append(f'<text x="{lx}" y="{ly}" fill="{colour}">{"+" if sign > 0 else "−"}</text>')
    for name in sorted(place):
        x, y = xy(name)
        b = blocks.get(name)
        kind = "input" if b is None else _label(b)
        fill = "#fde2b8" if name in marked else ("#e8eef7" if b is None else "#f7f7f7")
        stroke = "#c76b00" if name in marked else ("#1f5fa8" if name in outputs else "#555")
        width_px = 2.5 if name in outputs or name in marked else 1.0
        out.append(f'<rect x="{x}" y="{y}" width="{_W}" height="{_H}" rx="6" fill="{fill}" stroke="{stroke}" '
                   f'stroke-width="{width_px}"/>')
        out.append(f'<text x="{x + _W / 2}" y="{y + 19}" text-anchor="middle" font-weight="bold">'
                   f"{escape(name)}</text>")
        out.append(f'<text x="{x + _W / 2}" y="{y + 35}" text-anchor="middle" fill="#333">'
                   f"{escape(kind[:28])}</text>")
    out.append(f'<text x="{_M}" y="{height - 8}" fill="#555">{escape(diagram.name)}: blocks as written; '
               "blue arrows close loops, thick outlines are outputs"
               + (", orange blocks were added by diagnose" if marked else "") + "</text>")
    out.append("</svg>")
    return "\n".join(out) + "\n"

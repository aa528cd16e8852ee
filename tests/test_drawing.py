"""The chart as a block diagram (SVG without Graphviz): every block and every connection drawn, the loops found
by the layout are exactly the chart's cycles broken once, and the drawing does not depend on YAML order."""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import networkx as nx
import pytest
from click.testing import CliRunner

from flowchart2sdnn.analysis.drawing import chart_svg
from flowchart2sdnn.analysis.graph import chart_graph
from flowchart2sdnn.cli import main
from flowchart2sdnn.diagram.validate import load_diagram

ROOT = Path(__file__).resolve().parent.parent
NS = {"s": "http://www.w3.org/2000/svg"}
CHARTS = ["two_mass.yaml", "three_mass.yaml", "engine.yaml", "dc_motor.yaml"]


def _parsed(svg: str) -> ET.Element:
    return ET.fromstring(svg)


@pytest.mark.parametrize("name", CHARTS)
def test_every_block_and_connection_is_drawn(name):
    d = load_diagram(ROOT / "diagrams" / name)
    root = _parsed(chart_svg(d))
    boxes = root.findall("s:rect", NS)
    labels = {t.text for t in root.findall("s:text", NS)}
    g = chart_graph(d)
    assert len(boxes) == g.number_of_nodes()
    assert {b.name for b in d.blocks} | set(d.input_names) <= labels
    edges = [tuple(p.get("data-edge").split("->")) for p in root.findall("s:path", NS)]
    assert sorted(edges) == sorted(g.edges)
    # the feedback arrows (blue) break every cycle of the chart, and only cycles: without them the graph is
    # acyclic, and each of them closes a cycle (its target reaches its source)
    feedback = [tuple(p.get("data-edge").split("->")) for p in root.findall("s:path", NS)
                if p.get("stroke") == "#1f5fa8"]
    rest = nx.DiGraph(g)
    rest.remove_edges_from(feedback)
    assert nx.is_directed_acyclic_graph(rest)
    assert all(nx.has_path(g, v, u) for u, v in feedback)
    assert bool(feedback) == (not nx.is_directed_acyclic_graph(g))


@pytest.mark.parametrize("name", CHARTS)
def test_the_drawing_does_not_depend_on_yaml_order(name):
    d = load_diagram(ROOT / "diagrams" / name)
    blocks = list(d.blocks)
    random.Random(3).shuffle(blocks)
    assert chart_svg(replace(d, blocks=tuple(blocks))) == chart_svg(d)


def test_added_blocks_are_highlighted_and_the_cli_writes_the_file(tmp_path):
    d = load_diagram(ROOT / "diagrams" / "two_mass.yaml")
    root = _parsed(chart_svg(d, highlight=["MR1"]))
    orange = [r for r in root.findall("s:rect", NS) if r.get("fill") == "#fde2b8"]
    assert len(orange) == 1
    out = tmp_path / "c.svg"
    res = CliRunner().invoke(main, ["compile", str(ROOT / "diagrams" / "two_mass.yaml"), "--svg", str(out)])
    assert res.exit_code == 0, res.output
    assert _parsed(out.read_text()).tag.endswith("svg")

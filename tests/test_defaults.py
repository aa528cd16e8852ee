"""A chart without `substeps` and `delays` gets `auto` and `torques` (issue 13's defaults).

Oracles: the undamped frequency sqrt(k/m) for auto's N, the torque edges listed by hand from the three-mass
chart, the one loop of a chart without a speed sum (where `torques` has nothing to prefer: the search's edge).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from flowchart2sdnn.analysis.loops import analyse_loops
from flowchart2sdnn.cli.main import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.compiler.substeps import AUTO_BOUND
from flowchart2sdnn.diagram.dump import dump_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text, load_diagram
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"


def _without_keys(text: str) -> str:
    return re.sub(r"^(substeps|delays):.*\n", "", text, flags=re.M)


def _msd_text(k: float = 1250) -> str:
    """diagrams/mass_spring_damper.yaml (m = 2, no keys) with the spring k."""
    text = (DIAGRAMS / "mass_spring_damper.yaml").read_text()
    assert "substeps:" not in text and "delays:" not in text  # the bundled example shows the defaults
    return text.replace("init: 800", f"init: {k:g}")


def test_a_chart_without_the_keys_compiles_at_auto():
    """omega_n = sqrt(k/m) = 25 rad/s: auto's N is the smallest with omega*T/N <= bound, as `substeps: auto`."""
    diagram = diagram_from_text(_msd_text(), "msd.yaml")
    assert diagram.substeps is None and diagram.delays is None
    comp = compile_diagram(diagram)
    expected = math.ceil(math.sqrt(1250 / 2.0) * 0.001 / AUTO_BOUND - 1e-9)
    assert expected > 1 and comp.network.substeps == expected
    assert comp.substeps.requested is None and "auto (the default)" in comp.substeps.explain(0.001)
    explicit = compile_diagram(diagram_from_text(_msd_text().replace("sample_time:", "substeps: auto\n"
                                                                     "delays: torques\nsample_time:"), "msd.yaml"))
    assert explicit.network.weights == comp.network.weights
    assert explicit.network.delayed_edges == comp.network.delayed_edges


def test_a_chart_without_the_keys_delays_the_torques():
    """Three masses: every shaft and friction torque where it enters a Newton sum, none of the speeds."""
    d = diagram_from_text(_without_keys((DIAGRAMS / "three_mass_plant.yaml").read_text()), "plant.yaml")
    assert d.delays is None
    delayed = {(u, v) for u, v, _ in analyse_loops(d).delayed_edges}
    assert delayed == {("MC1", "MB1"), ("MD1", "MB1"), ("MR1", "MB1"), ("MC1", "MB2"), ("MD1", "MB2"),
                       ("MC2", "MB2"), ("MD2", "MB2"), ("MR2", "MB2"), ("MC2", "MB3"), ("MD2", "MB3"),
                       ("MR3", "MB3")}


NO_SPEED_SUM = """\
sdnn: 1
name: leak
sample_time: 0.01
{extra}
inputs:
  u: {{}}
outputs:
  x: {{}}
parameters:
  a: {{init: 2.0, min: 0}}
blocks:
  s: {{type: sum, in: [u, -ax]}}
  x: {{type: integrator, in: s}}
  ax: {{type: gain, in: x, k: a}}
"""


def test_torques_falls_back_to_the_search_without_a_speed_sum():
    """s feeds its integrator directly (no gain between): no speed sum, so the loop s -> x -> ax -> s is broken
    where the search breaks it, on the edge back into the sum from the forward path u -> s -> x."""
    nets = {}
    for extra in ("", "delays: torques", "delays: search"):
        net = compile_diagram(diagram_from_text(NO_SPEED_SUM.format(extra=extra), "leak.yaml")).network
        nets[extra] = net
        assert {(e.source, e.target) for e in net.delayed_edges} == {("ax", "s")}
    assert nets[""].weights == nets["delays: search"].weights


def test_compile_explain_prints_the_default_n(tmp_path):
    chart = tmp_path / "msd.yaml"
    chart.write_text(_msd_text())
    out = CliRunner().invoke(main, ["compile", str(chart), "--explain"])
    assert out.exit_code == 0, out.output
    n = math.ceil(math.sqrt(1250 / 2.0) * 0.001 / AUTO_BOUND - 1e-9)
    assert f"substeps N = {n} " in out.output and "auto (the default)" in out.output
    one = CliRunner().invoke(main, ["compile", str(chart), "--explain", "--substeps", "1"])
    assert "substeps N = 1 " in one.output and "auto" not in one.output.split("substeps N = 1")[1]


@pytest.mark.parametrize("pinned", ["paper/engine.yaml", "paper/two_mass.yaml", "paper/plant.yaml"])
def test_the_papers_charts_pin_its_scheme(pinned):
    """The paper's experiment keeps the network it was measured with."""
    d = load_diagram(DIAGRAMS / pinned)
    assert (d.substeps, d.delays) == (1, "search")
    assert compile_diagram(d).network.substeps == 1


@pytest.mark.parametrize("chart", ["engine.yaml", "two_mass.yaml"])
def test_the_charts_users_copy_take_the_accurate_scheme(chart):
    """The README tour's charts fit on mid-step torques and several steps per sample, not the paper's network."""
    d = load_diagram(DIAGRAMS / chart)
    assert d.delays == "midpoint" and isinstance(d.substeps, int) and d.substeps > 1
    assert compile_diagram(d).network.substeps == d.substeps


def test_identify_records_the_default_and_dumps_the_fitted_n(tmp_path):
    """RESULT.json: requested null (not given), the auto N used, delays torques; the identified chart names that
    N and that rule, so that it reloads onto the network it was fitted with."""
    import flowchart2sdnn as sd

    chart = tmp_path / "msd.yaml"
    chart.write_text(_msd_text())
    d = load_diagram(chart)
    data = excite(d, ExcitationSettings(seconds=0.3, seed=1))
    ds = sd.dataset_from_frame(__import__("pandas").DataFrame(data), time="time", inputs=d.input_names,
                               outputs=d.output_names)
    result = sd.identify(d, ds, max_iter=1)
    n = math.ceil(math.sqrt(1250 / 2.0) * 0.001 / AUTO_BOUND - 1e-9)
    disc = json.loads(result.to_json())["discretization"]
    assert (disc["substeps"], disc["requested"], disc["delays"]) == (n, None, "torques")
    assert disc["step"] == pytest.approx(0.001 / n)
    assert result.chart.substeps == n and result.chart.delays == "torques"
    out = tmp_path / "identified.yaml"
    out.write_text(dump_diagram(result.chart))
    again = load_diagram(out)
    assert again.substeps == n and compile_diagram(again).network.substeps == n
    assert compile_diagram(again).network.delayed_edges == compile_diagram(d).network.delayed_edges


def test_the_api_follows_the_chart_defaults_and_takes_an_override(tmp_path):
    import flowchart2sdnn as sd

    chart = tmp_path / "msd.yaml"
    chart.write_text(_msd_text())
    n = math.ceil(math.sqrt(1250 / 2.0) * 0.001 / AUTO_BOUND - 1e-9)
    assert sd.compile_chart(chart).network.substeps == n
    one = sd.compile_chart(chart, substeps=1)
    assert one.network.substeps == 1 and one.substeps.requested == 1

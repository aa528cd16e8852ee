"""Progress a newcomer can read: each LM iteration with its cost and the cost's fall (never a percentage of
--max-iter, a limit rather than a goal); a bar only where there is a true fraction (starts, files)."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.cli import terminal
from flowchart2sdnn.cli.terminal import Progress
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.optimize import iteration_text
from flowchart2sdnn.identify.offline.run import identify
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parents[1]
LINE = re.compile(r"^LM iteration (\d+): cost (\S+)(?:, ([+-]\S+) %)?$")


def test_each_iteration_reports_its_cost_and_fall_as_the_trainer_recorded_them(tmp_path):
    """The oracle is the trainer's own cost history (the result's optimizer trace), not the progress text."""
    chart = replace(load_diagram(ROOT / "diagrams" / "mass_spring_damper.yaml"), substeps=1)
    columns = excite(chart, ExcitationSettings(seconds=0.3, seed=5, amplitude=(-50.0, 50.0), noise_std=1e-5))
    write_csv(tmp_path / "msd.csv", columns, float_format="%.17g")
    data = sd.read_csv(tmp_path / "msd.csv")
    # a start off the truth, so the fit takes several iterations
    chart = replace(chart, parameters=tuple(replace(p, init=p.init * 1.3) for p in chart.parameters))
    calls: list[tuple[str, float | None]] = []
    result = identify(chart, data, progress=lambda text, fraction: calls.append((text, fraction)),
                      max_iter=30, shooting="off", floor_bias=False)
    history = result.optimizer.cost_history
    lines = [(LINE.match(text), fraction) for text, fraction in calls if text.startswith("LM iteration")]
    assert len(lines) >= 3 and all(m is not None for m, _ in lines), calls
    assert all(fraction is None for _, fraction in lines)  # no bar: max_iter is a safety limit
    for m, _ in lines:
        k = int(m.group(1))
        assert float(m.group(2)) == pytest.approx(history[k], rel=1e-3)
        if k == 1:
            assert m.group(3) is None  # the first report has nothing to fall from
        else:
            fall = 100 * (history[k] - history[k - 1]) / history[k - 1]
            assert float(m.group(3)) == pytest.approx(fall, rel=0.06, abs=1e-12)


def test_iteration_text_without_a_previous_cost_has_no_fall():
    assert iteration_text(1, 0.5) == "LM iteration 1: cost 5.000e-01"
    assert iteration_text(2, 0.25, 0.5).endswith(", -50 %")
    assert iteration_text(3, 0.25, 0.0) == "LM iteration 3: cost 2.500e-01"  # nothing to divide by


@pytest.fixture
def clock(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(terminal.time, "monotonic", lambda: now[0])
    return now


def test_progress_shows_a_bar_only_for_a_true_fraction(clock, capsys):
    progress = Progress(quiet=False)
    progress.tty = False
    clock[0] += 10
    progress("LM iteration 12: cost 3.410e-02, -12 %", None)
    clock[0] += 10
    progress("start 2/4: cost 1.2 (small_cost_change)", 0.5)
    err = capsys.readouterr().err.splitlines()
    assert err == ["LM iteration 12: cost 3.410e-02, -12 % (10 s)",
                   "[" + "#" * 10 + "." * 10 + "]  50% start 2/4: cost 1.2 (small_cost_change) (20 s)"]


def test_quiet_progress_and_the_first_second_print_nothing(clock, capsys):
    Progress(quiet=True)("LM iteration 1: cost 1", None)
    clock[0] += 0.5
    Progress(quiet=False)("LM iteration 1: cost 1", None)
    assert capsys.readouterr().err == ""

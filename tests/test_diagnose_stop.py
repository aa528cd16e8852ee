"""How a diagnose run ends (issue 16): no tracing from an unconverged first fit, a ``stop`` that describes the
whole run, and validation records started from their first n samples (``--init-window``) and read with
``--map``.

Data: continuous simulations of small plant charts with measurement noise (never the model under test); the
truths are the plants' own values.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from diagnose_bench import DATA, chart, record

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose, whole_run_stop
from flowchart2sdnn.report.diagnose_text import STOP_MESSAGES, format_report

NOISE = 0.02
EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
EFFECTS = [BUILTIN_EFFECTS[n] for n in ("friction", "damping")]
V0 = 1.5  # the validation plant's speed at t = 0 (m/s): the record starts in motion


def _moving_plant():
    """The friction plant started at v = V0 instead of at rest."""
    plant = chart("one_mass_friction_plant")
    return replace(plant, blocks=tuple(replace(b, init=V0) if b.name == "v" else b for b in plant.blocks))


@pytest.fixture(scope="module")
def records():
    plant = chart("one_mass_friction_plant")
    return record(plant, 5.0, 3, NOISE, **EXCITATION), record(_moving_plant(), 2.0, 101, NOISE, **EXCITATION)


def test_whole_run_stop_by_hand():
    assert whole_run_stop("nothing_accepted", 0) == "nothing_accepted"
    assert whole_run_stop("nothing_accepted", 2) == "done_after_accepting"
    assert whole_run_stop("nothing_significant", 1) == "done_after_accepting"
    assert whole_run_stop("rounds", 3) == "rounds"
    assert whole_run_stop("interrupted", 1) == "interrupted"
    assert {"done_after_accepting", "first_fit_not_converged"} <= set(STOP_MESSAGES)


def test_an_unconverged_first_fit_is_not_traced(records):
    train, val = records
    d = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(max_iter=1, rounds=2), EFFECTS)
    r = d.report
    assert r["first_fit"]["converged"] is False and r["first_fit"]["status"] == "max_iter"
    assert r["stop"] == r["last_round"] == "first_fit_not_converged"
    assert r["first_fit"]["still_moving"]  # one iteration from the chart's init: the parameters still move
    assert r["candidates"] == [] and r["rounds"] == [] and r["accepted"] == [] and r["n_accepted"] == 0
    assert "still moved by more than their standard error" in format_report(r)
    # on request it traces anyway (and friction is what this plant lacks)
    anyway = diagnose(chart("one_mass"), train, [val],
                      DiagnoseSettings(max_iter=1, rounds=1, require_converged=False), EFFECTS).report
    assert anyway["stop"] != "first_fit_not_converged" and anyway["candidates"]


def test_stop_describes_the_whole_run():
    plant = chart("one_mass_friction_plant")
    train, val = record(plant, 6.0, 3, NOISE, **EXCITATION), record(plant, 3.0, 101, NOISE, **EXCITATION)
    r = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(rounds=3), EFFECTS).report
    assert r["first_fit"]["converged"] is True
    assert r["accepted"] and r["n_accepted"] == len(r["accepted"])
    assert r["last_round"] in ("nothing_accepted", "nothing_significant")
    # a last round refitted and accepted nothing, or found nothing significant to refit
    assert len(r["rounds"]) > len(r["accepted"]) or r["last_round"] == "nothing_significant"
    assert r["stop"] == "done_after_accepting"
    assert "stopped: effects were accepted" in format_report(r)


def test_init_window_starts_each_validation_record_from_its_first_samples(records):
    train, val = records
    n = 20
    s = DiagnoseSettings(rounds=0, init_window=n)
    r = diagnose(chart("one_mass"), train, [val, val], s, EFFECTS)
    for m in r.final.validation["records"]:
        assert m["rows"] == val.n_rows - n  # scored from row n
        v0 = m["initial_state"]["values"]["v"]
        # the plant's own initial speed, within the noise averaged over the window (and the chart's error)
        assert abs(v0 - V0) < 4 * NOISE / math.sqrt(n) + 0.01
    # without the window: started from the chart's own initial state, scored from the first aligned row
    plain = diagnose(chart("one_mass"), train, [val], replace(s, init_window=0), EFFECTS).final
    assert plain.validation["records"][0]["rows"] >= val.n_rows - 1
    assert "initial_state" not in plain.validation["records"][0]
    with pytest.raises(ValueError, match="init_window"):
        diagnose(chart("one_mass"), train, [], s, EFFECTS)
    with pytest.raises(ValueError, match="init_window"):
        DiagnoseSettings(init_window=5, split=0.5)


# ------------------------------------------------------------------------------------------------ CLI
@pytest.fixture(scope="module")
def files(tmp_path_factory, records):
    d = tmp_path_factory.mktemp("stop")
    train, val = records
    write_csv(d / "train.csv", {"time": train.time, "F": train.columns["F"], "v": train.columns["v"]})
    # the validation record names its columns differently: --map must apply to it too
    write_csv(d / "val.csv", {"time": val.time, "force": val.columns["F"], "speed": val.columns["v"]})
    write_csv(d / "train_named.csv", {"time": train.time, "force": train.columns["F"], "speed": train.columns["v"]})
    return d


def test_cli_init_window_and_map_on_every_record(files):
    rep = files / "rep.json"
    args = ["diagnose", str(DATA / "one_mass.yaml"), str(files / "train_named.csv"),
            "--validate", str(files / "val.csv"), "--map", "F=force", "--map", "v=speed", "--init-window", "10",
            "--effects", "damping", "--rounds", "0", "--report", str(rep), "--quiet"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    report = json.loads(rep.read_text())
    val = report["after"]
    assert report["settings"]["init_window"] == 10 and report["command"]["map"] == {"F": "force", "v": "speed"}
    assert np.isfinite(val["validation_rms"]) and val["validation_initial_state"][0]["window"] == 10
    # without --map the validation record's columns are not found: one line, exit 1
    bare = [a for a in args if a not in ("--map", "F=force", "v=speed")]
    bare[2] = str(files / "train.csv")
    bare[bare.index("--report") + 1] = str(files / "rep2.json")
    res = CliRunner().invoke(main, bare)
    assert res.exit_code == 1 and "val.csv" in res.output and len(res.output.strip().splitlines()) == 1


def test_cli_init_window_needs_a_validation_record(files):
    res = CliRunner().invoke(main, ["diagnose", str(files / "train.csv"), "--diagram", str(DATA / "one_mass.yaml"),
                                    "--init-window", "5"])
    assert res.exit_code == 2 and "--init-window" in res.output


def test_cli_refuses_an_unconverged_first_fit_in_one_line(files):
    rep = files / "unconverged.json"
    res = CliRunner().invoke(main, ["diagnose", str(DATA / "one_mass.yaml"), str(files / "train.csv"),
                                    "--max-iter", "1", "--effects", "damping", "--report", str(rep), "--quiet"])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "still moved by more than their standard error" in lines[0]
    assert "nothing traced" in lines[0]
    assert json.loads(rep.read_text())["stop"] == "first_fit_not_converged"


def test_still_moving_names_what_one_iteration_left_and_nothing_at_the_minimum(records):
    """The oracle: the standard errors and the Gauss-Newton step recomputed here with numpy from (J, e)."""
    import numpy as np

    from flowchart2sdnn.diagnose.fitting import fit_chart, still_moving

    train, val = records
    settings = DiagnoseSettings()
    early = fit_chart(chart("one_mass"), [train], [(val, 0)], settings, 1, 0, "chart")
    done = fit_chart(chart("one_mass"), [train], [(val, 0)], settings, settings.max_iter, 0, "chart")
    assert done.identification.converged and still_moving(done) == []
    moving = still_moving(early)
    assert moving
    p = early.identification.problem
    e, J = p.fun(np.asarray(early.identification.x))
    step = np.linalg.lstsq(J, e, rcond=None)[0]
    i = p.names.index(moving[0])
    assert abs(step[i]) > np.sqrt(float(e @ e) / len(e) * np.linalg.pinv(J.T @ J)[i, i])


class _Cubic:
    """A one-quantity problem y = x^3 with the record y = 8: the Gauss-Newton step from x = 0.5 overshoots to 11."""

    def bounds(self):
        return np.array([-np.inf]), np.array([np.inf])

    def residual(self, x):
        return np.array([8.0 - x[0] ** 3])


def test_a_step_counts_only_as_far_as_it_is_trusted():
    """still_moving's trusted part of the Gauss-Newton step (fitstate._trusted_length), against the hand-worked
    trust-region shortening: from x = 0.5 the whole step 10.5 raises the cost from 31.0 to 8.8e5, the quarter step
    (x = 3.125) to 253; at 1/16 (x = 1.156) the cost falls by 10.2 where the linearisation predicts 3.75: trusted."""
    from flowchart2sdnn.diagnose.fitstate import _trusted_length

    x = np.array([0.5])
    e = 8.0 - 0.125
    step = np.array([e / 0.75])
    cost, predicted = 0.5 * e * e, 0.5 * e * e
    t = _trusted_length(_Cubic(), x, step, cost, predicted, unit=1e-3)
    assert t == 1 / 16
    for longer in (1.0, 0.25):
        fall = cost - 0.5 * (8.0 - (0.5 + longer * step[0]) ** 3) ** 2
        assert fall < 0.25 * (2 * longer - longer ** 2) * predicted
    # nothing worth moving: the part still trusted-or-not would gain less than one unit before it is trusted
    assert _trusted_length(_Cubic(), x, step, cost, predicted, unit=10.0) == 0.0

"""diagnose's defences against false alarms (issue 16): a candidate's validation gain must exceed floor² plus
spread_z standard errors of the gain (the standard error read off the gain's spread over the parts of the
validation records), and must beat the current chart refitted as briefly without any effect (the control).

Oracles: the parts' residuals are made by hand and the standard error computed here with numpy from the
definition (paired differences of the parts' mean squares, sd / sqrt(parts)); `metrics`' parts against the
squared error summed by hand; the control on a continuous plant the chart describes exactly (nothing to find)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flowchart2sdnn.diagnose.fitting import DiagnoseSettings, Fitted, gain_spread
from flowchart2sdnn.diagnose.loop import refusal


def _fitted(parts_sse: list[float], rows: int = 100, n_out: int = 2, cost: float = 1.0, floor=None) -> Fitted:
    """A Fitted with one validation record cut into parts of `rows` rows and the given squared errors."""
    sse = float(sum(parts_sse))
    record = {"rows": rows * len(parts_sse), "rms": {f"y{i}": 0.0 for i in range(n_out)},
              "segments": [[rows, s] for s in parts_sse]}
    validation = {"rms_all": math.sqrt(sse / (rows * len(parts_sse) * n_out)), "records": [record],
                  "rms_records": [math.sqrt(sse / (rows * len(parts_sse) * n_out))]}
    return Fitted(None, cost, 10_000, 5, validation, validation_floor=floor)


def test_gain_spread_is_the_standard_error_of_the_paired_fall():
    before = [4.0, 5.0, 6.0, 5.0, 4.0, 6.0, 5.0, 5.0, 4.0, 6.0]
    after = [3.0, 4.5, 4.0, 4.8, 3.9, 5.0, 4.0, 4.9, 3.0, 5.5]
    fall = (np.array(before) - np.array(after)) / (100 * 2)
    expected = np.std(fall, ddof=1) / np.sqrt(len(fall))
    assert gain_spread(_fitted(after), _fitted(before)) == pytest.approx(expected, rel=1e-12)


def test_a_gain_spread_evenly_passes_and_the_same_gain_in_one_part_is_refused():
    settings = DiagnoseSettings()
    before = _fitted([10.0] * 10, cost=1.0)
    # 10 % off every part's squared error: the pooled RMS falls 5 %, the same in every part
    even = _fitted([9.0] * 10, cost=0.9)
    assert refusal(even, before, settings) is None
    # the same total fall, all of it in one part: as likely a lucky stretch as an effect
    lumped = _fitted([10.0] * 9 + [0.0], cost=0.9)
    assert lumped.validation_rms == pytest.approx(even.validation_rms)
    why = refusal(lumped, before, settings)
    assert why is not None and "spread" in why
    # without the spread test (spread_z = 0) the lumped gain is accepted: the rule is what refused it
    assert refusal(lumped, before, DiagnoseSettings(spread_z=0)) is None


def test_the_floor_and_the_spread_add():
    """A gain just above spread_z standard errors but not above floor² plus them is refused."""
    settings = DiagnoseSettings()
    rng = np.random.default_rng(3)
    b = 10.0 + rng.normal(0, 0.3, 10)
    a = b - 3.0 + rng.normal(0, 0.3, 10)
    before, after = _fitted(list(b), cost=1.0), _fitted(list(a), cost=0.9)
    gain = before.validation_rms**2 - after.validation_rms**2
    se = gain_spread(after, before)
    assert gain > 2 * se
    assert refusal(after, before, settings) is None
    floor = math.sqrt(gain - 2 * se) * 1.01
    before_with_floor = _fitted(list(b), cost=1.0, floor=floor)
    assert refusal(after, before_with_floor, settings) is not None


def test_metrics_parts_sum_the_squared_error():
    """`metrics(segments=k)`: k consecutive parts of the scored rows, each with its rows and its squared error
    summed over every output, against the free run's error summed here by hand."""
    import sys
    from pathlib import Path

    from flowchart2sdnn.compiler import compile_diagram
    from flowchart2sdnn.diagram.validate import load_diagram
    from flowchart2sdnn.identify.offline.problem import metrics
    from flowchart2sdnn.network.alignment import run_aligned
    from flowchart2sdnn.network.runtime import CompiledNetwork
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from diagnose_bench import record

    diagrams = Path(__file__).resolve().parents[1] / "diagrams"
    ds = record(load_diagram(diagrams / "two_mass_plant.yaml"), 0.5, 4, 0.01)
    compiled = CompiledNetwork(compile_diagram(load_diagram(diagrams / "two_mass_learned.yaml"), substeps=1).network)
    x = compiled.theta0()
    m = metrics(compiled, x, ds, "zoh", score_from=100, segments=4)
    y = np.column_stack([ds.columns[n] for n in compiled.output_names])
    yhat = run_aligned(compiled, x, np.asarray(ds.columns["M1"], dtype=float)[:, None], "zoh")
    e = (y - yhat)[100:]
    rows = [r for r, _ in m["segments"]]
    assert rows == [100, 100, 100, 100] and sum(rows) == m["rows"] == 400
    for k, (_, sse) in enumerate(m["segments"]):
        assert sse == pytest.approx(float(np.sum(e[100 * k:100 * (k + 1)] ** 2)), rel=1e-12)
    assert "segments" not in metrics(compiled, x, ds, "zoh")


def test_spread_z_is_checked():
    with pytest.raises(ValueError, match="spread_z"):
        DiagnoseSettings(spread_z=-1)


def test_an_unfinished_first_fit_gives_no_effect_the_credit():
    """The one-mass chart is complete for its plant (mass + viscous friction). Traced from the chart as given, not
    fitted at all (max_iter 0, --allow-unconverged), any effect's 40-iteration refit finishes the descent and
    "explains" the residual: without the control a term is accepted (damping at v, validation RMS 0.076 -> 0.020, the noise); with
    it nothing is, and the round says why."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from diagnose_bench import chart, record

    from flowchart2sdnn.diagnose import diagnose
    from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS

    plant = chart("one_mass_plant")
    excitation = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
    train, val = record(plant, 4.0, 3, 0.02, **excitation), record(plant, 2.0, 101, 0.02, **excitation)
    effects = [BUILTIN_EFFECTS[n] for n in ("friction", "damping")]
    base = DiagnoseSettings(max_iter=0, rounds=1, require_converged=False)
    without = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(**{**base.__dict__, "control_refit": False}),
                       effects).report
    assert without["accepted"], "the control test needs a case that fools the loop without it"
    report = diagnose(chart("one_mass"), train, [val], base, effects).report
    assert report["accepted"] == []
    (entry,) = report["rounds"]
    assert entry["control"]["used_as_baseline"] is True
    assert "without any effect" in entry["reason"]
    # the final chart is the same chart at the control's better point, not the unfinished first fit
    assert entry["control"]["final"] is True
    assert report["after"]["validation_rms"] == pytest.approx(entry["control"]["validation_rms"], rel=1e-9)
    assert report["after"]["validation_rms"] < 0.5 * report["before"]["validation_rms"]


def test_the_control_gets_the_growing_horizon_when_a_candidate_did(monkeypatch):
    """A converged first fit in a local minimum (false-alarm bench, physical two-mass chart, noise 0.003, seed 2:
    train RMS 0.52) was left by the growing-horizon refit of a scanned overflow limit; the control refitted only
    on whole records stayed there, and the overflow took the credit. The control must get every start a candidate
    got: with a candidate refitted on a growing horizon, the control's refit from the chart as given is also grown,
    and it wins when it reaches the lower cost. The fits are stand-ins: their costs are the oracle."""
    from types import SimpleNamespace

    from flowchart2sdnn.diagnose import refits

    grown_calls = []
    ident = SimpleNamespace(status="converged")

    def fake_fit_chart(diagram, train, records, settings, max_iter, dof, start, progress=None, accepted=(), target=float("inf")):
        return Fitted(ident, 1.0, 100, 5, {}, start)

    def fake_fit_growing(diagram, train, records, settings, max_iter, dof, start, accepted=(), target=float("inf")):
        grown_calls.append((diagram, start))
        return Fitted(ident, 0.5, 100, 5, {}, start)

    monkeypatch.setattr(refits, "fit_chart", fake_fit_chart)
    monkeypatch.setattr(refits, "fit_growing", fake_fit_growing)
    current = Fitted(SimpleNamespace(status="converged", diagram="current chart"), 2.0, 100, 5, {})
    settings = DiagnoseSettings()
    plain = refits.control_fit(current, "chart as given", [], [], settings, 0, [], None)
    assert grown_calls == [] and plain.cost == 1.0
    grown = refits.control_fit(current, "chart as given", [], [], settings, 0, [], None, horizon=True)
    assert grown_calls == [("chart as given", "control_horizon")]
    assert grown.cost == 0.5 and grown.start == "control_horizon"
    # horizon 0 (off) keeps it off for the control as for the candidates
    grown_calls.clear()
    refits.control_fit(current, "chart as given", [], [], DiagnoseSettings(horizon=0), 0, [], None, horizon=True)
    assert grown_calls == []
    # without such a candidate the control's refit from the chart as given grows under the neutral candidates'
    # rule: when it is unpredictable (fitting.unpredictable), and only from the chart as given
    monkeypatch.setattr(refits, "unpredictable", lambda fitted, train, settings: True)
    chaotic = refits.control_fit(current, "chart as given", [], [], settings, 0, [], None)
    assert grown_calls == [("chart as given", "control_horizon")] and chaotic.start == "control_horizon"

"""The discretization's bias on each parameter (identify.assess.floorbias) and the intervals widened by it.

Oracle: on noise-free data from the continuous plant the parameters that explain the data are the plant's own
(the truth); a fit's error there is the discretization's bias alone. The corrected estimate (identified - beta)
must be far nearer the truth than the identified one. A network at N = 64 on the same data is the cross-check
that the error is the discretization's: it falls towards the truth as the step shrinks.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.assess.floorbias import BIAS_WARN
from flowchart2sdnn.identify.document import from_document
from flowchart2sdnn.identify.offline.run import with_floor_bias
from flowchart2sdnn.report.identify_text import format_result
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
PLANT = load_diagram(DIAGRAMS / "two_mass_coulomb_plant.yaml")  # its parameters free, init at the truth


def _record(noise: float):
    data = excite(PLANT, ExcitationSettings(seconds=3, seed=2, noise_std=noise))
    return sd.dataset_from_frame(pd.DataFrame(data), time="time", inputs=["M1"], outputs=["w1", "w2"])


@pytest.fixture(scope="module")
def clean():
    return _record(0.0)


@pytest.fixture(scope="module")
def noisy():
    return _record(0.01)


# measured (3 s, seed 2, noise-free; |identified - truth| / |corrected - truth|, smallest over the 8 parameters):
# auto (N = 7) 34 (J1; c 1737, b1 184), N = 1 with `delays: torques` 11.8 (d; c 728, b1 23)
@pytest.mark.parametrize(("substeps", "factor"), [("auto", 10.0), (1, 4.0)])
def test_the_corrected_estimate_is_nearer_the_truth(clean, substeps, factor):
    truth = PLANT.parameter_values()
    fit = sd.identify(dataclasses.replace(PLANT, substeps=substeps, delays="torques"), clean, max_iter=50)
    bias = fit.extra["discretization"]["bias"]
    assert bias["refit"]["status"] != "max_iter"
    fine = sd.identify(dataclasses.replace(PLANT, substeps=64, delays="torques"), clean, max_iter=50,
                       floor_bias=False)
    for name, est in fit.parameters.items():
        raw = abs(est.value - truth[name])
        corrected = abs(bias["corrected"][name]["value"] - truth[name])
        assert raw > 0 and corrected * factor < raw, (name, raw, corrected)
        # the cross-check: at N = 64 the fit itself is nearer the truth (the error is the step's)
        assert abs(fine.parameters[name].value - truth[name]) < raw, name


def test_bias_widens_the_interval_and_is_reported(noisy):
    """N = 1: beta is several standard errors; the interval grows by |beta|, the file and the summary say so."""
    fit = sd.identify(dataclasses.replace(PLANT, substeps=1, delays="torques"), noisy, max_iter=50)
    doc = json.loads(fit.to_json())
    bias = doc["discretization"]["bias"]
    assert set(bias["beta"]) == set(PLANT.parameter_values())
    for name, p in doc["parameters"].items():
        b, (lo, hi), (nlo, nhi) = bias["beta"][name], p["ci95"], p["ci95_noise"]
        assert lo == pytest.approx(nlo - abs(b)) and hi == pytest.approx(nhi + abs(b))
        assert bias["corrected"][name]["value"] == pytest.approx(p["value"] - b)
        assert bias["ratio"][name] == pytest.approx(abs(b) / p["stderr"])
    (warning,) = [n for n in fit.notices if n.code == "FLOOR004"]
    assert "c by" in warning.message
    # it names exactly the parameters RESULT.json's bias puts past half a standard error, with their numbers
    over = {n for n, r in bias["ratio"].items() if r is not None and r > BIAS_WARN}
    assert set(warning.numbers["shifted"]) == over and "c" in over
    for name in over:
        assert warning.numbers["shifted"][name]["beta"] == pytest.approx(bias["beta"][name])
        assert warning.numbers["shifted"][name]["standard_errors"] == pytest.approx(bias["ratio"][name])
    assert from_document(doc).to_document()["parameters"] == doc["parameters"]  # read back unchanged
    text = format_result(fit)
    assert "discretization bias" in text and "corrected 95 % interval" in text


def test_without_floor_bias_the_interval_is_the_noise_alone(noisy):
    fit = sd.identify(PLANT, noisy, max_iter=50, floor_bias=False)
    assert "bias" not in fit.extra["discretization"]
    assert all(e.ci95 == e.ci95_noise for e in fit.parameters.values())
    assert "discretization bias" not in format_result(fit)


def test_the_analysis_added_afterwards_is_identifys_own_at_the_same_point(noisy):
    """with_floor_bias (diagnose's final fit, made with floor_bias off): the point stays, the bias, the widened
    intervals and the warning are what identify's default run reports (N = 1: beta several standard errors)."""
    chart = dataclasses.replace(PLANT, substeps=1, delays="torques")
    plain = sd.identify(chart, noisy, max_iter=50, floor_bias=False)
    added = with_floor_bias(plain, [noisy])
    default = sd.identify(chart, noisy, max_iter=50)
    assert added.values == plain.values == default.values
    beta = added.extra["discretization"]["bias"]["beta"]
    assert beta == pytest.approx(default.extra["discretization"]["bias"]["beta"], rel=1e-9)
    for name, est in added.parameters.items():
        assert est.ci95_noise == plain.parameters[name].ci95
        assert est.ci95 == pytest.approx(default.parameters[name].ci95, rel=1e-9)
        assert est.ci95[1] - est.ci95[0] == pytest.approx(est.ci95_noise[1] - est.ci95_noise[0] + 2 * abs(beta[name]))
    assert [n for n in added.notices if n.code == "FLOOR004"]
    assert added.settings.floor_bias and with_floor_bias(added, [noisy]) is added  # done once


def test_bias_skips_cleanly_where_the_oracle_cannot_run(noisy, monkeypatch):
    def refuse(*args, **kwargs):
        raise ValueError("algebraic loop (no integrator or delay on it): a -> b -> a")

    monkeypatch.setattr("flowchart2sdnn.simulate.continuous.simulate_continuous", refuse)
    fit = sd.identify(PLANT, noisy, max_iter=50)
    bias = fit.extra["discretization"]["bias"]
    assert bias["beta"] is None and "cannot run this chart" in bias["skipped"]
    assert all(e.ci95 == e.ci95_noise for e in fit.parameters.values())
    assert "discretization bias: not estimated" in format_result(fit)


def test_cli_switches_it_off(tmp_path, noisy):
    csv = tmp_path / "d.csv"
    pd.DataFrame({"time": noisy.time, **{k: v for k, v in noisy.columns.items()}}).to_csv(csv, index=False)
    out = tmp_path / "r.json"
    res = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(DIAGRAMS / "two_mass_coulomb_plant.yaml"),
                                    "--max-iter", "20", "--quiet", "--no-floor-bias", "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert "bias" not in doc["discretization"] and doc["settings"]["floor_bias"] is False


def test_per_record_parameters_skip_the_bias(tmp_path):
    """The identified chart holds a per-record parameter's mean: an oracle run of every record at it is no plant."""
    from test_per_record import OFFSETS, _chart, _record

    chart = _chart(tmp_path)
    fit = sd.identify(chart, [_record(chart, k, off, noise=0.001) for k, off in enumerate(OFFSETS)], max_iter=30)
    bias = fit.extra["discretization"]["bias"]
    assert bias["beta"] is None and "per-record parameters (off)" in bias["skipped"]
    assert all(e.ci95 == e.ci95_noise for e in fit.parameters.values())


def test_an_unconverged_refit_continues_and_warns_only_while_beta_moves(clean, monkeypatch):
    """With 1 iteration the N = 1 refit (4 to converge with the default bounds in the box, 8 with the transform)
    stops unconverged: it runs 1 more, reports how far beta moved, and warns since it moved more than
    BETA_SETTLED; the default refit converges and does not warn."""
    from flowchart2sdnn.identify.assess import floorbias

    chart = dataclasses.replace(PLANT, substeps=1, delays="torques")
    settled = sd.identify(chart, clean, max_iter=50)
    assert settled.extra["discretization"]["bias"]["refit"]["beta_change"] is None
    assert not any(n.code == "FLOOR003" for n in settled.notices)
    monkeypatch.setattr(floorbias, "BIAS_ITER", 1)
    fit = sd.identify(chart, clean, max_iter=50)
    refit = fit.extra["discretization"]["bias"]["refit"]
    assert refit["status"] == "max_iter" and refit["iterations"] == 2
    assert refit["beta_change"] > floorbias.BETA_SETTLED
    (warning,) = [n for n in fit.notices if n.code == "FLOOR003"]
    assert warning.numbers == {"iterations": 2, "beta_change": refit["beta_change"]}
    assert "did not converge in 2 iterations" in warning.message

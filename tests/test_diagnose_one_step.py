"""Near the noise a significant candidate is refitted only when its one Gauss-Newton step, simulated on the
validation records, lowers the validation RMS by min_gain (diagnose.choice.one_step_relevant).

Oracle: the same run without that gate (``one_step=False``), whose brief refits of the candidates the gate
dropped must each fail the acceptance's first test (passes_gain) - the gate may only spare refits that could not
have been accepted - and a step its linearisation mispredicts (a learned curve's steep basis) must be shortened
before it is trusted. Data: a continuous simulation of the one-mass plant with a weak Coulomb and Stribeck friction (a tenth of
the bench's) that the chart lacks, 0.02 m/s noise: the fit ends near the noise, the friction is significant and
worth accepting, an input offset is significant and is not.
"""

from __future__ import annotations

from dataclasses import replace

from diagnose_bench import chart, record

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose

EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
EFFECTS = [BUILTIN_EFFECTS[n] for n in ("friction", "damping", "input_offset")]


def _weak_friction_plant():
    plant = chart("one_mass_friction_plant")
    return replace(plant, parameters=tuple(replace(p, init=0.1 * p.init) if p.name in ("Fc", "Fs") else p
                                           for p in plant.parameters))


def _title(c: dict) -> str:
    return f"{c['effect']} at {c['at']}" + (f" ({c['label']})" if c["label"] else "")


def test_one_step_spares_only_refits_that_could_not_be_accepted():
    plant = _weak_friction_plant()
    train, val = record(plant, 4.0, 3, 0.02, **EXCITATION), record(plant, 2.0, 101, 0.02, **EXCITATION)
    settings = DiagnoseSettings(rounds=1)
    gated_run = diagnose(chart("one_mass"), train, [val], settings, EFFECTS).report
    plain_run = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(**{**settings.__dict__, "one_step": False}),
                         EFFECTS).report
    (entry,) = gated_run["rounds"]
    rows = {row["candidate"]: row for row in entry["one_step"]}
    dropped = {title for title, row in rows.items() if not row["refitted"]}
    assert dropped == {"input_offset at F"}
    assert not any(c.get("refitted") for c in gated_run["candidates"] if _title(c) in dropped)
    # the learned curve's whole step lands far off: shortened until trusted, where it lowers the validation RMS a
    # little - refitted, and it is what the refits find best
    assert rows["friction at v"]["step"] < 1 and rows["friction at v"]["rho"] >= 0.25
    assert rows["friction at v"]["refitted"]
    refitted = {_title(c): c for c in plain_run["candidates"] if c.get("refitted")}
    assert dropped <= set(refitted)
    before = plain_run["before"]["validation_rms"]
    for title in dropped:
        assert not refitted[title]["validation_rms_after"] < before * (1 - settings.min_gain), title
    assert gated_run["accepted"] == plain_run["accepted"] and gated_run["accepted"][0]["effect"] == "friction"

"""HSM150 servo motor (real measurements, ../shared/data/real/hsm150_motor_steps): a torque offset per record.

Fitted on pos 0.06 and neg 0.04, validated on neg 0.045 with its offset fitted on its first second. Oracles: the
records' own steady speeds (SOURCE.md's table, recomputed here from the data), the physics of the offset's sign
(Coulomb friction opposes the motion of each record), and the same chart with one shared offset. Skipped when
the data are absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from realdata import real_dataset

import flowchart2sdnn as sd

ROOT = Path(__file__).resolve().parents[1]
DATA, pytestmark = real_dataset("hsm150_motor_steps", "idf_pos_0p06_1.csv", "HSM150 data not present")
MAP = {"M": "torque_cmd_Nm", "w": "speed_rad_s"}



def _read(name):
    return sd.read_csv(DATA / f"idf_{name}_1.csv", map=MAP)


def test_per_record_offsets_explain_the_steady_speeds_and_beat_a_shared_offset():
    train = [_read("pos_0p06"), _read("neg_0p04")]
    val = _read("neg_0p045")
    per = sd.identify(sd.load_chart(ROOT / "diagrams" / "real" / "hsm150.yaml"), train, val, init_window=1000)
    shared = sd.identify(sd.load_chart(ROOT / "diagrams" / "real" / "hsm150_shared_offset.yaml"), train, val,
                         init_window=1000)
    offsets = [r["value"] for r in per.extra["parameters_per_record"]["off"]]
    assert offsets[0] < 0 < offsets[1]  # friction against +w on the pos record, against -w on the neg one
    B = per.parameters["B"].value
    for ds, off in zip(train, offsets, strict=True):
        w = np.asarray(ds.columns["w"])
        M = np.asarray(ds.columns["M"])
        for rows in (slice(8000, 10000), slice(18000, 20000)):  # steady before and after the step
            assert (M[rows].mean() + off) / B == pytest.approx(w[rows].mean(), rel=0.1)
    assert per.fit.validation.fit_percent["w"] > shared.fit.validation.fit_percent["w"] + 20

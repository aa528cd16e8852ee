"""A fit whose residual is far above the records' noise says so (identify.offline.run._far_above_noise).

Oracle: the record's own, known content. The continuous plant's record at 0.01 rad/s noise is fitted by its own
chart (the residual at the noise: no warning); the same record with a slow 0.2 rad/s sine added to w2, which no
chart parameter can produce and which leaves the second differences (the noise estimate) as they were, gives a
residual of about sqrt(0.01² + 0.2²/4) / 0.01 ≈ 10x the noise on the two outputs together: warned."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.api import dataset_from_frame
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.run import identify
from flowchart2sdnn.identify.settings import IdentifySettings
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parent.parent
WORDS = "the training residual RMS is "


@pytest.fixture(scope="module")
def record():
    plant = load_diagram(ROOT / "diagrams" / "two_mass_coulomb_plant.yaml")
    frame = excite(plant, ExcitationSettings(seconds=5.0, seed=3, noise_std=0.01))
    return plant, frame


def _fit(plant, frame):
    chart = load_diagram(ROOT / "diagrams" / "two_mass_coulomb.yaml")
    data = dataset_from_frame(frame, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names))
    return identify(chart, data, settings=IdentifySettings(seed=1, floor_bias=False))


def test_a_fit_at_the_noise_is_not_warned(record):
    r = _fit(*record)
    assert r.converged
    assert not [n for n in r.notices if n.code == "NOISE001"]


def test_a_record_the_chart_cannot_follow_is_warned(record):
    plant, frame = record
    t = np.asarray(frame["time"], dtype=float)
    moved = dict(frame, w2=np.asarray(frame["w2"], dtype=float) + 0.2 * np.sin(2 * np.pi * 0.5 * t))
    r = _fit(plant, moved)
    said = [n for n in r.notices if n.code == "NOISE001"]
    assert len(said) == 1 and "sdnn diagnose" in said[0].message and "--starts" in said[0].message
    ratio = said[0].numbers["ratio"]
    assert said[0].message.startswith(f"{WORDS}{ratio:.3g}x")
    assert 5 < ratio < 15  # about 10x: the sine's RMS over the two outputs against the noise

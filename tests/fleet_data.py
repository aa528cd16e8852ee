"""A small fleet for the scale-out tests: a one-mass drive with Coulomb and viscous friction, logged by `excite`."""

from __future__ import annotations

from pathlib import Path

DRIVE_CHART = """\
sdnn: 1
name: drive
description: one-mass drive with Coulomb and viscous friction (fleet tests)
sample_time: 0.001
substeps: 1        # the subject is the fleet, not the discretization (auto would take 29 steps a sample)
delays: search
inputs:
  M1: {unit: N*m}
outputs:
  w1: {unit: rad/s}
parameters:
  J1: {init: 0.2, unit: kg*m^2, min: 0}
  Fc: {init: 0.5, unit: N*m, min: 0}
  b:  {init: 0.05, unit: N*m*s/rad, min: 0}
blocks:
  MB:  {type: sum, in: [M1, -MF, -MV], unit: N*m}
  acc: {type: gain, in: MB, k: 1/J1}
  w1:  {type: integrator, in: acc, unit: rad/s}
  sg:  {type: function, f: sign_smooth, in: w1, eps: 0.01}
  MF:  {type: gain, in: sg, k: Fc, unit: N*m}
  MV:  {type: gain, in: w1, k: b, unit: N*m}
"""

TRUTH = {"J1": 0.25, "Fc": 0.6, "b": 0.04}


def write_chart(directory: Path) -> Path:
    path = directory / "drive.yaml"
    path.write_text(DRIVE_CHART)
    return path


def write_log(path: Path, seed: int, seconds: float = 1.0, noise: float = 0.01, **params: float) -> Path:
    """Excite the drive with the given parameters (default TRUTH) and write its log as CSV."""
    from flowchart2sdnn.data.csvdata import write_csv
    from flowchart2sdnn.diagram.validate import diagram_from_text
    from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

    diagram = diagram_from_text(DRIVE_CHART, "drive.yaml")
    values = {**TRUTH, **params}
    columns = excite(diagram, ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise), parameters=values)
    write_csv(path, columns, float_format="%.17g")
    return path


def sleep_then(x: int) -> int:
    """Return x after a pause that makes the first item finish last (executor ordering tests)."""
    import time

    time.sleep(0.05 * (3 - x))
    return x

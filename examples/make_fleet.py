"""Make a small fleet of drive logs for the README tour's step 8 (`sdnn batch` and `sdnn report`).

Every log is a virtual test-bench record of ``diagrams/two_mass_plant.yaml`` (the paper's two-mass drive with
exact Coulomb, Stribeck and viscous friction on both machines), excited as ``sdnn excite`` does (APRBS ±7 N·m
plus relay, 0.01 rad/s noise), written as ``DIR/driveNN_dayDDD.csv``. Each drive has its own parameters (a
seeded 3 % spread around the plant chart's), and some wear, so that the drift report has something to find:

* drive 01 stays as it was;
* drive 02's shaft loses stiffness: ``c`` falls by 4 % of its first value a day;
* drive 03's load grows (material builds up on a roll): ``J2`` grows by 5 % a day.

Run from the repository root::

    python examples/make_fleet.py logs                      # 3 drives x 5 days of 5 s (a few seconds)
    python examples/make_fleet.py logs --drives 2 --days 3 --seconds 2

The same arguments and seed give the same files, byte for byte; existing files are replaced.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

PLANT = Path(__file__).resolve().parents[1] / "diagrams" / "two_mass_plant.yaml"
#: drive -> (parameters, relative change per day); drives not listed stay as they were
WEAR = {2: (("c",), -0.04), 3: (("J2",), 0.05)}
SPREAD = ("J2", "c", "d", "Fc2", "Fs2", "b2")  # the motor (J1, its friction) is the one stage 1 identified


def plant_values(nominal: dict[str, float], drive: int, day: int, seed: int) -> dict[str, float]:
    """The true parameters of `drive` on `day` (days count from 1)."""
    rng = np.random.default_rng([seed, drive])
    values = dict(nominal)
    for name in SPREAD:
        values[name] *= 1 + 0.03 * rng.standard_normal()
    names, per_day = WEAR.get(drive, ((), 0.0))
    for name in names:
        values[name] *= 1 + per_day * (day - 1)
    values["Fs2"] = max(values["Fs2"], values["Fc2"])  # static friction is never below Coulomb friction
    return values


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("directory", type=Path, help="where the logs go (created if needed)")
    ap.add_argument("--drives", type=int, default=3)
    ap.add_argument("--days", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=5.0, help="length of each log (1 kHz)")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    if args.drives < 1 or args.days < 1 or not args.seconds > 0:
        ap.error("--drives and --days must be at least 1 and --seconds positive")
    plant = load_diagram(PLANT)
    nominal = plant.parameter_values()
    args.directory.mkdir(parents=True, exist_ok=True)
    for drive in range(1, args.drives + 1):
        for day in range(1, args.days + 1):
            values = plant_values(nominal, drive, day, args.seed)
            settings = ExcitationSettings(seconds=args.seconds, seed=1000 * args.seed + 100 * drive + day,
                                          noise_std=0.01)
            path = args.directory / f"drive{drive:02d}_day{day:03d}.csv"
            write_csv(path, excite(plant, settings, parameters=values))
    print(f"wrote {args.drives * args.days} logs of {args.seconds:g} s to {args.directory}/", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

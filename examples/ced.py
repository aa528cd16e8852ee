"""Coupled Electric Drives benchmark: the grey-box chart z = |G(s) u| (diagrams/real/ced.yaml) identified and
scored by the official protocol (nonlinear_benchmarks.CED, ../shared/data/real/BENCHMARKS.md section 2):
train on samples 0..399 of each DATAUNIF record, test on samples 400..499 of each, the test part's initial
state fitted on its first 4 samples (parameters fixed), simulation RMSE from sample 4, in z's units.

By default both training parts are fitted together (one parameter set, as the protocol allows); `--separate`
fits each record on its own training part and tests it on its own test part.
The data are read in place from ../shared/data/real/ced (never copied into the repository).
Run: PYTHONPATH=. python examples/ced.py [--starts N] [--separate]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import flowchart2sdnn as sd

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "ced"
CHART = ROOT / "diagrams" / "real" / "ced.yaml"
RECORDS = {"low amplitude (unif_1)": "unif_1.csv", "high amplitude (unif_2)": "unif_2.csv"}
SPLIT = 400  # train rows 0..399, test rows 400..499 (official)
WINDOW = 4  # the official initial-state window, also the first scored test sample
OUTPUT = "z_pulley_speed_abs_raw"
# CT-SUBNET (Beintema et al., ICLR 2023), median test RMS over restarts, on a different split (300 / 200)
PUBLISHED = {"low amplitude (unif_1)": 0.143, "high amplitude (unif_2)": 0.0997}


def records() -> dict[str, object]:
    return {label: sd.read_csv(DATA / name) for label, name in RECORDS.items()}


def test_rmse(chart, train: list, test, starts: int = 1, seed: int = 0):
    """(identification, test RMSE): `chart` fitted on `train`, then `test` run from the initial state fitted on
    its first WINDOW samples and scored from sample WINDOW (identify's init_window)."""
    result = sd.identify(chart, train, validation=test, init_window=WINDOW, starts=starts, seed=seed)
    return result, float(result.fit.validation.rms[OUTPUT])


def protocol(separate: bool = False, starts: int = 4, seed: int = 0, chart_path: Path = CHART) -> dict:
    """{record label: (test RMSE, identification that produced it)} by the official protocol."""
    chart = sd.load_chart(chart_path)
    data = records()
    trains = {label: d.slice(0, SPLIT) for label, d in data.items()}
    out = {}
    fitted = None
    for label, d in data.items():
        test = d.slice(SPLIT, None)
        if separate:
            out[label] = test_rmse(chart, [trains[label]], test, starts, seed)[::-1]
        elif fitted is None:
            fitted = sd.identify(chart, list(trains.values()), validation=test, init_window=WINDOW,
                                 starts=starts, seed=seed)
            out[label] = (float(fitted.fit.validation.rms[OUTPUT]), fitted)
        else:
            # the same parameters on the other test part: the identified chart, not refitted (max_iter=0 only
            # evaluates it, including the test part's initial-state window)
            again = sd.identify(fitted.chart, list(trains.values()), validation=test, init_window=WINDOW,
                                max_iter=0)
            out[label] = (float(again.fit.validation.rms[OUTPUT]), fitted)
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--starts", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--separate", action="store_true", help="fit each record on its own training part")
    args = parser.parse_args()
    table = protocol(args.separate, args.starts, args.seed)
    data = records()
    print(f"CED, official split: train 0..{SPLIT - 1}, test {SPLIT}..499, initial window {WINDOW}, "
          f"{'each record fitted separately' if args.separate else 'both training parts fitted together'}")
    print(f"{'test record':26s} {'RMSE':>8s} {'train mean':>11s} {'CT-SUBNET*':>11s}")
    for label, (rmse, _) in table.items():
        z = data[label].columns[OUTPUT]
        # the trivial baseline: the training part's mean, scored on the same test rows
        baseline = float(np.sqrt(np.mean((z[SPLIT + WINDOW:] - z[:SPLIT].mean()) ** 2)))
        print(f"{label:26s} {rmse:8.4f} {baseline:11.4f} {PUBLISHED[label]:11.4f}")
    print("* median over restarts, split 300 train / 200 test (not the official one)")
    seen = set()
    for _, result in table.values():
        if id(result) in seen:
            continue
        seen.add(id(result))
        values = ", ".join(f"{n} = {e.value:.4g} [{e.ci95[0]:.3g}, {e.ci95[1]:.3g}]"
                           for n, e in result.parameters.items())
        print(f"fit ({result.status}, train RMS {result.fit.train.rms[OUTPUT]:.4f}): {values}")
        for w in result.warnings:
            print("  warning:", w)


if __name__ == "__main__":
    main()

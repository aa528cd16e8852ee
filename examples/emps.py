"""EMPS benchmark (Electro-Mechanical Positioning System): the physical chart M q'' = F - Fv q' - Fc sign(q') -
offset (diagrams/real/emps.yaml) identified on train.csv and scored by the official protocol
(nonlinear_benchmarks.EMPS, ../shared/data/real/BENCHMARKS.md section 1): the test record's initial state fitted
on its first 20 samples with the identified parameters fixed (identify's init_window), then a free-run
simulation from the force alone, RMSE of the position from sample 20, in mm.

Rows printed, each by that same protocol:
- the published IDIM-LS parameters (Janot, Gautier, Brunot 2019) put into the same charts, not fitted: how far
  the physical model that the benchmark's authors identified gets when it is simulated open loop;
- the chart with viscous friction only (Fc and offset fixed at 0), the chart identified on train.csv (the
  result), and the chart with asymmetric viscous friction
  (diagrams/real/emps_asymmetric.yaml: Fv+ for v > 0, Fv- for v < 0, the effect issue 16 names);
- with --diagnose: one round of `sdnn diagnose` from the viscous-only chart on train.csv alone (its validation
  the last 30 % of train), the augmented chart refitted on all of train.csv; and `sdnn diagnose train.csv
  --validate test.csv --init-window 20` from the symmetric chart (issue 16's protocol, as for Cascaded Tanks):
  before/after on test by the same window and scoring, with effects chosen on the test record, so its "after"
  is not a clean test score;
- an oracle that is not a result: the chart fitted on test.csv itself, to show what the structure can reach on
  that record.
The record is position-controlled in closed loop, while the protocol simulates the plant open loop from the
force: nothing pulls the simulated position back, so a small force error grows into a position error along the
record; the per-5 s RMS printed shows it.
The data are read in place from ../shared/data/real/emps (never copied into the repository).
Run: PYTHONPATH=. python examples/emps.py [--starts N] [--diagnose]   (about 10 s; --diagnose about 5 min)
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import flowchart2sdnn as sd

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "emps"
CHART = ROOT / "diagrams" / "real" / "emps.yaml"
ASYMMETRIC = ROOT / "diagrams" / "real" / "emps_asymmetric.yaml"
WINDOW = 20  # the official initial-state window, also the first scored test sample
OUTPUT = "q_meas_m"
# test RMSE in mm (BENCHMARKS.md section 1): dynoNet (Forgione & Piga 2021, possibly on the training record),
# CT-SUBNET (Beintema et al. 2023, on deepSI's split)
PUBLISHED_MM = {"dynoNet": 2.64, "CT-SUBNET": 4.61}
# IDIM-LS (EMPS_Description.pdf): symmetric, and asymmetric (Fc+ 20.144, Fc- 20.628 written as their mean and
# an offset of (Fc+ - Fc-)/2, which is the same force for every v != 0)
IDIM_LS = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
IDIM_LS_ASYMMETRIC = {"M": 95.1540, "Fvp": 166.7061, "Fvm": 240.4236, "Fc": (20.1440 + 20.6277) / 2,
                      "offset": (20.1440 - 20.6277) / 2}


def records() -> tuple[object, object]:
    """(train, test) as read by the library."""
    return sd.read_csv(DATA / "train.csv"), sd.read_csv(DATA / "test.csv")


def with_values(chart, values: dict):
    """The chart with these parameters' values as init."""
    return replace(chart, parameters=tuple(replace(p, init=values[p.name]) if p.name in values else p
                                           for p in chart.parameters))


def viscous_only(chart):
    """The symmetric chart without Coulomb friction and offset (both fixed at 0): the chart issue 14 starts from."""
    return replace(chart, parameters=tuple(replace(p, init=0.0, fixed=True) if p.name in ("Fc", "offset") else p
                                           for p in chart.parameters))


def protocol(chart, train, test, starts: int = 1, seed: int = 0, fit: bool = True):
    """(test RMSE in mm, identification): `chart` fitted on `train` (or only evaluated, `fit=False`), `test`
    run from the state fitted on its first WINDOW samples, scored from sample WINDOW."""
    result = sd.identify(chart, train, validation=test, init_window=WINDOW, starts=starts, seed=seed,
                         max_iter=1000 if fit else 0)
    return 1000.0 * float(result.fit.validation.rms[OUTPUT]), result


def error_by_stretch(result, test, seconds: float = 5.0) -> list[float]:
    """RMS position error (mm) of the protocol's free run on consecutive stretches of the test record."""
    from flowchart2sdnn.identify.offline.initstate import estimate_initial_state
    from flowchart2sdnn.identify.offline.problem import columns_of
    from flowchart2sdnn.network.alignment import run_aligned

    compiled, x = result._network()
    q = test.columns[OUTPUT]
    state = estimate_initial_state(compiled, x, test, "zoh", WINDOW, {OUTPUT: float(q[0])})
    y = run_aligned(compiled, state.theta, columns_of(test, compiled.input_names), "zoh",
                    history=state.history)[:, 0]
    n = int(round(seconds / test.sample_time))
    e = 1000.0 * (q - y)
    return [float(np.sqrt(np.mean(e[i:i + n] ** 2))) for i in range(WINDOW, len(e), n)]


def diagnosed(train, test, rounds: int = 3):
    """diagnose from the symmetric chart, trained on `train`, validated on `test` by the protocol (window and
    scoring as `protocol`)."""
    return sd.diagnose(CHART, train, [test], rounds=rounds, init_window=WINDOW)


def diagnosed_viscous(train, test):
    """(diagnosis, test RMSE mm, refit): one round of diagnose from the viscous-only chart on train alone (its
    default validation: the last 30 % of train), the augmented chart refitted on all of train and scored by the
    protocol: the test record plays no part in choosing the effect."""
    d = sd.diagnose(viscous_only(sd.load_chart(CHART)), train, rounds=1)
    rmse, refit = protocol(d.diagram, train, test)
    return d, rmse, refit


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--starts", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--diagnose", action="store_true", help="also run sdnn diagnose from the symmetric chart")
    args = parser.parse_args()
    train, test = records()
    spread = 1000.0 * float(np.std(test.columns[OUTPUT][WINDOW:]))
    chart, asymmetric = sd.load_chart(CHART), sd.load_chart(ASYMMETRIC)
    rows = [("published IDIM-LS parameters, symmetric chart (not fitted)",
             *protocol(with_values(chart, IDIM_LS), train, test, fit=False)),
            ("published IDIM-LS parameters, asymmetric chart (not fitted)",
             *protocol(with_values(asymmetric, IDIM_LS_ASYMMETRIC), train, test, fit=False)),
            ("emps.yaml, viscous friction only (Fc = offset = 0), identified on train",
             *protocol(viscous_only(chart), train, test, args.starts, args.seed)),
            ("emps.yaml identified on train", *protocol(chart, train, test, args.starts, args.seed)),
            ("emps_asymmetric.yaml identified on train", *protocol(asymmetric, train, test, args.starts, args.seed))]
    if args.diagnose:
        d, rmse, refit = diagnosed_viscous(train, test)
        accepted = ", ".join(f"{a['effect']} at {a['at']}" + (f" ({a['label']})" if a["label"] else "")
                             for a in d.report["accepted"]) or "nothing"
        rows.append((f"diagnose (1 round, train only) from viscous only: {accepted}", rmse, refit))
    oracle = protocol(asymmetric, test, test)
    print(f"EMPS, official protocol: train on train.csv, test.csv from the state fitted on its first {WINDOW} "
          f"samples, RMSE from sample {WINDOW} (std of the test position {spread:.2f} mm)")
    print(f"{'model':72s} {'test mm':>8s} {'fit %':>6s} {'train mm':>8s}  per 5 s of test [mm]")
    for label, rmse, result in rows:
        train_mm = protocol(result.chart, train, train, fit=False)[0]  # train.csv scored the same way
        stretches = " ".join(f"{s:.1f}" for s in error_by_stretch(result, test))
        print(f"{label:72s} {rmse:8.2f} {100 * (1 - rmse / spread):6.1f} {train_mm:8.2f}  {stretches}")
    for name, mm in PUBLISHED_MM.items():
        print(f"{name + ' (published)':72s} {mm:8.2f} {100 * (1 - mm / spread):6.1f}")
    print(f"{'oracle, not a result: emps_asymmetric.yaml fitted on test.csv itself':72s} {oracle[0]:8.2f}")
    for label, _, result in rows[2:] + [("oracle", *oracle)]:
        values = ", ".join(f"{n} = {e.value:.4g} " + (f"[{e.ci95[0]:.4g}, {e.ci95[1]:.4g}]" if e.ci95 else "(fixed)")
                           for n, e in result.parameters.items())
        print(f"{label} ({result.status}, converged {result.converged}): {values}")
        for w in result.warnings:
            print("  warning:", w)
    print("published IDIM-LS: " + ", ".join(f"{k} = {v:.4g}" for k, v in IDIM_LS.items())
          + "; asymmetric: " + ", ".join(f"{k} = {v:.4g}" for k, v in IDIM_LS_ASYMMETRIC.items()))
    if args.diagnose:
        d = diagnosed(train, test)
        print("diagnose --validate test.csv --init-window 20 from emps.yaml (effects chosen on the test record): "
              f"test RMSE {1000 * d.report['before']['validation_rms']:.2f} mm before")
        for r in d.report["rounds"]:
            label = f"{r['effect']} at {r['at']}" + (f" ({r['label']})" if r["label"] else "")
            print(f"  round {r['round']}: {label}, accepted {r['accepted']}: "
                  f"{1000 * r['validation_rms_before']:.2f} -> {1000 * (r['validation_rms_after'] or np.nan):.2f} mm")
        print(f"  stop: {d.report['stop']}")


if __name__ == "__main__":
    main()

"""`sdnn diagnose` on real measurements: EMPS and the UWaterloo flexible drive (the numbers of benchmarks/notes/diagnose.md).

EMPS (../shared/data/real/emps): the chart is a mass with viscous friction only
(tests/data/diagnose/emps_mass.yaml). diagnose runs on train.csv with its last 30 % as validation; the chart
as given and the augmented chart are then refitted on the whole train.csv and simulated on the official test
record (test.csv, the pulses record) from the force alone, the initial position and speed taken from a
quadratic fit to the first 20 samples; the score is the RMSE of samples 20.. in mm (the benchmark protocol).
train.csv starts in motion too: by default the chart's speed starts at train's v0 (same fit) for diagnose and
the refit (`moving_start`); the runs with v0 = 0 are printed first for comparison. The identified friction
force (viscous term plus learned curve or the physical `coulomb` terms) is least-squares fitted by
Fv*v + Fc*sign(v) + offset (and per direction) over the speed range of the data, to compare with the
published IDIM-LS values. `emps_spread` refits the diagnosed chart on other stretches (halves of train, the
test record itself as an oracle) to show how much the test RMSE depends on the friction of the stretch.
`emps_record_difference` measures, without any model, how much more force the test record needs than the
training record at the same speed (both follow the same trajectory to 0.09 mm, so the difference of their
forces is the difference of their friction), and `emps_friction_scale` how the test RMSE of the diagnosed
chart moves when all its friction is scaled by 1 + d: together they show that the test RMSE is set by a
friction level 1-2 % above train's, which nothing fitted on train alone can know.

UWaterloo MTE 360 flexible drive: the chart without Coulomb friction (diagrams/real/flexible_drive_linear.yaml),
trained on square_2V, validated on square_1p5V; fit % before and after on every record of the folder.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/real_diagnose.py [emps] [flexible]``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import read_csv
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.problem import metrics
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real"
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}


def initial_state(time_s: np.ndarray, q: np.ndarray, n: int = 20) -> tuple[float, float]:
    """(q0, v0) at the first sample from a quadratic fit to the first n samples."""
    c = np.polyfit(time_s[:n] - time_s[0], q[:n], 2)
    return float(c[2]), float(c[1])


def with_initial_speed(diagram, record):
    """The chart with the speed integrator `v` starting at the record's v0 (quadratic fit, first 20 samples)."""
    _, v0 = initial_state(record.time, record.columns["q"])
    return dataclasses.replace(diagram, blocks=tuple(
        dataclasses.replace(b, init=v0) if b.name == "v" else b for b in diagram.blocks))


def emps_test_rmse_mm(diagram, test) -> float:
    """Free-run simulation RMSE on the test record, samples 20.., in mm (initial state from the first 20)."""
    q, force = test.columns["q"], test.columns["F"]
    q0, _ = initial_state(test.time, q)
    chart = with_initial_speed(diagram, test)
    compiled = CompiledNetwork(compile_diagram(chart).network)
    y = run_aligned(compiled, compiled.theta0(), force[:, None], "zoh", {"q": q0})[:, 0]
    return 1000.0 * float(np.sqrt(np.mean((q[20:] - y[20:]) ** 2)))


def friction_coefficients(result: dict, speed_max: float) -> dict:
    """Fv, Fc, offset of the identified friction, symmetric and per direction.

    The friction force is the chart's viscous term plus what diagnose added: learned curves (`friction`) and
    the physical terms of `coulomb` (Fc_v*sign(v) + c_v + dFv_v*max(v, 0); sign for the sign_smooth, whose
    eps is far below the smallest speed sampled here).
    """
    p = {k: v["value"] for k, v in result["parameters"].items()}
    v = np.concatenate([-np.linspace(0.05, 1, 200), np.linspace(0.05, 1, 200)]) * speed_max
    force = p.get("Fv", 0.0) * v
    for w in result["nonlinear"].values():
        a, vv = np.asarray(w["a"]), np.asarray(w["v"])
        b = np.asarray(w.get("b") or np.zeros_like(a))
        force = force + np.tanh(np.outer(v, a) + b) @ vv
    force = force + p.get("Fc_v", 0.0) * np.sign(v) + p.get("c_v", 0.0) + p.get("dFv_v", 0.0) * np.maximum(v, 0.0)
    sym = np.linalg.lstsq(np.column_stack([v, np.sign(v), np.ones_like(v)]), force, rcond=None)[0]
    out = {"M": p["M"], "Fv": sym[0], "Fc": sym[1], "offset": sym[2]}
    for side, mask in (("+", v > 0), ("-", v < 0)):
        c = np.linalg.lstsq(np.column_stack([v[mask], np.ones(mask.sum())]), force[mask], rcond=None)[0]
        out["Fv" + side], out["Fc" + side] = c[0], abs(c[1])
    return out


def emps(rounds: int = 3, moving_start: bool = True):
    """diagnose, refit on all of train, test RMSE. `moving_start`: the training record starts in motion too
    (about 6 mm/s), so the chart's speed starts at train's v0 (quadratic fit to its first 20 samples), as the
    test simulation does; without it the speed starts at 0 and the fit bends the friction to make up for it."""
    folder = REAL / "emps"
    maps = {"F": "force_N", "q": "q_meas_m"}
    train = read_csv(folder / "train.csv", ["F", "q"], maps, 0.001)
    test = read_csv(folder / "test.csv", ["F", "q"], maps, 0.001)
    chart = load_diagram(ROOT / "tests" / "data" / "diagnose" / "emps_mass.yaml")
    if moving_start:
        chart = with_initial_speed(chart, train)
    t0 = time.perf_counter()
    d = diagnose(chart, train, (), DiagnoseSettings(rounds=rounds))
    start = "v0 from train" if moving_start else "v0 = 0"
    print(f"EMPS diagnose --rounds {rounds} ({start}): {time.perf_counter() - t0:.0f} s; accepted: "
          + ", ".join(f"{a['effect']} at {a['at']}" + (f" ({a['label']})" if a["label"] else "")
                      for a in d.report["accepted"]))
    for r in d.report["rounds"]:
        print(f"  round {r['round']} {r['effect']} at {r['at']}: accepted {r['accepted']}, validation RMS "
              f"{1000 * r['validation_rms_before']:.2f} -> {1000 * (r['validation_rms_after'] or np.nan):.2f} mm")
    speed = float(np.max(np.abs(np.diff(train.columns["q"]) / 0.001)))
    for name, fitted in (("chart as given", d.nominal), ("after diagnose", d.final)):
        full = identify(fitted.diagram, train, None, IdentifySettings(max_iter=150))
        val_mm = 1000 * fitted.validation_rms
        print(f"  {name}: validation (last 30 % of train) {val_mm:.2f} mm; refitted on all of train: "
              f"test RMSE {emps_test_rmse_mm(full.diagram, test):.2f} mm "
              f"(without refit {emps_test_rmse_mm(fitted.diagram, test):.2f} mm)")
        print("    parameters: " + ", ".join(f"{k} = {v['value']:.4g}" for k, v in full.result["parameters"].items()))
        if len(full.result["parameters"]) > 2 or full.result["nonlinear"]:
            c = friction_coefficients(full.result, speed)
            print("    friction: " + ", ".join(f"{k} = {v:.4g}" for k, v in c.items()))
    print("  published (IDIM-LS): " + ", ".join(f"{k} = {v}" for k, v in PUBLISHED.items()))
    return d


def emps_spread(diagram, train, test) -> None:
    """How much the test RMSE depends on which stretch of measurements the same chart is fitted on.

    The chart (the diagnosed one) is refitted on windows of train.csv, each simulated from its own first
    sample (v0 from the quadratic fit), and on test.csv itself (an oracle, not a benchmark result: it shows
    what the structure can reach on that record).
    """
    n = train.n_rows
    windows = {"all of train": train, "first 70 % of train": train.slice(0, int(0.7 * n)),
               "first half of train": train.slice(0, n // 2), "second half of train": train.slice(n // 2, n),
               "test itself (oracle)": test}
    print("  | fitted on | RMSE on its window [mm] | test RMSE [mm] | M | Fv+ | Fv- | Fc+ | Fc- |")
    print("  |---|---|---|---|---|---|---|---|")
    for name, ds in windows.items():
        fit = identify(with_initial_speed(diagram, ds), ds, None, IdentifySettings(max_iter=150))
        c = friction_coefficients(fit.result, 0.12)
        own = 1000 * fit.result["fit"]["train"]["rms"]["q"]
        print(f"  | {name} | {own:.2f} | {emps_test_rmse_mm(fit.diagram, test):.2f} | {c['M']:.2f} | "
              f"{c['Fv+']:.1f} | {c['Fv-']:.1f} | {c['Fc+']:.2f} | {c['Fc-']:.2f} |")


def record_difference(v: np.ndarray, force_a: np.ndarray, force_b: np.ndarray, edges: np.ndarray,
                      bins: np.ndarray, guard: int = 100) -> np.ndarray:
    """Mean of force_b - force_a per speed bin, over the samples at least `guard` samples after every edge.

    For two records that follow the same trajectory (same speed and acceleration at every sample), this is
    the difference of the force the plant needed, i.e. of its friction, at that speed; samples shortly after
    an edge of the test record's pulses (its controller's transients) are left out. NaN for an empty bin.
    """
    since = np.full(len(v), np.iinfo(np.int64).max)
    for k in np.sort(edges):
        idx = np.arange(k, len(v))
        since[idx] = np.minimum(since[idx], idx - k)
    keep = since >= guard
    d = force_b - force_a
    out = np.full(len(bins) - 1, np.nan)
    for i, (lo, hi) in enumerate(zip(bins[:-1], bins[1:], strict=True)):
        m = keep & (v >= lo) & (v < hi)
        if m.any():
            out[i] = float(d[m].mean())
    return out


def emps_record_difference(train, test) -> None:
    """Model-free: the extra force the test record needs over the training record at the same speed."""
    q_a, q_b = train.columns["q"], test.columns["q"]
    print(f"EMPS test vs train, same trajectory: q_test - q_train = {1000 * np.sqrt(np.mean((q_b - q_a) ** 2)):.3f} "
          "mm rms; F_test - F_train (N) per speed bin, >= 100 ms after every pulse edge:")
    v = np.gradient(q_a, 0.001)
    edges = np.flatnonzero(np.abs(np.diff(test.columns["F"])) > 100.0) + 1
    bins = np.array([-0.14, -0.10, -0.06, -0.02, -0.005, 0.005, 0.02, 0.06, 0.10, 0.14])
    diff = record_difference(v, train.columns["F"], test.columns["F"], edges, bins)
    ranges = (f"{lo:+.3f}..{hi:+.3f}" for lo, hi in zip(bins[:-1], bins[1:], strict=True))
    print("  | v [m/s] | " + " | ".join(ranges) + " |")
    print("  | F_test - F_train [N] | " + " | ".join(f"{x:+.2f}" for x in diff) + " |")


def with_parameters(diagram, values: dict):
    """The chart with the given parameters' values (their `init`) replaced."""
    return dataclasses.replace(diagram, parameters=tuple(
        dataclasses.replace(p, init=values[p.name]) if p.name in values else p for p in diagram.parameters))


def emps_friction_scale(diagram, train, test, scales=(-0.02, -0.01, 0.0, 0.01, 0.02, 0.03)) -> None:
    """Test and train RMSE of the chart refitted on all of train, with all its friction scaled by 1 + d.

    Friction parameters: the viscous Fv and the `coulomb` option's Fc_*, c_*, dFv_* (a learned friction
    curve is not scaled).
    """
    fit = identify(with_initial_speed(diagram, train), train, None, IdentifySettings(max_iter=150))
    values = {k: v["value"] for k, v in fit.result["parameters"].items()}
    friction = [k for k in values if k == "Fv" or k.split("_")[0] in ("Fc", "c", "dFv")]
    print("  | friction x (1 + d), d = | " + " | ".join(f"{d:+.0%}" for d in scales) + " |")
    rows = {"test RMSE [mm]": [], "train RMSE [mm]": []}
    for d in scales:
        chart = with_parameters(fit.diagram, {k: values[k] * (1 + d) for k in friction})
        rows["test RMSE [mm]"].append(emps_test_rmse_mm(chart, test))
        rows["train RMSE [mm]"].append(emps_test_rmse_mm(chart, train))
    for name, xs in rows.items():
        print(f"  | {name} | " + " | ".join(f"{x:.2f}" for x in xs) + " |")


def flexible() -> None:
    folder = REAL / "uwaterloo_mte360_flexible_drive"
    maps = {"u": "u_V", "v1": "v1_cart1_mm_s", "v2": "v2_cart2_mm_s"}
    cols = ["u", "v1", "v2"]
    read = {p.stem: read_csv(p, cols, maps, 0.001) for p in sorted(folder.glob("*.csv"))}
    t0 = time.perf_counter()
    d = diagnose(load_diagram(ROOT / "diagrams" / "real" / "flexible_drive_linear.yaml"), read["square_2V"],
                 [read["square_1p5V"]], DiagnoseSettings(rounds=3))
    print(f"flexible drive diagnose: {time.perf_counter() - t0:.0f} s; accepted: "
          + ", ".join(f"{a['effect']} at {a['at']}" for a in d.report["accepted"]))
    for name, w in d.report["final"]["nonlinear"].items():
        a, v = np.asarray(w["a"]), np.asarray(w["v"])
        b = np.asarray(w.get("b") or np.zeros_like(a))
        at = np.array([-100.0, -50.0, -10.0, 10.0, 50.0, 100.0])
        curve = np.tanh(np.outer(at, a) + b) @ v
        print(f"  {name} [V] at " + ", ".join(f"{s:g}" for s in at) + " mm/s: " + ", ".join(f"{x:.3f}" for x in curve))
    print("  | record | v1 before | v1 after | v2 before | v2 after |")
    print("  |---|---|---|---|---|")
    for stem, ds in read.items():
        row = []
        for fitted in (d.nominal, d.final):
            m = metrics(fitted.identification.problem.compiled, fitted.identification.x, ds, "zoh")
            row.append(m["fit_percent"])
        mark = "*" if stem == "square_2V" else ""
        print(f"  | {stem}{mark} | {row[0]['v1']:.1f} | {row[1]['v1']:.1f} | {row[0]['v2']:.1f} | {row[1]['v2']:.1f} |")


if __name__ == "__main__":
    which = sys.argv[1:] or ["emps", "flexible"]
    if not REAL.is_dir():
        sys.exit(f"{REAL} is absent")
    if "emps" in which:
        emps(3, moving_start=False)
        emps(1, moving_start=False)
        emps(3)
        d1 = emps(1)
        maps = {"F": "force_N", "q": "q_meas_m"}
        tr, te = (read_csv(REAL / "emps" / f, ["F", "q"], maps, 0.001) for f in ("train.csv", "test.csv"))
        print("EMPS, the chart after diagnose --rounds 1 refitted on other stretches:")
        emps_spread(d1.final.diagram, tr, te)
        emps_record_difference(tr, te)
        print("EMPS, the chart after diagnose --rounds 1 refitted on all of train, its friction scaled:")
        emps_friction_scale(d1.final.diagram, tr, te)
    if "flexible" in which:
        flexible()

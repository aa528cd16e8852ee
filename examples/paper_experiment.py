"""Reproduce the paper's experiment (two_mass_sdnn_paper.md, sections 6.1-6.3, Tables 1 and 2) on the test bench.

1. Data: ``sdnn excite`` (the paper's APRBS +-7 N*m with holds of 10-250 ms plus the relay bias) on
   diagrams/paper/engine_plant.yaml (the motor alone, stage 1) and diagrams/paper/plant.yaml (the two-mass
   drive, stage 2): 100 s at 1 kHz, Gaussian measurement noise of 0.01 rad/s on every speed.
2. Stage 1 (Table 1): J1 and the motor friction MR1 (3 tanh neurons) of diagrams/paper/engine.yaml from the
   idle record, from J1 = 0.6 and J1 = 0.01.
3. Stage 2 (Table 2): J2, c, d and the load friction MR2 of diagrams/paper/two_mass.yaml from the speed w2,
   with J1 and MR1 fixed from the stage-1 result (``--fix-from``), from (J2, d, c) = (0.7, 0.4, 100) and
   (0.1, 0.7, 800); the second start once more with a multi-start (``--starts N``).
4. Both stages offline and quasi-online (``--online --window 25000 --average 25000``).

Offline, stage 2 follows a staged recipe (see docs/paper_experiment.md for why): (a) fit on the first 1 s,
(b) on the first 3 s, (c) restart the learned curves from their initial weights and fit them alone on the whole
record with the physical parameters held, (d) fit everything on the whole record. Each step is one call of
:func:`flowchart2sdnn.identify.run.identify` (what ``sdnn identify --split`` does on a leading part of a
record); a multi-start acts on step (a). Stage 1 is one plain ``identify`` on the whole record.

Every learned friction curve is scored against the plant's true friction
``Fs sign(w) - (Fs - Fc) tanh(w/ws) + b w`` (sign smoothed as in the plant) by the RMS difference over a grid
of the speeds the record visits, leaving out the band ``|w| < BAND`` where the true curve jumps; the table
gives it in % of the largest true friction on that grid.

Run from the repository root: ``python examples/paper_experiment.py`` (``--help`` for the options).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import Dataset, read_csv, write_csv
from flowchart2sdnn.data.excitation import ExcitationSettings, excite
from flowchart2sdnn.diagram.model import Diagram
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.chartio import dump_diagram, fix_from_result, with_values
from flowchart2sdnn.identify.problem import required_columns
from flowchart2sdnn.identify.run import IdentifySettings, identify

REPO = Path(__file__).resolve().parents[1]
CHARTS = REPO / "diagrams" / "paper"
#: speeds with |w| below this (rad/s) are left out of the friction score: the true curve jumps there
BAND = 0.05
NOISE = 0.01  # rad/s, measurement noise on every logged speed
DATA_SEEDS = {"engine": 1, "plant": 2}
TABLE1_STARTS = (0.6, 0.01)
TABLE2_STARTS = ((0.7, 0.4, 100.0), (0.1, 0.7, 800.0))  # (J2, d, c) as in the paper's Table 2
TRUTH_NAMES = ("J1", "J2", "c", "d")
#: the paper's results: Table 1 (J1, E) and Table 2 (J2, d, c, E)
PAPER_T1 = ((0.1912, 5.629e-2), (0.1912, 4.387e-2))
PAPER_T2 = ((0.3838, 0.2406, 477.2, 3.792e-2), (0.3881, 0.0919, 477.6, 6.400e-2))


# --------------------------------------------------------------------------------------------- data
def make_data(out: Path, seconds: float, noise: float = NOISE) -> dict[str, Path]:
    """Excite both plant charts as ``sdnn excite PLANT --seconds S --seed N --noise σ`` does; return the CSVs."""
    paths = {}
    for name, chart in (("engine", "engine_plant.yaml"), ("plant", "plant.yaml")):
        plant = load_diagram(CHARTS / chart)
        columns = excite(plant, ExcitationSettings(seconds=seconds, seed=DATA_SEEDS[name], noise_std=noise))
        paths[name] = out / f"{name}.csv"
        write_csv(paths[name], columns)
    return paths


def read_record(path: Path, chart: Diagram) -> Dataset:
    return read_csv(path, required_columns(chart), {}, chart.sample_time)


# ----------------------------------------------------------------------------------------- friction
def true_friction(plant: Diagram, machine: int) -> Callable[[np.ndarray], np.ndarray]:
    """The plant's friction on machine 1 or 2, from its parameters Fs, Fc, b, ws and the sign block's eps."""
    p = {q.name: q.init for q in plant.parameters}
    fs, fc, b, ws = (p[f"{k}{machine}"] for k in ("Fs", "Fc", "b", "ws"))
    eps = plant.block(f"sg{machine}").eps
    return lambda w: fs * np.tanh(w / eps) - (fs - fc) * np.tanh(w / ws) + b * w


def learned_curve(weights: dict) -> Callable[[np.ndarray], np.ndarray]:
    """y = sum v_i tanh(a_i w + b_i) of a nonlinear block's weights (as stored in RESULT.json)."""
    a, v = np.asarray(weights["a"]), np.asarray(weights["v"])
    b = np.asarray(weights.get("b") or np.zeros_like(a))
    return lambda w: np.tanh(np.multiply.outer(w, a) + b) @ v


def curve_error(weights: dict, truth: Callable, speeds: np.ndarray, band: float = BAND) -> tuple[float, float]:
    """(RMS of learned - true, largest |true|) on 2001 speeds over [min, max] of `speeds` with |w| >= band."""
    grid = np.linspace(float(np.min(speeds)), float(np.max(speeds)), 2001)
    grid = grid[np.abs(grid) >= band]
    f_true = truth(grid)
    rms = float(np.sqrt(np.mean((learned_curve(weights)(grid) - f_true) ** 2)))
    return rms, float(np.max(np.abs(f_true)))


# ------------------------------------------------------------------------------------ staged offline fit
@dataclass(frozen=True)
class Step:
    """One offline step: fit on the first `seconds` of the record (None: all of it)."""

    seconds: float | None
    curves_only: bool = False  # hold every physical parameter, fit only the learned curves
    restart_curves: bool = False  # restart the learned curves from the chart's initial weights first
    multistart: bool = False  # this step gets the --starts N


#: Stage 2 offline: locate the shaft resonance on short horizons, then the friction on the whole record.
STAGED = (Step(1.0, multistart=True), Step(3.0), Step(None, curves_only=True, restart_curves=True), Step(None))
#: Stage 1 offline: one plain fit on the whole record.
PLAIN = (Step(None, multistart=True),)


def _initial_curves(chart: Diagram, seed: int) -> dict[str, dict]:
    """The learned blocks' initial weights as the compiler draws them (or as stored in the chart)."""
    curves: dict[str, dict] = {}
    for fw in compile_diagram(chart, seed=seed).network.free_weights:
        if fw.block is not None and not fw.fixed:
            curves.setdefault(fw.block, {"a": [], "v": [], "b": []})[fw.role].append(fw.init)
    return {k: {"a": w["a"], "v": w["v"], **({"b": w["b"]} if w["b"] else {})} for k, w in curves.items()}


def staged_identify(chart: Diagram, data: Dataset, steps: Sequence[Step], starts: int = 1, seed: int = 0,
                    max_iter: int = 60, log: Callable[[str], None] = lambda s: None):
    """Run `steps` one after the other, each starting from the values the previous one found.

    Returns the :class:`~flowchart2sdnn.identify.run.Identification` of the last step and the step log.
    """
    initial = _initial_curves(chart, seed)
    params = {p.name: p.init for p in chart.parameters}
    curves: dict[str, dict] = {}
    out, history = None, []
    for step in steps:
        if step.restart_curves:
            curves.update(initial)
        current = with_values(chart, params, curves)
        if step.curves_only:
            current = replace(current, parameters=tuple(replace(p, fixed=True) for p in current.parameters))
        n = data.n_rows if step.seconds is None else min(data.n_rows, round(step.seconds / chart.sample_time))
        settings = IdentifySettings(starts=starts if step.multistart else 1, seed=seed, max_iter=max_iter)
        t = time.perf_counter()
        out = identify(current, data.slice(0, n), None, settings)
        r = out.result
        params.update({k: v["value"] for k, v in r["parameters"].items()})
        curves.update({k: {key: w[key] for key in ("a", "v", "b") if key in w}
                       for k, w in r["nonlinear"].items() if not w["fixed"]})
        entry = {"rows": n, "curves_only": step.curves_only, "restart": step.restart_curves,
                 "starts": settings.starts, "cost": r["fit"]["train"]["cost"], "status": r["status"],
                 "seconds": round(time.perf_counter() - t, 2),
                 "values": {k: v["value"] for k, v in r["parameters"].items() if not v["fixed"]}}
        if "multistart" in r:
            entry["multistart_costs"] = r["multistart"]["costs"]
        history.append(entry)
        log(f"    {n} rows{' curves only' if step.curves_only else ''}: cost {entry['cost']:.4g} "
            f"({entry['seconds']:.1f} s) {', '.join(f'{k} {v:.4g}' for k, v in entry['values'].items())}")
    # the last step ran with the chart's own fixed flags, so its identified chart is the full result
    return out, history


# ----------------------------------------------------------------------------------------------- runs
@dataclass
class Run:
    """One row of the results: where it started, what it found, how well, how long."""

    stage: int
    mode: str  # "offline" | "quasi-online"
    label: str
    init: dict
    values: dict = field(default_factory=dict)
    cost: float | None = None
    curve_rms: float | None = None  # % of the largest true friction
    curve_name: str = ""
    seconds: float = 0.0
    status: str = ""
    history: list = field(default_factory=list)
    result_file: str = ""


def _save(out_dir: Path, name: str, outcome, history=None) -> Path:
    result = dict(outcome.result)
    if history is not None:
        result["staged"] = history
    path = out_dir / f"{name}.json"
    chart = out_dir / f"{name}.chart.yaml"
    result["identified_chart"] = str(chart)
    path.write_text(json.dumps(result, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    chart.write_text(dump_diagram(outcome.diagram, {"from": str(path), "status": result["status"]}),
                     encoding="utf-8")
    return path


def _score(run: Run, outcome, curve: str, truth: Callable, speeds: np.ndarray, online: bool) -> None:
    r = outcome.result
    run.values = {k: v["value"] for k, v in r["parameters"].items()}
    run.status = r["status"]
    run.cost = r["online"]["mean_cost"] if online else r["fit"]["train"]["cost"]
    rms, peak = curve_error(r["nonlinear"][curve], truth, speeds)
    run.curve_rms, run.curve_name = 100.0 * rms / peak, curve


def run_fit(run: Run, chart: Diagram, data: Dataset, out_dir: Path, name: str, curve: str, truth, speeds,
            steps: Sequence[Step], starts: int, seed: int, max_iter: int, log) -> Path:
    t = time.perf_counter()
    if run.mode == "offline":
        outcome, run.history = staged_identify(chart, data, steps, starts, seed, max_iter, log)
    else:
        outcome = identify(chart, data, None, IdentifySettings(online=True, window=min(25000, data.n_rows),
                                                               average=min(25000, data.n_rows), seed=seed))
    run.seconds = time.perf_counter() - t
    _score(run, outcome, curve, truth, speeds, run.mode != "offline")
    path = _save(out_dir, name, outcome, run.history or None)
    run.result_file = str(path)
    log(f"  {run.label}: {', '.join(f'{k} {v:.5g}' for k, v in run.values.items())}; cost {run.cost:.4g}; "
        f"{curve} RMS {run.curve_rms:.2f} % ({run.seconds:.1f} s, {run.status})")
    return path


def experiment(out_dir: Path, seconds: float = 100.0, starts: int = 8, seed: int = 0, max_iter: int = 60,
               modes: Sequence[str] = ("offline", "quasi-online"), log: Callable[[str], None] = print) -> list[Run]:
    """The whole experiment; returns the runs in table order and writes every result under `out_dir`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    paths = make_data(out_dir, seconds)
    log(f"data: {paths['engine'].name}, {paths['plant'].name} ({seconds:g} s, noise {NOISE} rad/s, "
        f"{time.perf_counter() - t:.1f} s)")
    plant = load_diagram(CHARTS / "plant.yaml")
    engine = load_diagram(CHARTS / "engine.yaml")
    two_mass = load_diagram(CHARTS / "two_mass.yaml")
    d1, d2 = read_record(paths["engine"], engine), read_record(paths["plant"], two_mass)
    w1 = read_csv(paths["engine"], ["w1"], {}, engine.sample_time).columns["w1"]
    w2 = read_csv(paths["plant"], ["w2"], {}, two_mass.sample_time).columns["w2"]
    runs: list[Run] = []
    for mode in modes:
        tag = "off" if mode == "offline" else "on"
        stage1_file = None
        for i, j1 in enumerate(TABLE1_STARTS):
            run = Run(1, mode, f"stage 1 {mode}, J1 from {j1:g}", {"J1": j1})
            log(f"{run.label}")
            path = run_fit(run, with_values(engine, {"J1": j1}, {}), d1, out_dir, f"stage1_{tag}_start{i + 1}",
                           "MR1", true_friction(plant, 1), w1, PLAIN, 1, seed, max_iter, log)
            stage1_file = stage1_file or path  # the paper continues from its first Table 1 row
            runs.append(run)
        fixed, _ = fix_from_result(two_mass, stage1_file)
        variants = [(k, s, 1) for k, s in enumerate(TABLE2_STARTS)]
        if mode == "offline" and starts > 1:
            variants.append((1, TABLE2_STARTS[1], starts))
        for k, (j2, d, c), n_starts in variants:
            label = f"stage 2 {mode}, start {k + 1}" + (f", --starts {n_starts}" if n_starts > 1 else "")
            run = Run(2, mode, label, {"J2": j2, "d": d, "c": c})
            log(label)
            name = f"stage2_{tag}_start{k + 1}" + (f"_starts{n_starts}" if n_starts > 1 else "")
            run_fit(run, with_values(fixed, {"J2": j2, "d": d, "c": c}, {}), d2, out_dir, name, "MR2",
                    true_friction(plant, 2), w2, STAGED, n_starts, seed, max_iter, log)
            runs.append(run)
    return runs


# ---------------------------------------------------------------------------------------------- table
def truth_values(plant: Diagram) -> dict[str, float]:
    return {p.name: p.init for p in plant.parameters if p.name in TRUTH_NAMES}


def _pct(value: float, true: float) -> str:
    return f"{value:.4g} ({100 * (value - true) / true:+.2f} %)"


def acceptance(run: Run, truth: dict[str, float]) -> bool:
    """J1, J2, c within 2 %, d within 10 %, the friction curve within 5 % of its maximum."""
    limits = {"J1": 0.02, "J2": 0.02, "c": 0.02, "d": 0.10}
    names = ("J1",) if run.stage == 1 else ("J2", "c", "d")
    ok = all(abs(run.values[n] - truth[n]) <= limits[n] * abs(truth[n]) for n in names)
    return ok and run.curve_rms is not None and run.curve_rms <= 5.0


def tables(runs: Sequence[Run], truth: dict[str, float], noise: float = NOISE, rows: int | None = None) -> str:
    """The README tables (markdown): paper, truth, ours."""
    q = rows
    floor = "" if q is None else f" (noise floor 1/2 Q σ² = {0.5 * q * noise**2:.3g} offline, " \
        f"{0.5 * min(q, 25000) * noise**2:.3g} quasi-online)"
    lines = ["Table 1 (stage 1, motor in idle)", "",
             "| run | J1 start | J1 [kg m²] | MR1 RMS error [% of max] | E | time [s] | pass |",
             "|---|---|---|---|---|---|---|"]
    for (j1, e), s in zip(PAPER_T1, TABLE1_STARTS, strict=True):
        lines.append(f"| paper (quasi-online) | {s:g} | {j1} | (figure only) | {e:.4g} | | |")
    lines.append(f"| truth (plant chart) | | {truth['J1']} | 0 | | | |")
    for r in runs:
        if r.stage == 1:
            lines.append(f"| ours, {r.mode} | {r.init['J1']:g} | {_pct(r.values['J1'], truth['J1'])} | "
                         f"{r.curve_rms:.2f} | {r.cost:.4g} | {r.seconds:.0f} | {'yes' if acceptance(r, truth) else 'NO'} |")
    lines += ["", "Table 2 (stage 2, two-mass drive; J1 and MR1 fixed from stage 1)", "",
              "| run | start (J2, d, c) | J2 [kg m²] | d [N m s/rad] | c [N m/rad] | MR2 RMS error [% of max] | E "
              "| time [s] | pass |", "|---|---|---|---|---|---|---|---|---|"]
    for (j2, d, c, e), s in zip(PAPER_T2, TABLE2_STARTS, strict=True):
        lines.append(f"| paper (quasi-online) | {s[0]:g}, {s[1]:g}, {s[2]:g} | {j2} | {d} | {c} | (figure only) "
                     f"| {e:.4g} | | |")
    lines.append(f"| truth (plant chart) | | {truth['J2']} | {truth['d']} | {truth['c']} | 0 | | | |")
    for r in runs:
        if r.stage == 2:
            how = r.mode + (f", --starts {r.label.rsplit(' ', 1)[-1]}" if "--starts" in r.label else "")
            lines.append(f"| ours, {how} | {r.init['J2']:g}, {r.init['d']:g}, {r.init['c']:g} | "
                         f"{_pct(r.values['J2'], truth['J2'])} | {_pct(r.values['d'], truth['d'])} | "
                         f"{_pct(r.values['c'], truth['c'])} | {r.curve_rms:.2f} | {r.cost:.4g} | {r.seconds:.0f} "
                         f"| {'yes' if acceptance(r, truth) else 'NO'} |")
    lines += ["", f"E: ours offline = 1/2 sum of squared free-run errors over the whole record; quasi-online and "
              f"paper = mean window cost over the last 25 000 steps{floor}. Friction error: RMS over the speeds the "
              f"record visits, |w| >= {BAND} rad/s."]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("paper_experiment_output"),
                    help="directory for the data, the results and the identified charts")
    ap.add_argument("--seconds", type=float, default=100.0, help="record length (paper: 100 s)")
    ap.add_argument("--starts", type=int, default=8, help="multi-start for the second Table 2 start")
    ap.add_argument("--seed", type=int, default=0, help="seed of the initial curves and the multi-start")
    ap.add_argument("--max-iter", type=int, default=60, help="LM iterations per offline step")
    ap.add_argument("--offline-only", action="store_true", help="skip the quasi-online runs")
    args = ap.parse_args(argv)
    t = time.perf_counter()
    modes = ("offline",) if args.offline_only else ("offline", "quasi-online")
    runs = experiment(args.out, args.seconds, args.starts, args.seed, args.max_iter, modes)
    truth = truth_values(load_diagram(CHARTS / "plant.yaml"))
    rows = round(args.seconds / 0.001) - 1
    text = tables(runs, truth, rows=rows)
    (args.out / "tables.md").write_text(text, encoding="utf-8")
    print()
    print(text)
    print(f"total {time.perf_counter() - t:.0f} s; results in {args.out}/")
    return 0 if all(acceptance(r, truth) for r in runs if r.mode == "offline" and "start 1" in r.label
                    or "--starts" in r.label) else 1


if __name__ == "__main__":
    sys.exit(main())

"""Reproduce the paper's experiment (two_mass_sdnn_paper.md, sections 6.1-6.3, Tables 1 and 2) on the test bench.

1. Data: ``sdnn excite`` (the paper's APRBS +-7 N*m with holds of 10-250 ms plus the relay bias) on
   diagrams/paper/engine_plant.yaml (the motor alone, stage 1) and diagrams/paper/plant.yaml (the two-mass
   drive, stage 2): 100 s at 1 kHz, Gaussian measurement noise of 0.01 rad/s on every speed.
2. Stage 1 (Table 1): J1 and the motor friction MR1 (3 tanh neurons) of diagrams/paper/engine.yaml from the
   idle record, from J1 = 0.6 and J1 = 0.01; single start, then with a multi-start (``--starts 4``).
3. Stage 2 (Table 2): J2, c, d and the load friction MR2 of diagrams/paper/two_mass.yaml from the speed w2,
   with J1 and MR1 fixed from the stage-1 result (``--fix-from``), from (J2, d, c) = (0.7, 0.4, 100) and
   (0.1, 0.7, 800); single start, then with a multi-start (``--starts 16``). Stage 2 continues from the
   offline stage-1 result with the lowest cost.
4. Both stages offline and quasi-online (``--online --window 25000 --average 25000``); stage 2 quasi-online
   also with ``--starts 16`` (16 whole quasi-online runs, the lowest final window cost reported).

Offline, stage 2 follows a staged recipe (docs/paper_experiment.md says why): (a) fit on the first 0.5 s (the
multi-start acts here), (b) on the first 3 s, (c) restart the learned curve from its initial weights and fit it
alone on the whole record with the physical parameters held (up to 4 starts with a multi-start), (d) fit
everything on the whole record. Stage 1 is one fit on the whole record (the multi-start draws there). Every
step is Levenberg-Marquardt as in ``sdnn identify`` (fit.lm, fit.multistart, identify.offline.problem), except that
the first damping is scaled to the problem as ``identify`` does it (mu0 = TAU * max diag(J^T J));
the final values go through :func:`flowchart2sdnn.identify.offline.run.identify` once more (no iteration) for the
result document. Quasi-online runs are plain ``identify(..., online=True)``.

Every learned friction curve is scored against the plant's true friction
``Fs sign(w) - (Fs - Fc) tanh(w/ws) + b w`` (sign smoothed as in the plant) by the RMS difference over a grid
of the speeds the record visits, leaving out the band ``|w| < BAND`` where the true curve jumps; the table
gives it in % of the largest true friction on that grid.

Run from the repository root: ``python examples/paper_experiment.py`` (``--help`` for the options).
"""

from __future__ import annotations

import os

# Small matrices (P ~ 10): threaded BLAS only adds contention on a shared machine (see flowchart2sdnn/cli/__init__.py).
# Set before numpy is first imported; a user's own setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import dataclass, field, replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from flowchart2sdnn.compiler import compile_diagram  # noqa: E402
from flowchart2sdnn.data.csvdata import Dataset, read_csv, write_csv  # noqa: E402
from flowchart2sdnn.diagram.dump import dump_diagram, with_values  # noqa: E402
from flowchart2sdnn.diagram.model import Diagram  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt  # noqa: E402
from flowchart2sdnn.fit.multistart import draw_starts, run_multistart  # noqa: E402
from flowchart2sdnn.identify.document import fix_from_result  # noqa: E402
from flowchart2sdnn.identify.offline.problem import Problem, build_problem, required_columns  # noqa: E402
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

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
    multistart: bool = False  # this step gets the run's --starts N ...
    max_starts: int | None = None  # ... but at most this many


#: Stage 2 offline: locate the shaft resonance on short horizons, then the friction on the whole record.
STAGED = (Step(0.5, multistart=True), Step(3.0),
          Step(None, curves_only=True, restart_curves=True, multistart=True, max_starts=4), Step(None))
#: Stage 1 offline: one plain fit on the whole record.
PLAIN = (Step(None, multistart=True),)
#: Initial LM damping mu0 = TAU * max diag(Ju^T Ju) at the start (Madsen, Nielsen & Tingleff 2004, section 3.2)
TAU = 1e-3


def _initial_curves(chart: Diagram, seed: int) -> dict[str, dict]:
    """The learned blocks' initial weights as the compiler draws them (or as stored in the chart)."""
    curves: dict[str, dict] = {}
    for fw in compile_diagram(chart, seed=seed).network.free_weights:
        if fw.block is not None and not fw.fixed:
            curves.setdefault(fw.block, {"a": [], "v": [], "b": []})[fw.role].append(fw.init)
    return {k: {"a": w["a"], "v": w["v"], **({"b": w["b"]} if w["b"] else {})} for k, w in curves.items()}


def lm_step(chart: Diagram, data: Dataset, starts: int = 1, seed: int = 0, max_iter: int = 60,
            tau: float = TAU):
    """LM (multi-start when `starts` > 1) on `data` from the chart's values; (problem, MultiStartResult).

    What ``sdnn identify`` does (the first damping scaled to the problem, see
    :attr:`flowchart2sdnn.fit.lm.LMOptions.tau`; each start with its own stability floor).
    """
    problem = build_problem(chart, data, "zoh", seed)
    names = problem.names
    lower, upper = problem.bounds()
    rows = draw_starts(names, problem.compiled.theta0(), lower, upper, starts, seed)
    options = LMOptions(max_iter=max_iter, tau=tau, min_rel_cost_change=1e-10)

    def fit_one(x0: np.ndarray):
        pb = problem.from_start(x0)
        return levenberg_marquardt(pb.fun, x0, names, lower, upper, options, guard=pb.guard, residual=pb.residual)

    return problem, run_multistart(fit_one, rows)


def _values(problem: Problem, x: np.ndarray) -> tuple[dict[str, float], dict[str, dict]]:
    params, free = problem.compiled.values(x)
    curves: dict[str, dict] = {}
    for fw in problem.network.free_weights:
        if fw.block is not None and not fw.fixed:
            curves.setdefault(fw.block, {"a": [], "v": [], "b": []})[fw.role].append(float(free[fw.name]))
    return dict(params), {k: {r: w[r] for r in ("a", "v", "b") if w[r]} for k, w in curves.items()}


def staged_identify(chart: Diagram, data: Dataset, steps: Sequence[Step], starts: int = 1, seed: int = 0,
                    max_iter: int = 60, tau: float = TAU, log: Callable[[str], None] = lambda s: None):
    """Run `steps` one after the other, each starting from the values the previous one found.

    Returns the :class:`~flowchart2sdnn.identify.offline.run.Identification` of the chart with the final values on
    the whole record (the result document of ``sdnn identify``; no further iteration) and the step log.
    """
    initial = _initial_curves(chart, seed)
    params = {p.name: p.init for p in chart.parameters}
    curves: dict[str, dict] = {}
    history = []
    for step in steps:
        if step.restart_curves:
            curves.update(initial)
        current = with_values(chart, params, curves)
        if step.curves_only:
            current = replace(current, parameters=tuple(replace(p, fixed=True) for p in current.parameters))
        n = data.n_rows if step.seconds is None else min(data.n_rows, round(step.seconds / chart.sample_time))
        t = time.perf_counter()
        n_starts = min(starts, step.max_starts or starts) if step.multistart else 1
        problem, ms = lm_step(current, data.slice(0, n), n_starts, seed, max_iter, tau)
        best = ms.best
        new_params, new_curves = _values(problem, best.x)
        params.update(new_params)
        curves.update(new_curves)
        entry = {"rows": n, "curves_only": step.curves_only, "restart_curves": step.restart_curves,
                 "starts": len(ms.results), "cost": best.cost, "status": best.status, "iterations": best.iterations,
                 "seconds": round(time.perf_counter() - t, 2),
                 "values": {k: v for k, v in new_params.items() if k in problem.names}}
        if len(ms.results) > 1:
            entry["multistart_costs"] = [float(c) for c in ms.costs]
        history.append(entry)
        log(f"    {n} rows{' curves only' if step.curves_only else ''}: cost {best.cost:.4g} after "
            f"{best.iterations} iterations ({entry['seconds']:.1f} s) "
            f"{', '.join(f'{k} {v:.4g}' for k, v in entry['values'].items())}")
    final = identify(with_values(chart, params, curves), data, None, IdentifySettings(max_iter=0, seed=seed))
    final.result["status"], final.result["message"] = history[-1]["status"], "staged offline fit (see 'staged')"
    return final, history


# ----------------------------------------------------------------------------------------------- runs
IDENTIFY, STAGED_MODE, ONLINE = "sdnn identify", "staged", "quasi-online"
MODES = (IDENTIFY, STAGED_MODE, ONLINE)
_TAG = {IDENTIFY: "cli", STAGED_MODE: "staged", ONLINE: "online"}


@dataclass
class Run:
    """One row of the results: where it started, what it found, how well, how long."""

    stage: int
    mode: str  # one of MODES
    start: int  # 1 or 2: the row of the paper's table it starts from
    init: dict
    starts: int = 1  # multi-start (offline)
    values: dict = field(default_factory=dict)
    cost: float | None = None
    curve_rms: float | None = None  # % of the largest true friction
    seconds: float = 0.0
    status: str = ""
    basin: str = ""  # multi-start: starts that reached (within 1.5x) the best cost, of all starts
    result_file: str = ""

    @property
    def label(self) -> str:
        more = f" --starts {self.starts}" if self.starts > 1 else ""
        return f"stage {self.stage}, start {self.start}: {self.mode}{more}"

    @property
    def name(self) -> str:
        """File stem of its RESULT.json, e.g. stage2_cli_start2_starts16."""
        more = f"_starts{self.starts}" if self.starts > 1 else ""
        return f"stage{self.stage}_{_TAG[self.mode]}_start{self.start}{more}"


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


def _basin(costs: Sequence[float | None]) -> str:
    finite = [c for c in costs if c is not None and np.isfinite(c)]
    best = min(finite)
    return f"{sum(c <= 1.5 * best for c in finite)}/{len(costs)}"


def run_fit(run: Run, chart: Diagram, data: Dataset, curve: str, truth: Callable, speeds: np.ndarray,
            steps: Sequence[Step], out_dir: Path, seed: int = 0, max_iter: int = 60, tau: float = TAU,
            log: Callable[[str], None] = print) -> Run:
    """Fit `chart` as `run.mode` says, score it against the truth, save RESULT.json and the identified chart.

    ``sdnn identify``: :func:`~flowchart2sdnn.identify.offline.run.identify` with the CLI's defaults (what the command
    line does); staged: :func:`staged_identify` with `steps`; quasi-online: ``identify --online`` with
    Q = K = 25 000.
    """
    log(run.label)
    t = time.perf_counter()
    history = None
    if run.mode == STAGED_MODE:
        outcome, history = staged_identify(chart, data, steps, run.starts, seed, max_iter, tau, log)
        costs = next((h["multistart_costs"] for h in history if "multistart_costs" in h), None)
        run.basin = _basin(costs) if costs else ""
    elif run.mode == IDENTIFY:
        outcome = identify(chart, data, None, IdentifySettings(starts=run.starts, seed=seed))
        if run.starts > 1:
            run.basin = _basin(outcome.result["multistart"]["costs"])
    else:
        q = min(25000, data.n_rows - 1)
        outcome = identify(chart, data, None, IdentifySettings(online=True, window=q, average=q, seed=seed,
                                                               starts=run.starts))
        if run.starts > 1:
            run.basin = _basin(outcome.result["multistart"]["costs"])
    run.seconds = time.perf_counter() - t
    r = outcome.result
    run.values = {k: v["value"] for k, v in r["parameters"].items()}
    run.status = r["status"]
    run.cost = r["online"]["mean_cost"] if run.mode == ONLINE else r["fit"]["train"]["cost"]
    rms, peak = curve_error(r["nonlinear"][curve], truth, speeds)
    run.curve_rms = 100.0 * rms / peak
    run.result_file = str(_save(out_dir, run.name, outcome, history))
    log(f"  -> {', '.join(f'{k} {v:.5g}' for k, v in run.values.items())}; cost {run.cost:.4g}; "
        f"{curve} error {run.curve_rms:.2f} % ({run.seconds:.1f} s, {run.status})")
    return run


#: (mode, multi-start) of the runs, per stage: stage 1 from both Table 1 starts, stage 2 from both Table 2 starts
PLAN = {
    1: ((IDENTIFY, False), (IDENTIFY, True), (STAGED_MODE, False), (ONLINE, False)),
    2: ((IDENTIFY, False), (IDENTIFY, True), (STAGED_MODE, False), (STAGED_MODE, True), (ONLINE, False),
        (ONLINE, True)),
}


def experiment(out_dir: Path, seconds: float = 100.0, starts: int = 16, engine_starts: int = 4, seed: int = 0,
               max_iter: int = 60, tau: float = TAU, modes: Sequence[str] = MODES,
               log: Callable[[str], None] = print, substeps: int | str | None = None,
               delays: str | None = None) -> list[Run]:
    """The whole experiment; returns the runs in table order and writes data and results under `out_dir`.

    The ``sdnn identify`` multi-start runs from the second Table 1 start and from both Table 2 starts, the
    staged one from both. Stage 2 of each mode continues from that mode's
    stage-1 result with the lowest cost (the paper's test of a run: its error), as ``--fix-from THAT.json``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    paths = make_data(out_dir, seconds)
    log(f"data: {paths['engine']} and {paths['plant']} ({seconds:g} s at 1 kHz, noise {NOISE} rad/s, "
        f"{time.perf_counter() - t:.1f} s)")
    plant = load_diagram(CHARTS / "plant.yaml")
    charts = {1: load_diagram(CHARTS / "engine.yaml"), 2: load_diagram(CHARTS / "two_mass.yaml")}
    if substeps is not None or delays is not None:  # the charts pin the paper's scheme; rows at another one
        charts = {k: dataclasses.replace(c, substeps=substeps if substeps is not None else c.substeps,
                                         delays=delays or c.delays) for k, c in charts.items()}
    data = {1: read_record(paths["engine"], charts[1]), 2: read_record(paths["plant"], charts[2])}
    starts_of = {1: [{"J1": j1} for j1 in TABLE1_STARTS], 2: [{"J2": j2, "d": d, "c": c} for j2, d, c in TABLE2_STARTS]}
    n_multi = {1: engine_starts, 2: starts}
    steps = {1: PLAIN, 2: STAGED}
    fit = {"out_dir": out_dir, "seed": seed, "max_iter": max_iter, "tau": tau, "log": log}
    runs: list[Run] = []
    for stage in (1, 2):
        chart, record = charts[stage], data[stage]
        speeds, friction = record.columns[f"w{stage}"], true_friction(plant, stage)
        for mode, multi in PLAN[stage]:
            if mode not in modes or (multi and n_multi[stage] <= 1):
                continue
            base = chart
            if stage == 2:  # --fix-from the best stage-1 result of the same mode
                best = min((r for r in runs if r.stage == 1 and r.mode == mode), key=lambda r: r.cost)
                log(f"stage 2, {mode}: --fix-from {best.result_file} (J1 {best.values['J1']:.5g})")
                base, _ = fix_from_result(chart, best.result_file)
            for k, init in enumerate(starts_of[stage]):
                run = Run(stage, mode, k + 1, init, starts=n_multi[stage] if multi else 1)
                if multi and mode == IDENTIFY and k == 0 and stage == 1:
                    continue  # stage 1 from J1 = 0.6 needs no multi-start
                runs.append(run_fit(run, with_values(base, init, {}), record, f"MR{stage}", friction, speeds,
                                    steps[stage], **fit))
    order = {m: i for i, m in enumerate(MODES)}
    return sorted(runs, key=lambda r: (r.stage, order[r.mode], r.starts > 1, r.start))


# ---------------------------------------------------------------------------------------------- table
def truth_values(plant: Diagram) -> dict[str, float]:
    return {p.name: p.init for p in plant.parameters if p.name in TRUTH_NAMES}


def acceptance(run: Run, truth: dict[str, float]) -> bool:
    """J1, J2, c within 2 %, d within 10 %, the friction curve within 5 % of its maximum."""
    limits = {"J1": 0.02, "J2": 0.02, "c": 0.02, "d": 0.10}
    names = ("J1",) if run.stage == 1 else ("J2", "c", "d")
    ok = all(abs(run.values[n] - truth[n]) <= limits[n] * abs(truth[n]) for n in names)
    return ok and run.curve_rms is not None and run.curve_rms <= 5.0


def _pct(value: float, true: float) -> str:
    return f"{value:.5g} ({100 * (value - true) / true:+.2f} %)"


def _how(r: Run) -> str:
    return f"ours, {r.mode}" + (f" --starts {r.starts}" if r.starts > 1 else "")


def tables(runs: Sequence[Run], truth: dict[str, float], rows: int, noise: float = NOISE) -> str:
    """The results as markdown tables (paper, truth, ours) with a note on E."""
    ok = {True: "yes", False: "**no**"}
    out = ["**Table 1** (stage 1: the motor in idle; J1 and the motor friction MR1)", "",
           "| run | J1 start | J1 [kg m²] | MR1 error [% of max] | E | time [s] | pass |",
           "|---|---|---|---|---|---|---|"]
    for (j1, e), s in zip(PAPER_T1, TABLE1_STARTS, strict=True):
        out.append(f"| paper (quasi-online) | {s:g} | {j1} | (Fig. 7) | {e:.4g} | | |")
    out.append(f"| truth (plant.yaml) | | {truth['J1']} | 0 | | | |")
    for r in (r for r in runs if r.stage == 1):
        out.append(f"| {_how(r)} | {r.init['J1']:g} | {_pct(r.values['J1'], truth['J1'])} | {r.curve_rms:.2f} "
                   f"| {r.cost:.4g} | {r.seconds:.0f} | {ok[acceptance(r, truth)]} |")
    out += ["", "**Table 2** (stage 2: the two-mass drive; J2, d, c and the load friction MR2; J1 and MR1 fixed "
            "from stage 1)", "",
            "| run | start (J2, d, c) | J2 [kg m²] | d [N m s/rad] | c [N m/rad] | MR2 error [% of max] | E "
            "| starts in the best basin | time [s] | pass |", "|---|---|---|---|---|---|---|---|---|---|"]
    for (j2, d, c, e), s in zip(PAPER_T2, TABLE2_STARTS, strict=True):
        out.append(f"| paper (quasi-online) | {s[0]:g}, {s[1]:g}, {s[2]:g} | {j2} | {d} | {c} | (Fig. 10) "
                   f"| {e:.4g} | | | |")
    out.append(f"| truth (plant.yaml) | | {truth['J2']} | {truth['d']} | {truth['c']} | 0 | | | | |")
    for r in (r for r in runs if r.stage == 2):
        out.append(f"| {_how(r)} | {r.init['J2']:g}, {r.init['d']:g}, {r.init['c']:g} | "
                   f"{_pct(r.values['J2'], truth['J2'])} | {_pct(r.values['d'], truth['d'])} | "
                   f"{_pct(r.values['c'], truth['c'])} | {r.curve_rms:.2f} | {r.cost:.4g} | {r.basin} "
                   f"| {r.seconds:.0f} | {ok[acceptance(r, truth)]} |")
    q = min(rows, 25000)
    out += ["", f"E: offline (sdnn identify, staged), 1/2 sum of the squared free-run errors over the whole record ({rows} samples; the "
            f"noise alone gives 1/2 Q σ² = {0.5 * rows * noise**2:.3g}); quasi-online (and the paper), the mean "
            f"window cost over the last {q} steps (noise alone: {0.5 * q * noise**2:.3g}). Friction error: RMS of "
            f"learned minus true friction over the speeds the record visits, |w| >= {BAND} rad/s, in % of the "
            "largest true friction there. Pass: J1, J2, c within 2 %, d within 10 %, friction error <= 5 %."]
    return "\n".join(out) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("paper_experiment_output"),
                    help="directory for the data, the results and the identified charts")
    ap.add_argument("--seconds", type=float, default=100.0, help="record length (paper: 100 s)")
    ap.add_argument("--starts", type=int, default=16, help="multi-start of stage 2")
    ap.add_argument("--engine-starts", type=int, default=4, help="multi-start of stage 1")
    ap.add_argument("--seed", type=int, default=0, help="seed of the initial curves and the multi-starts")
    ap.add_argument("--max-iter", type=int, default=60,
                    help="LM iterations per staged step (sdnn identify keeps its default, 100)")
    ap.add_argument("--tau", type=float, default=TAU, help="staged: initial LM damping mu0 = tau * max diag(J^T J)")
    ap.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES), metavar="MODE",
                    help=f"which runs: any of {', '.join(repr(m) for m in MODES)}")
    ap.add_argument("--substeps", type=lambda v: v if v == "auto" else int(v), default=None,
                    help="network steps per sample for both stages (default: the charts' 1, the paper's)")
    ap.add_argument("--delays", choices=("search", "torques", "midpoint"), default=None,
                    help="the delay rule for both stages (default: the charts' search, the paper's)")
    args = ap.parse_args(argv)
    t = time.perf_counter()
    runs = experiment(args.out, args.seconds, args.starts, args.engine_starts, args.seed, args.max_iter,
                      args.tau, args.modes, substeps=args.substeps, delays=args.delays)
    truth = truth_values(load_diagram(CHARTS / "plant.yaml"))
    text = tables(runs, truth, rows=round(args.seconds / 0.001) - 1)
    (args.out / "tables.md").write_text(text, encoding="utf-8")
    print()
    print(text)
    print(f"total {time.perf_counter() - t:.0f} s; data, results and identified charts in {args.out}/")
    # the acceptance of the experiment: every multi-start run passes
    return 0 if all(acceptance(r, truth) for r in runs if r.starts > 1) else 1


if __name__ == "__main__":
    sys.exit(main())

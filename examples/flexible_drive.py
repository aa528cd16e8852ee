"""Identify the real UWaterloo MTE 360 flexible drive (two carts and a spring) with flowchart2sdnn.

The data (16 open-loop records, voltage in, both cart speeds out, 1 kHz) are read in place from
``../shared/data/real/uwaterloo_mte360_flexible_drive`` (see its SOURCE.md); nothing is copied.

Protocol (benchmarks/notes/real_flexible_drive.md has the results):

* train on ``square_2V`` alone with :func:`flowchart2sdnn.identify.offline.run.identify` (exactly what
  ``sdnn identify CHART square_2V.csv --map u=u_V --map v1=v1_cart1_mm_s --map v2=v2_cart2_mm_s``
  does), and, as a second protocol, on ``square_2V`` + ``sine_4Hz`` together (a stacked fit, see
  :func:`fit_stacked`: the library trains on one record only);
* validate by free-run simulation from each record's start (the speed integrators use ``init: data``);
  fit % = 100 (1 - ||y - yhat|| / ||y - mean y||) per record and cart, scored only when the measured
  speed moves by at least 10 quanta (4.6592 mm/s each) peak to peak;
* report the two-mass mode of the identified linear part (eigenvalues of the continuous model) and the
  parameters next to the student estimates of SOURCE.md.

Run ``python examples/flexible_drive.py`` from the repository root (about a minute on one core);
``--quick`` runs only the owner's model on square_2V; ``--json FILE`` writes every number.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import Dataset, read_csv
from flowchart2sdnn.diagram.model import Diagram
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.uncertainty import covariance
from flowchart2sdnn.identify.offline.problem import Problem, build_problem, metrics, required_columns
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.network.stability import rest_eigenvalues
from flowchart2sdnn.tables import table

REPO = Path(__file__).resolve().parents[1]
DATA_DIR = REPO.parent / "shared" / "data" / "real" / "uwaterloo_mte360_flexible_drive"
CHARTS = {
    "coulomb": REPO / "diagrams" / "real" / "flexible_drive.yaml",
    "offset": REPO / "diagrams" / "real" / "flexible_drive_offset.yaml",
    "learned": REPO / "diagrams" / "real" / "flexible_drive_learned.yaml",
    "linear": REPO / "diagrams" / "real" / "flexible_drive_linear.yaml",
}
#: chart name -> CSV header (what `--map` does on the command line)
MAPPING = {"u": "u_V", "v1": "v1_cart1_mm_s", "v2": "v2_cart2_mm_s"}
OUTPUTS = ("v1", "v2")
QUANTUM = 4.6592  # mm/s, one encoder speed step
MIN_QUANTA = 10
TRAIN = ("square_2V",)
TRAIN_PLUS = ("square_2V", "sine_4Hz")
ACCEPTANCE_RECORD = "square_1p5V"
#: student estimates from SOURCE.md (volt-normalised units)
STUDENT = {"m1": 2.6634e-4, "m2": 1.4383e-4, "k": 0.0351, "b1": 0.0085, "b2": 8.4745e-4, "d1": 0.5934,
           "d2": 0.05934}
#: the lab's figures: pole of their damped linear model, and the damped frequency they measured
LAB_POLE_HZ = 2.76
LAB_DAMPED_HZ = 2.97
#: a network at rest with an eigenvalue beyond this modulus is unstable (chatter or divergence)
REST_LIMIT = 1.0 + 1e-9


# ------------------------------------------------------------------------------------------------ data
def record_order(name: str) -> tuple[int, float]:
    """Squares first, then the sines by frequency (``sine_2p5Hz`` -> 2.5)."""
    if name.startswith("sine_"):
        return 1, float(name[len("sine_"):-len("Hz")].replace("p", "."))
    return 0, float(name.split("_")[1].rstrip("V").replace("p", "."))


def load_records(diagram: Diagram, data_dir: Path = DATA_DIR,
                 names: Sequence[str] | None = None) -> dict[str, Dataset]:
    """Read the records a chart needs, in place, mapping chart names onto the CSV headers."""
    paths = sorted(Path(data_dir).glob("*.csv"), key=lambda p: record_order(p.stem))
    if names is not None:
        paths = [p for p in paths if p.stem in set(names)]
    cols = required_columns(diagram)
    return {p.stem: read_csv(p, cols, MAPPING, diagram.sample_time) for p in paths}


def quanta_moved(values: np.ndarray) -> float:
    """Peak-to-peak range of a measured speed in encoder quanta."""
    return float(np.ptp(values)) / QUANTUM


def is_scored(data: Dataset, output: str) -> bool:
    """A record/cart is scored when its measured speed moves by at least MIN_QUANTA quanta."""
    return quanta_moved(data.columns[output]) >= MIN_QUANTA - 1e-9


# ------------------------------------------------------------------------------------------------ fits
@dataclass
class Fit:
    """One identification: values, 95 % half-widths, fit metrics per record, and how it went."""

    label: str
    chart: str
    train: tuple[str, ...]
    compiled: CompiledNetwork
    x: np.ndarray
    values: dict[str, float]
    ci95: dict[str, float | None]
    nonlinear: dict[str, dict]
    cost: float
    status: str
    message: str
    seconds: float
    rest_radius: float
    warnings: list[str] = field(default_factory=list)
    fits: dict[str, dict[str, float | None]] = field(default_factory=dict)

    def evaluate(self, records: Mapping[str, Dataset]) -> None:
        """Free-run fit % on every record (the library's `metrics`, the number `sdnn identify` prints)."""
        for name, data in records.items():
            m = metrics(self.compiled, self.x, data, "zoh")
            self.fits[name] = {o: m["fit_percent"][o] for o in OUTPUTS}


def rest_radius(problem: Problem, x: np.ndarray) -> float:
    """Largest modulus of the network's eigenvalues at rest (> 1: chatters or diverges from rest)."""
    params, free = problem.compiled.values(x)
    return float(np.max(np.abs(rest_eigenvalues(problem.network, problem.network.weight_values(params, free)))))


def _curves(problem: Problem, x: np.ndarray) -> dict[str, dict]:
    _, free = problem.compiled.values(x)
    out: dict[str, dict] = {}
    for fw in problem.network.free_weights:
        if fw.block is not None and fw.role is not None:
            out.setdefault(fw.block, {"a": [], "v": [], "b": []})[fw.role].append(float(free[fw.name]))
    return out


def fit_single(diagram: Diagram, records: Mapping[str, Dataset], train: str, label: str,
               max_iter: int = 100) -> Fit:
    """Identify on one record with the library's `identify` (what `sdnn identify` runs)."""
    t0 = time.perf_counter()
    ident = identify(diagram, records[train], None, IdentifySettings(max_iter=max_iter, seed=0))
    seconds = time.perf_counter() - t0
    r = ident.result
    values = {n: p["value"] for n, p in r["parameters"].items()}
    ci = {n: (None if p["ci95"] is None else 0.5 * (p["ci95"][1] - p["ci95"][0]))
          for n, p in r["parameters"].items()}
    fit = Fit(label, diagram.name, (train,), ident.problem.compiled, np.asarray(ident.x), values, ci,
              _curves(ident.problem, ident.x), r["fit"]["train"]["cost"], r["status"], r["message"], seconds,
              rest_radius(ident.problem, ident.x), list(r["warnings"]))
    if fit.rest_radius > REST_LIMIT:
        fit.warnings.append(f"the identified network is unstable at rest (eigenvalue modulus {fit.rest_radius:.3g})")
    return fit


def fit_stacked(diagram: Diagram, records: Mapping[str, Dataset], train: Sequence[str], label: str,
                max_iter: int = 100) -> Fit:
    """Identify on several records at once: one network, the residuals of all records stacked.

    Each record runs from its own measured initial speeds. This uses the library's pieces (build_problem,
    levenberg_marquardt, covariance) because `identify` takes one training record. The guard refuses any
    network unstable at rest, not only a chattering one: the library's guard (identify.offline.problem.guard, via
    network.stability.chatter_radius) ignores real eigenvalues > 1, i.e. a learned friction curve with a
    negative slope at zero, on which the RTRL Jacobian explodes (see benchmarks/notes/real_flexible_drive.md).
    """
    t0 = time.perf_counter()
    network = compile_diagram(diagram, seed=0).network
    problems = [build_problem(diagram, records[n], "zoh", 0, network=network) for n in train]
    first = problems[0]

    def fun(x):
        parts = [p.fun(x) for p in problems]
        if any(q is None for q in parts):
            return None
        return np.concatenate([q[0] for q in parts]), np.vstack([q[1] for q in parts])

    def residual(x):
        parts = [p.residual(x) for p in problems]
        return None if any(q is None for q in parts) else np.concatenate(parts)

    def guard(x):
        radius = rest_radius(first, x)
        return None if radius <= REST_LIMIT else f"the network is unstable at rest (eigenvalue modulus {radius:.3g})"

    names = first.names
    lower, upper = first.bounds()
    lm = levenberg_marquardt(fun, first.compiled.theta0(), names, lower, upper, LMOptions(max_iter=max_iter),
                             guard=guard, residual=residual)
    cov = covariance(lm.jac, lm.residual, names=names)
    seconds = time.perf_counter() - t0
    x = np.asarray(lm.x)
    pvals, _ = first.compiled.values(x)
    index = {n: i for i, n in enumerate(names)}
    ci = {n: (float(cov.ci95[index[n]]) if cov.available and n in index and np.isfinite(cov.ci95[index[n]])
              else None) for n in pvals}
    warnings = [cov.warning] if cov.warning else []
    return Fit(label, diagram.name, tuple(train), first.compiled, x, dict(pvals), ci, _curves(first, x), lm.cost,
               lm.status, lm.message, seconds, rest_radius(first, x), warnings)


# ------------------------------------------------------------------------------------------------ physics
def resonance(m1: float, m2: float, k: float, b1: float, b2: float) -> dict[str, float]:
    """The two-mass mode of the linear part (Coulomb friction left out).

    State (v1, v2, x1 - x2): m1 v1' = -b1 v1 - k dx, m2 v2' = k dx - b2 v2, dx' = v1 - v2. Returns the
    complex pair's natural frequency |lambda| / 2 pi (what the lab calls the pole, 2.76 Hz), its damped
    frequency Im(lambda) / 2 pi, damping ratio, the real (rigid-body) pole, the undamped two-mass frequency
    sqrt(k (m1 + m2) / (m1 m2)) / 2 pi and the anti-resonance of cart 1, sqrt(k / m2) / 2 pi.
    """
    a = np.array([[-b1 / m1, 0.0, -k / m1], [0.0, -b2 / m2, k / m2], [1.0, -1.0, 0.0]])
    eig = np.linalg.eigvals(a)
    pair = eig[np.argmax(np.abs(eig.imag))]
    real = eig[np.argmin(np.abs(eig.imag))].real
    wn = abs(pair)
    return {"f_natural_hz": wn / (2 * math.pi), "f_damped_hz": abs(pair.imag) / (2 * math.pi),
            "zeta": -pair.real / wn, "rigid_pole_per_s": float(real),
            "f_undamped_hz": math.sqrt(k * (m1 + m2) / (m1 * m2)) / (2 * math.pi),
            "f_antiresonance_hz": math.sqrt(k / m2) / (2 * math.pi)}


def friction_curve(fit: Fit, cart: int, speeds: Sequence[float]) -> list[float]:
    """Total friction force (V) of a cart at the given speeds: viscous + Coulomb or learned part."""
    v = np.asarray(speeds, dtype=float)
    total = fit.values.get(f"b{cart}", 0.0) * v
    curve = fit.nonlinear.get(f"R{cart}")
    if curve is not None:
        b = curve["b"] or [0.0] * len(curve["a"])
        total = total + sum(vi * np.tanh(ai * v + bi) for ai, vi, bi in zip(curve["a"], curve["v"], b, strict=True))
    elif f"d{cart}" in fit.values:
        total = total + fit.values[f"d{cart}"] * np.tanh(v / 2.0)  # the chart's sign_smooth, eps = 2 mm/s
    return [float(f) for f in total]


# ------------------------------------------------------------------------------------------------ report
def _pct(value: float | None, scored: bool) -> str:
    if value is None:
        return "n/a"
    return f"{value:.1f}" if scored else f"({value:.0f})"


def fit_table(fits: Sequence[Fit], records: Mapping[str, Dataset]) -> str:
    """Fit % per record and cart for each fit; unscored records in brackets, training records marked *."""
    headers = ["record", "moves v1/v2 [quanta]"] + [f"{f.label} {o}" for f in fits for o in OUTPUTS]
    rows = []
    for name, data in records.items():
        moves = f"{quanta_moved(data.columns['v1']):.0f}/{quanta_moved(data.columns['v2']):.0f}"
        row = [name, moves]
        for f in fits:
            mark = "*" if name in f.train else ""
            for o in OUTPUTS:
                row.append(_pct(f.fits[name][o], is_scored(data, o)) + mark)
        rows.append(row)
    return table(headers, rows)


def validation_summary(fit: Fit, records: Mapping[str, Dataset]) -> dict[str, float]:
    """Mean fit % over the scored validation records (training records left out), per cart."""
    out = {}
    for o in OUTPUTS:
        vals = [fit.fits[n][o] for n, d in records.items()
                if n not in fit.train and is_scored(d, o) and fit.fits[n][o] is not None]
        out[o] = float(np.mean(vals)) if vals else float("nan")
    return out


def parameter_table(fits: Sequence[Fit]) -> str:
    names = list(dict.fromkeys(n for f in fits for n in f.values))
    headers = ["parameter", "student"] + [f.label for f in fits]
    rows = []
    for n in names:
        row = [n, f"{STUDENT[n]:.4g}" if n in STUDENT else ""]
        for f in fits:
            if n not in f.values:
                row.append("")
                continue
            ci = f.ci95.get(n)
            row.append(f"{f.values[n]:.4g}" + (f" ± {ci:.2g}" if ci is not None else ""))
        rows.append(row)
    return table(headers, rows)


def resonance_table(fits: Sequence[Fit]) -> str:
    rows = []
    student = resonance(*(STUDENT[n] for n in ("m1", "m2", "k", "b1", "b2")))
    for label, r in [("student parameters", student)] + [
            (f.label, resonance(*(f.values[n] for n in ("m1", "m2", "k", "b1", "b2")))) for f in fits]:
        rows.append([label, f"{r['f_natural_hz']:.3f}", f"{r['f_damped_hz']:.3f}", f"{r['zeta']:.3f}",
                     f"{r['f_undamped_hz']:.3f}", f"{r['f_antiresonance_hz']:.3f}"])
    return table(["model", "|pole| Hz", "damped Hz", "zeta", "undamped Hz", "anti-res. Hz"], rows)


def run(data_dir: Path = DATA_DIR, quick: bool = False, max_iter: int = 100,
        log: Callable[[str], None] = print) -> dict:
    """Every fit of the protocol; returns a JSON-able summary (and logs the tables through `log`)."""
    t_start = time.perf_counter()
    diagrams = {key: load_diagram(path) for key, path in CHARTS.items()}
    records = load_records(diagrams["coulomb"], data_dir)
    fits: list[Fit] = []
    plan = [("coulomb", False)] if quick else [
        ("coulomb", False), ("offset", False), ("learned", False), ("linear", False),
        ("coulomb", True), ("offset", True), ("learned", True)]
    for key, stacked in plan:
        label = key + ("+sine" if stacked else "")
        if stacked:
            fit = fit_stacked(diagrams[key], records, TRAIN_PLUS, label, max_iter)
        else:
            fit = fit_single(diagrams[key], records, TRAIN[0], label, max_iter)
        fit.evaluate(records)
        fits.append(fit)
        acc = fit.fits[ACCEPTANCE_RECORD]
        log(f"{label:14s} trained on {'+'.join(fit.train)} in {fit.seconds:5.1f} s, {fit.status}; "
            f"{ACCEPTANCE_RECORD}: v1 {acc['v1']:.1f} %, v2 {acc['v2']:.1f} %")
        for w in fit.warnings:
            log(f"  warning: {w}")
    excluded = [f"{n} {o}" for n, d in records.items() for o in OUTPUTS if not is_scored(d, o)]
    log("\nfit % per record (free run from the record's start; * = training record; "
        f"(bracketed) = not scored, the speed moves < {MIN_QUANTA} quanta)")
    log(fit_table(fits, records))
    log("mean fit % over the scored validation records:")
    log(table(["fit", "v1", "v2"], [[f.label, *(f"{v:.1f}" for v in validation_summary(f, records).values())]
                                    for f in fits]))
    log("parameters (± 95 % half-width from the Jacobian; far too narrow, see the docs):")
    log(parameter_table(fits))
    log(f"two-mass mode of the linear part (lab: pole {LAB_POLE_HZ} Hz, measured damped {LAB_DAMPED_HZ} Hz):")
    log(resonance_table(fits))
    seconds = time.perf_counter() - t_start
    log(f"total run time {seconds:.1f} s")
    return {
        "excluded": excluded,
        "seconds": seconds,
        "fits": [{"label": f.label, "chart": f.chart, "train": list(f.train), "status": f.status,
                  "message": f.message, "seconds": f.seconds, "cost": f.cost, "values": f.values, "ci95": f.ci95,
                  "nonlinear": f.nonlinear, "rest_radius": f.rest_radius, "warnings": f.warnings,
                  "fit_percent": f.fits, "validation_mean": validation_summary(f, records),
                  "resonance": resonance(*(f.values[n] for n in ("m1", "m2", "k", "b1", "b2"))),
                  "friction_v1": friction_curve(f, 1, [1, 5, 20, 50, 100, 150]),
                  "friction_v2": friction_curve(f, 2, [1, 5, 20, 50, 100, 150])} for f in fits],
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATA_DIR, help="folder with the 16 CSV records")
    parser.add_argument("--quick", action="store_true", help="only the owner's model trained on square_2V")
    parser.add_argument("--max-iter", type=int, default=100)
    parser.add_argument("--json", type=Path, help="write every number to this file")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"no data folder {args.data} (the records live in ../shared, beside the repository)", file=sys.stderr)
        return 2
    summary = run(args.data, args.quick, args.max_iter)
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Second-order read-outs and stages against sub-steps: the discretization floor per unit of compute (issue 13).

Plants: diagrams/two_mass_coulomb_plant.yaml and diagrams/three_mass_plant.yaml with their TRUE parameters,
T = 1 ms, the project's excitation (`sdnn excite`: APRBS + relay, noise-free, 20 s, seed 1) and the
continuous RK4 oracle (20 steps per sample) as truth. Every number is the RMS error in rad/s over rows 1..Q-1.

1. Baseline: the compiled network (`delays: torques`) at N = 1, 2, 4, 8 sub-steps; its cost in network steps
   per sample and in measured ms of the numba kernels (one simulation, one RTRL Jacobian over all parameters).
2. A plain numpy symplectic Euler of the same physics (written from the plant's equations, not from the
   network) reproduces the network at every N: the read-outs and stages below are compared on equal terms.
3. Read-outs on the compiled network at N = 1, 2, 4: linear combinations of neurons at a sample's last step
   (with g = h/J the integrator's weight and MB its speed sum): the mean of two consecutive steps,
   (w[k-1] + w[k])/2 = w - g/2*MB[k]  ("v - h/2*a"); v + h/2*a with a from the current state and the held
   input, = (w[k] + w[k+1])/2 had the input been held one step more; the same with the next sample's input;
   and v + h/2*(speed-dependent torques only)/J, which removes exactly their half-step lag.
4. Stages: the speed-dependent torques (friction, viscous, shaft damping) extrapolated to the step's midpoint,
   1.5*tau(k) - 0.5*tau(k-1), as a rewrite of the compiled network (flowchart2sdnn.network.midstep; a GDNN
   with delay-2 edges, RTRL exact) and checked against a numpy recursion; the same extrapolation of the speed
   before the nonlinearity (numpy); Heun's RK2 of the whole ODE (numpy, two force evaluations per step).
5. Angles: the shaft twists (not outputs of these charts) run half a step ahead of the speeds; their read-out
   mean(phi[k-1], phi[k]) = phi - h/2*dw.
6. Friction: the Coulomb torque Fc*tanh(20 w) evaluated on each model's speeds against the truth's.
7. Stability of the extrapolation for a friction slope s on inertia J (roots of the linear recursion).
8. Bias: noise-free refits started at the truth (every parameter free): how far the floor moves them.
9. (`--coverage S`) With 0.01 rad/s noise over seeds 1..S, fits from the truth: how often each parameter's 95 %
   interval covers the truth, for auto sub-steps and the midpoint speed torques at N = 1, 2.

Run from the repository root: `python benchmarks/bench_readout.py [--seconds 20] [--no-refit] [--coverage S]` (3-4 minutes;
`--coverage 10` adds about 3).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.compiler import compile_diagram  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt  # noqa: E402
from flowchart2sdnn.fit.uncertainty import covariance  # noqa: E402
from flowchart2sdnn.network.alignment import network_inputs  # noqa: E402
from flowchart2sdnn.network.midstep import extrapolate_speed_torques, speed_structure  # noqa: E402
from flowchart2sdnn.network.runtime import CompiledNetwork  # noqa: E402
from flowchart2sdnn.simulate.continuous import simulate_continuous  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

PLANTS = ("two_mass_coulomb_plant", "three_mass_plant")
TANH_SLOPE = 20.0  # the plants' Coulomb law: Fc * tanh(20 w)


# ---------------------------------------------------------------------------------------------- numpy physics
@dataclasses.dataclass(frozen=True)
class Chain:
    """Inertias J on shafts (c, d) in a row, friction Fc*tanh(20 w) + b*w on each, the input torque on mass 1."""

    J: np.ndarray
    c: np.ndarray
    d: np.ndarray
    Fc: np.ndarray
    b: np.ndarray

    @classmethod
    def of(cls, diagram) -> Chain:
        p = {q.name: q.init for q in diagram.parameters}
        n = sum(1 for k in p if k.startswith("J"))
        shaft = ("c", "d") if n == 2 else None
        get = (lambda s, i: p[s]) if shaft else (lambda s, i: p[f"{s}{i}"])
        return cls(np.array([p[f"J{i}"] for i in range(1, n + 1)]),
                   np.array([get("c", i) for i in range(1, n)]), np.array([get("d", i) for i in range(1, n)]),
                   np.array([p[f"Fc{i}"] for i in range(1, n + 1)]), np.array([p[f"b{i}"] for i in range(1, n + 1)]))

    def friction(self, w):
        return self.Fc * np.tanh(TANH_SLOPE * w) + self.b * w

    def spread(self, shaft):
        """Shaft torques (n-1) into the masses' sums (n): minus on the left mass, plus on the right."""
        out = np.zeros(len(self.J))
        out[:-1] -= shaft
        out[1:] += shaft
        return out

    def speed_torque(self, w):
        """The speed-dependent part of Newton's sums: friction, viscous, shaft damping."""
        return -self.friction(w) + self.spread(self.d * (w[:-1] - w[1:]))

    def spring_torque(self, phi):
        return self.spread(self.c * phi)


def numpy_run(ch: Chain, p: np.ndarray, T: float, N: int, scheme: str) -> tuple[np.ndarray, np.ndarray]:
    """Speeds and twists at the samples' ends. p (Q,): the input of each interval (held over it).

    symplectic: speeds from the previous step's torques, twists from the new speeds (the network's scheme);
    ab2: the same with the speed-dependent torques 1.5*tau(k) - 0.5*tau(k-1);
    midspeed: the same with them evaluated at the extrapolated speed 1.5*w(k) - 0.5*w(k-1);
    heun: Heun's RK2 of the ODE.
    """
    n, h = len(ch.J), T / N
    w, phi, w_prev, tv_prev = np.zeros(n), np.zeros(n - 1), np.zeros(n), np.zeros(n)
    e1 = np.eye(n)[0]

    def f(w_, phi_, uq):
        return (e1 * uq + ch.speed_torque(w_) + ch.spring_torque(phi_)) / ch.J, w_[:-1] - w_[1:]

    W, P = np.empty((len(p), n)), np.empty((len(p), n - 1))
    for q, uq in enumerate(p):
        for _ in range(N):
            if scheme == "heun":
                a1, v1 = f(w, phi, uq)
                a2, v2 = f(w + h * a1, phi + h * v1, uq)
                w, phi = w + h / 2 * (a1 + a2), phi + h / 2 * (v1 + v2)
                continue
            if scheme == "symplectic":
                tv = ch.speed_torque(w)
            elif scheme == "ab2":
                now = ch.speed_torque(w)
                tv, tv_prev = 1.5 * now - 0.5 * tv_prev, now
            elif scheme == "midspeed":
                tv = ch.speed_torque(1.5 * w - 0.5 * w_prev)
            else:
                raise ValueError(scheme)
            w_prev, w = w, w + h * (e1 * uq + tv + ch.spring_torque(phi)) / ch.J
            phi = phi + h * (w[:-1] - w[1:])
        W[q], P[q] = w, phi
    return W, P


# ---------------------------------------------------------------------------------------------- helpers
def rms(a, b) -> np.ndarray:
    return np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2, axis=0))


def cells(r) -> str:
    return " / ".join(f"{x:.5f}" for x in r)


def best_ms(fn, repeats: int) -> float:
    """Best CPU time of `repeats` calls (the machine is shared: CPU time is the fairer number)."""
    fn()  # compile the kernels outside the timing
    out = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        out.append(time.process_time() - t0)
    return min(out) * 1e3


@dataclasses.dataclass
class Bench:
    name: str
    diagram: object
    chain: Chain
    p: np.ndarray  # network inputs (Q-1, 1)
    truth: dict   # oracle signals at rows 1..Q-1
    outputs: tuple

    def network(self, n: int, stage: bool = False):
        net = compile_diagram(dataclasses.replace(self.diagram, delays="torques", substeps=n)).network
        return extrapolate_speed_torques(net) if stage else net

    def y(self) -> np.ndarray:
        return np.column_stack([self.truth[o] for o in self.outputs])


def load(name: str, seconds: float) -> Bench:
    d = load_diagram(ROOT / "diagrams" / f"{name}.yaml")
    data = excite(d, ExcitationSettings(seconds=seconds, seed=1, noise_std=0.0))
    u = np.column_stack([data[n] for n in d.input_names])
    sig = simulate_continuous(d, u, substeps=20, signals=True)  # the same run, every signal (twists too)
    assert np.allclose(np.column_stack([sig[o] for o in d.output_names]),
                       np.column_stack([data[o] for o in d.output_names]), atol=1e-12)
    return Bench(name, d, Chain.of(d), network_inputs(u), {k: v[1:] for k, v in sig.items()}, d.output_names)


# ---------------------------------------------------------------------------------------------- tables
def timing(net, p, repeats=5) -> tuple[float, float]:
    c = CompiledNetwork(net)
    th = c.theta0()
    return best_ms(lambda: c.simulate(th, p), repeats), best_ms(lambda: c.jacobian(th, p), repeats)


def baseline_and_stage(benches, sizes=(1, 2, 4, 8)) -> dict:
    print("## 1 + 4a. network, `delays: torques`, sub-steps vs the midpoint-extrapolated speed torques "
          "(network.midstep), RMS rad/s per output\n")
    print("| chart | scheme | N | steps / sample | RMS per output | max | simulate CPU ms | RTRL Jacobian CPU ms |")
    print("|---|---|---|---|---|---|---|---|")
    found = {}
    for b in benches:
        for stage in (False, True):
            for n in sizes:
                net = b.network(n, stage)
                c = CompiledNetwork(net)
                r = rms(c.simulate(c.theta0(), b.p), b.y())
                sim_ms, jac_ms = timing(net, b.p)
                found[(b.name, stage, n)] = r
                label = "AB2 speed torques" if stage else "sub-steps (baseline)"
                print(f"| {b.name} | {label} | {n} | {n} | {cells(r)} | {r.max():.5f} | {sim_ms:.1f} | "
                      f"{jac_ms:.0f} |")
    return found


def search_rule(benches, sizes=(1, 2)) -> None:
    print("\n## 4c. the rewrite on the search rule's network (`delays: search`: only Newton's sums that see every "
          "integrator through a delay are speed sums)\n")
    print("| chart | N | search | search + rewrite | extrapolated edges |")
    print("|---|---|---|---|---|")
    for b in benches:
        for n in sizes:
            net = compile_diagram(dataclasses.replace(b.diagram, delays="search", substeps=n)).network
            r = [rms(CompiledNetwork(x).simulate(CompiledNetwork(x).theta0(), b.p), b.y())
                 for x in (net, extrapolate_speed_torques(net))]
            edges = ", ".join(net.weights[j].origin for j in speed_structure(net).extrapolated)
            print(f"| {b.name} | {n} | {cells(r[0])} | {cells(r[1])} | {edges} |")


def reproduction(benches, sizes=(1, 2, 4, 8)) -> None:
    print("\n## 2. numpy symplectic Euler of the same physics vs the compiled network\n")
    print("| chart | N | numpy RMS per output | network RMS per output | max abs difference | AB2: numpy vs "
          "rewritten network |")
    print("|---|---|---|---|---|---|")
    for b in benches:
        for n in sizes:
            c = CompiledNetwork(b.network(n))
            yn = c.simulate(c.theta0(), b.p)
            w, _ = numpy_run(b.chain, b.p[:, 0], b.diagram.sample_time, n, "symplectic")
            ab2 = ""
            if n <= 2:
                c2 = CompiledNetwork(b.network(n, stage=True))
                w2, _ = numpy_run(b.chain, b.p[:, 0], b.diagram.sample_time, n, "ab2")
                ab2 = f"{np.abs(w2 - c2.simulate(c2.theta0(), b.p)).max():.1e}"
            print(f"| {b.name} | {n} | {cells(rms(w, b.y()))} | {cells(rms(yn, b.y()))} | "
                  f"{np.abs(w - yn).max():.1e} | {ab2} |")


def speed_readouts(net, sig: dict, p: np.ndarray) -> dict[str, np.ndarray]:
    """Read-outs of every speed output from the neurons at the sample's last step (see the docstring)."""
    values = net.weight_values()
    st = speed_structure(net)
    name = {(m, r): (la.name if la.size == 1 else f"{la.name}[{r}]")
            for m, la in enumerate(net.layers) for r in range(la.size)}
    p_next = np.vstack([p[1:], p[-1:]])
    cols: dict[str, list] = {}
    for o in net.outputs:
        key = (o.layer, o.neuron)
        if key not in st.speed_integrators:
            raise ValueError(f"output {o.name} is not a speed integrator")
        (j, feed), = [(j, w) for j, w in enumerate(net.weights) if w.matrix == "LW" and w.delay == 0
                      and (w.layer, w.row) == key and (w.source, w.col) in st.speed_sums]
        g, s = values[j], (feed.source, feed.col)
        into = [(values[i], w) for i, w in enumerate(net.weights) if (w.layer, w.row) == s]
        spring = sum(v * sig[name[(w.source, w.col)]] for v, w in into
                     if w.matrix == "LW" and w.delay == 1 and (w.source, w.col) in st.position_dependent)
        speed = sum(v * sig[name[(w.source, w.col)]] for v, w in into
                    if w.matrix == "LW" and w.delay == 1 and (w.source, w.col) not in st.position_dependent)
        held = sum(v * p[:, w.source] for v, w in into if w.matrix == "IW" and w.delay == 0)
        nxt = sum(v * p_next[:, w.source] for v, w in into if w.matrix == "IW" and w.delay == 0)
        w_now, mb = sig[name[key]], sig[name[s]]
        for label, r in (("raw", w_now),
                         ("mean(w[k-1], w[k]) = v - h/2*a", w_now - g / 2 * mb),
                         ("v + h/2*a, held input", w_now + g / 2 * (spring + speed + held)),
                         ("mean(w[k], w[k+1]), next input", w_now + g / 2 * (spring + speed + nxt)),
                         ("v + h/2*(speed torques)/J", w_now + g / 2 * speed)):
            cols.setdefault(label, []).append(r)
    return {k: np.column_stack(v) for k, v in cols.items()}


def readout_table(benches, sizes=(1, 2, 4)) -> dict:
    print("\n## 3. read-outs of the baseline network (linear in the neurons at a sample's last step; cost: N "
          "steps + a few flops per output and sample)\n")
    print("| chart | read-out | " + " | ".join(f"N = {n}" for n in sizes) + " |")
    print("|---|---|" + "---|" * len(sizes))
    found = {}
    for b in benches:
        rows: dict[str, list] = {}
        for n in sizes:
            net = b.network(n)
            c = CompiledNetwork(net)
            for label, r in speed_readouts(net, c.signals(c.theta0(), b.p), b.p).items():
                rows.setdefault(label, []).append(rms(r, b.y()))
                found[(b.name, label, n)] = rms(r, b.y())
        for label, rs in rows.items():
            print(f"| {b.name} | {label} | " + " | ".join(cells(r) for r in rs) + " |")
    return found


def numpy_stages(benches, sizes=(1, 2, 4)) -> None:
    print("\n## 4b. other stages in numpy (force evaluations per sample = N x evaluations per step)\n")
    print("| chart | scheme | evaluations / step | " + " | ".join(f"N = {n}" for n in sizes) + " |")
    print("|---|---|---|" + "---|" * len(sizes))
    for b in benches:
        for scheme, per_step in (("midspeed", 1), ("heun", 2)):
            rs = [rms(numpy_run(b.chain, b.p[:, 0], b.diagram.sample_time, n, scheme)[0], b.y()) for n in sizes]
            print(f"| {b.name} | {scheme} | {per_step} | " + " | ".join(cells(r) for r in rs) + " |")


def twist_table(benches, sizes=(1, 2, 4)) -> None:
    print("\n## 5. shaft twists [rad] (internal; a chart could output them): raw vs mean(phi[k-1], phi[k])\n")
    print("| chart | network | twist RMS (signal) | " + " | ".join(f"N = {n} raw / read-out" for n in sizes) + " |")
    print("|---|---|---|" + "---|" * len(sizes))
    for b in benches:
        twists = [k for k in b.truth if k.startswith("dphi")]
        for stage in (False, True):
            cols = []
            for n in sizes:
                net = b.network(n, stage)
                c = CompiledNetwork(net)
                sig = c.signals(c.theta0(), b.p)
                h = net.step
                raw = np.column_stack([sig[t] for t in twists])
                read = np.column_stack([sig[t] - h / 2 * sig["dw" + t[len("dphi"):]] for t in twists])
                y = np.column_stack([b.truth[t] for t in twists])
                cols.append(f"{' / '.join(f'{x:.1e}' for x in rms(raw, y))} → "
                            f"{' / '.join(f'{x:.1e}' for x in rms(read, y))}")
            size = " / ".join(f"{np.sqrt(np.mean(b.truth[t] ** 2)):.3f}" for t in twists)
            label = "AB2 speed torques" if stage else "baseline"
            print(f"| {b.name} | {label} | {size} | " + " | ".join(cols) + " |")


def friction_table(benches, base: dict, reads: dict, n: int = 1) -> None:
    print(f"\n## 6. Coulomb torque Fc*tanh(20 w) on the model's speeds vs on the truth's, N = {n}, RMS N*m\n")
    print("| chart | baseline raw | baseline, best read-out | AB2 speed torques | N = 4 baseline |")
    print("|---|---|---|---|---|")
    for b in benches:
        def coulomb(w, fc=b.chain.Fc):
            return fc * np.tanh(TANH_SLOPE * w)
        truth = coulomb(b.y())
        out = []
        for net in (b.network(n), None, b.network(n, stage=True), b.network(4)):
            if net is None:
                c = CompiledNetwork(b.network(n))
                w = speed_readouts(b.network(n), c.signals(c.theta0(), b.p), b.p)["mean(w[k-1], w[k]) = v - h/2*a"]
            else:
                c = CompiledNetwork(net)
                w = c.simulate(c.theta0(), b.p)
            out.append(" / ".join(f"{x:.4f}" for x in rms(coulomb(w), truth)))
        print(f"| {b.name} | " + " | ".join(out) + " |")


def cost_summary(benches, base: dict, targets=(0.003, 0.001)) -> None:
    print("\n## floor per unit of compute: fewest network steps per sample whose every output is within the target\n")
    print("| chart | target rad/s | sub-steps (baseline) | AB2 speed torques | compute saved |")
    print("|---|---|---|---|---|")
    for b in benches:
        for t in targets:
            found = []
            for stage in (False, True):
                ok = [n for (name, s, n), r in sorted(base.items()) if name == b.name and s == stage and r.max() <= t]
                found.append(min(ok) if ok else None)
            # first order: beyond the measured N the baseline's error falls as 1/N
            worst8 = base[(b.name, False, 8)].max()
            guess = int(np.ceil(8 * worst8 / t))
            text = [str(f) if f else f"> 8 (~{guess} by 1/N)" for f in found]
            steps = [f or guess for f in found]
            saved = f"{steps[0] / steps[1]:.0f}x" if found[1] else "—"
            print(f"| {b.name} | {t} | {text[0]} | {text[1]} | {saved} |")


def stability_line() -> None:
    """Friction slope s on inertia J, z = s*h/J: explicit Euler w+ = (1-z) w; AB2 w+ = w - z(1.5 w - 0.5 w-)."""
    z = np.linspace(0.01, 3, 300)
    euler = z[np.abs(1 - z) < 1].max()
    ab2 = z[[np.abs(np.roots([1, -(1 - 1.5 * zz), -0.5 * zz])).max() < 1 for zz in z]].max()
    print(f"\n## 7. stability for a friction slope s on inertia J, z = s*h/J: explicit Euler stable up to "
          f"z = {euler:.2f}, AB2 speed torques up to z = {ab2:.2f} (the chatter guard's 2*J/h becomes J/h)")


def fit_from(c: CompiledNetwork, p: np.ndarray, y: np.ndarray, iterations: int = 60):
    """LM (scale='jac', parameters >= 0) from the network's own theta0 on one record."""
    def fun(x):
        yhat, jac = c.jacobian(x, p)
        return (y - yhat).ravel(), jac.reshape(-1, jac.shape[-1])

    def residual(x):
        return (y - c.simulate(x, p)).ravel()

    x0 = c.theta0()
    return levenberg_marquardt(fun, x0, c.names, np.zeros_like(x0), None,
                               LMOptions(max_iter=iterations, scale="jac"), residual=residual)


def coverage_table(benches, seeds: int, seconds: float) -> None:
    """0.01 rad/s noise, seeds 1..S (excitation and noise), fits started at the truth: how often each 95 %
    interval (fit.uncertainty.covariance) covers the truth."""
    print(f"\n## 9. coverage: 0.01 rad/s noise, {seconds:g} s, seeds 1..{seeds}, fits from the truth; how often "
          "each 95 % interval covers the truth\n")
    print("| chart | network | N | covered / seeds per parameter | mean error % per parameter |")
    print("|---|---|---|---|---|")
    for b in benches:
        configs = [(False, "auto"), (True, 1), (True, 2)]
        hits = {k: 0 for k in configs}
        errs: dict = {k: [] for k in configs}
        nets = {k: b.network(k[1], k[0]) if k[1] != "auto" else
                compile_diagram(dataclasses.replace(b.diagram, delays="torques", substeps="auto")).network
                for k in configs}
        for seed in range(1, seeds + 1):
            data = excite(b.diagram, ExcitationSettings(seconds=seconds, seed=seed, noise_std=0.01))
            p = network_inputs(np.column_stack([data[n] for n in b.diagram.input_names]))
            y = np.column_stack([data[o] for o in b.outputs])[1:]
            for k in configs:
                c = CompiledNetwork(nets[k])
                res = fit_from(c, p, y)
                cov = covariance(res.jac, res.residual, names=c.names)
                truth = c.theta0()
                hits[k] = hits[k] + (np.abs(res.x - truth) <= cov.ci95)
                errs[k].append(100 * (res.x / truth - 1))
        for k in configs:
            c = CompiledNetwork(nets[k])
            label = "AB2 speed torques" if k[0] else "sub-steps (baseline)"
            n = nets[k].substeps
            cover = " ".join(f"{name} {int(h)}" for name, h in zip(c.names, hits[k], strict=True))
            mean = " ".join(f"{name} {e:+.3f}" for name, e in zip(c.names, np.mean(errs[k], axis=0), strict=True))
            print(f"| {b.name} | {label} | {n} | {cover} | {mean} |")


def refit_table(benches, iterations: int = 60) -> None:
    """Noise-free refits that START AT THE TRUTH: where the fit moves the parameters is the floor's bias."""
    print("\n## 8. bias: noise-free refits started at the true parameters (every parameter free, LM with "
          "scale='jac'); error of each parameter in %\n")
    print("| chart | network | N | residual RMS per output | parameter errors % | CPU s |")
    print("|---|---|---|---|---|---|")
    for b in benches:
        y = b.y()
        for stage, n in ((False, 1), (False, 8), (True, 1), (True, 2)):
            c = CompiledNetwork(b.network(n, stage))
            x0 = c.theta0()
            t0 = time.process_time()
            res = fit_from(c, b.p, y, iterations)
            cpu = time.process_time() - t0
            r = np.sqrt(np.mean(res.residual.reshape(y.shape) ** 2, axis=0))
            errs = " ".join(f"{name} {100 * (v / t - 1):+.2f}" for name, v, t in zip(c.names, res.x, x0, strict=True))
            label = "AB2 speed torques" if stage else "sub-steps (baseline)"
            print(f"| {b.name} | {label} | {n} | {cells(r)} | {errs} | {cpu:.0f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--no-refit", action="store_true", help="skip the refits of section 8")
    ap.add_argument("--coverage", type=int, default=0, metavar="S",
                    help="section 9: interval coverage over noise seeds 1..S (about 15 s a seed)")
    args = ap.parse_args()
    benches = [load(name, args.seconds) for name in PLANTS]
    print(f"# {args.seconds:g} s, seed 1, noise-free, T = 1 ms, truth: continuous RK4 (20 steps per sample)\n")
    base = baseline_and_stage(benches)
    reproduction(benches)
    reads = readout_table(benches)
    numpy_stages(benches)
    search_rule(benches)
    twist_table(benches)
    friction_table(benches, base, reads)
    cost_summary(benches, base)
    stability_line()
    if not args.no_refit:
        refit_table(benches)
    if args.coverage:
        coverage_table(benches, args.coverage, args.seconds)


if __name__ == "__main__":
    main()

"""Excitations and the virtual test bench run: the continuous oracle on the plant chart, then the sensors.

Three kinds, all sized by the plant's torque scale A and speed scale:

* ``aprbs``: the paper's APRBS (levels in +-A) plus the hysteresis relay on the measured motor speed
  (:class:`flowchart2sdnn.simulate.continuous.RelayFeedback`, level about A, switching at the speed scale),
  as `sdnn excite` does;
* ``multisine``: 20-60 sines log-spaced over ``[f_lo, f_hi]`` with random phases, scaled to peak A;
* ``closed-loop``: a digital PI speed controller with a torque limit written into the simulation chart:
  ``e_k = r_k - (w1(t_k) + n_k)``, integral clamped at the limit (anti-windup), command ``L sat((Kp e_k +
  I_k) / L)`` applied one sample later (the computation delay) and held; the command is the logged ``M1``.
  The reference r is an APRBS of speeds within the speed scale, n the measurement error of the logged speed.

Both loops (relay, PI) act on the speed as it is logged, noise included: the record is simulated again with
the logged measurement error until the two agree (``loop_mismatch``: the RMS of the difference between the
error the controller saw and the one logged, relative to the RMS of the logged one). White and AR noise agree
on the second run (a range limit may take more). An encoder's quantisation error is a chaotic function of the
trajectory: iterating does not converge (measured: the ratio stays at sqrt(2), independent realisations), so an
encoder record is simulated twice and its controller sees a quantisation error of the same size and spectrum
from the first run, not the logged one (``loop_mismatch`` about 1.4).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.simulate.continuous import RelayFeedback, simulate_continuous
from flowchart2sdnn.simulate.excitation import aprbs

from .plants import SUBSTEPS, Plant, chart_number, chart_text, copy_chart, log_uniform
from .sensors import Sensor

__all__ = ["EXCITATIONS", "Excitation", "draw_excitation", "simulation_chart", "excitation_inputs", "run_record"]

EXCITATIONS = ("aprbs", "multisine", "closed-loop")
PASSES = 4  # simulations at most per record when a loop reads the logged speed (2 with an encoder)


@dataclass(frozen=True)
class Excitation:
    kind: str
    amplitude: float  # A: APRBS level range, multisine peak, the PI's torque limit
    settings: dict = field(default_factory=dict)

    @property
    def input_peak(self) -> float:
        """The largest |command| the excitation asks for (what a saturation is sized against)."""
        return self.amplitude + self.settings.get("relay_level", 0.0)

    def as_dict(self) -> dict:
        return {"kind": self.kind, "amplitude": self.amplitude, **self.settings}


def draw_excitation(rng: np.random.Generator, plant: Plant, kind: str | None = None) -> Excitation:
    kind = kind or EXCITATIONS[int(rng.integers(0, len(EXCITATIONS)))]
    a, w = plant.torque, plant.speed
    if kind == "aprbs":
        # a relay level at least the APRBS's keeps the speed bounded (net torque against a run-away)
        return Excitation(kind, a, {"hold": (0.01, max(0.05, 2 * plant.t_acc)),
                                    "relay_level": a * float(rng.uniform(0.9, 1.2)), "relay_switch": w,
                                    "relay_band": 0.2 * w, "relay_band_scale": 0.2})
    if kind == "multisine":
        f_hi = min(log_uniform(rng, 5.0, 50.0), 0.2 / plant.sample_time)
        return Excitation(kind, a, {"f_lo": log_uniform(rng, 0.2, 2.0), "f_hi": f_hi,
                                    "lines": int(rng.integers(20, 61))})
    if kind == "closed-loop":
        # crossover below the lowest shaft resonance, so that the loop on the motor speed stays stable
        res = [math.sqrt(plant.parameters[f"c{j}"] * (1 / plant.parameters[f"J{j}"] + 1 / plant.parameters[f"J{j+1}"]))
               for j in range(1, plant.masses)]
        omega = min([log_uniform(rng, 5.0, 40.0)] + [0.2 * r for r in res])
        kp = plant.inertia * omega
        # against a spring to ground a speed held for longer than about a radian of the natural frequency
        # needs more torque than the limit: the reference changes faster there
        longest = 1.0 if plant.family != "spring" else min(1.0, 2 / math.sqrt(
            plant.parameters["k0"] / plant.parameters["J1"]))
        return Excitation(kind, a, {"kp": kp, "ki": kp * omega / 5, "reference": w,
                                    "hold": (min(0.05, longest / 2), longest)})
    raise ValueError(f"unknown excitation {kind!r}; one of {', '.join(EXCITATIONS)}")


def _multisine(q: int, T: float, rng: np.random.Generator, s: dict, amplitude: float) -> np.ndarray:
    freqs = np.geomspace(s["f_lo"], s["f_hi"], s["lines"])
    phases = rng.uniform(0, 2 * math.pi, len(freqs))
    t = np.arange(q) * T
    u = np.sin(2 * math.pi * freqs[None, :] * t[:, None] + phases[None, :]).sum(axis=1)
    return amplitude * u / np.max(np.abs(u))


def _controller_blocks(e: Excitation, T: float) -> dict[str, dict]:
    s, lim = e.settings, e.amplitude
    return {
        "ctl_e": {"type": "sum", "in": ["w_ref", "-w1", "-n_seen"]},
        "ctl_p": {"type": "gain", "in": "ctl_e", "k": chart_number(s["kp"])},
        "ctl_ki": {"type": "gain", "in": "ctl_e", "k": chart_number(s["ki"] * T)},
        "ctl_isum": {"type": "sum", "in": ["ctl_iprev", "ctl_ki"]},
        "ctl_isat": {"type": "function", "f": "sat", "in": "ctl_isum", "k": chart_number(1 / lim)},
        "ctl_i": {"type": "gain", "in": "ctl_isat", "k": chart_number(lim)},
        "ctl_iprev": {"type": "delay", "in": "ctl_i", "n": 1},
        "ctl_u": {"type": "sum", "in": ["ctl_p", "ctl_i"]},
        "ctl_usat": {"type": "function", "f": "sat", "in": "ctl_u", "k": chart_number(1 / lim)},
        "ctl_ulim": {"type": "gain", "in": "ctl_usat", "k": chart_number(lim)},
        "M1": {"type": "delay", "in": "ctl_ulim", "n": 1},
    }


def simulation_chart(plant_chart: dict, plant: Plant, excitation: Excitation, encoder: bool) -> dict:
    """The plant chart with what the bench adds: the PI loop (closed loop) and the angles an encoder reads."""
    chart = copy_chart(plant_chart)
    chart["name"] = plant_chart["name"] + "_bench"
    if encoder:
        for w in plant.speeds:
            if w in plant.outputs:
                chart["blocks"][f"enc_{w}"] = {"type": "integrator", "in": w}
    if excitation.kind == "closed-loop":
        chart["inputs"] = {"w_ref": {}, "n_seen": {}}
        chart["blocks"].update(_controller_blocks(excitation, plant.sample_time))
    return chart


def excitation_inputs(excitation: Excitation, plant: Plant, q: int, rng: np.random.Generator) -> np.ndarray:
    T, s = plant.sample_time, excitation.settings
    if excitation.kind == "aprbs":
        return aprbs(q, T, rng, (-excitation.amplitude, excitation.amplitude), s["hold"])[:, None]
    if excitation.kind == "multisine":
        return _multisine(q, T, rng, s, excitation.amplitude)[:, None]
    ref = aprbs(q, T, rng, (-s["reference"], s["reference"]), s["hold"])
    return np.column_stack([ref, np.zeros(q)])


def run_record(plant_chart: dict, plant: Plant, excitation: Excitation, sensor: Sensor, seconds: float,
               rng: np.random.Generator) -> tuple[dict[str, np.ndarray], dict]:
    """Simulate one record: (logged columns: time, M1, the outputs; facts: clean ranges, loop mismatch, passes)."""
    T = plant.sample_time
    q = int(round(seconds / T))
    chart = simulation_chart(plant_chart, plant, excitation, sensor.kind == "encoder")
    diagram = diagram_from_text(chart_text(chart), chart["name"])
    u = excitation_inputs(excitation, plant, q, rng)
    loop = excitation.kind != "multisine"
    seen = np.zeros(q)
    ranges = None
    passes, mismatch = 0, 0.0
    most = 2 if sensor.kind == "encoder" else PASSES
    for passes in range(1, most + 1):
        relay = None
        if excitation.kind == "aprbs":
            s = excitation.settings
            relay = RelayFeedback("M1", "w1", s["relay_level"], s["relay_switch"], s["relay_band"],
                                  s["relay_band_scale"], noise=seen)
        elif excitation.kind == "closed-loop":
            u[:, 1] = seen
        sig = simulate_continuous(diagram, u, substeps=SUBSTEPS, signals=True, controller=relay)
        if ranges is None:
            ranges = {y: (float(np.ptp(sig[y])), float(np.max(np.abs(sig[y])))) for y in plant.outputs}
        angles = {y: sig[y] if y.startswith("phi") else sig.get(f"enc_{y}") for y in plant.outputs}
        measured = sensor.measure(sig, plant.outputs, T, angles, ranges)
        logged_error = measured["w1"] - sig["w1"]
        scale = float(np.sqrt(np.mean(logged_error**2))) or 1.0
        mismatch = float(np.sqrt(np.mean((logged_error - seen) ** 2))) / scale
        if not loop or mismatch < 1e-9:
            break
        if passes < most:
            seen = logged_error
    columns = {"time": np.arange(q) * T, "M1": np.asarray(sig["M1"], dtype=float), **measured}
    facts = {"ranges": ranges, "passes": passes, "loop_mismatch": mismatch if loop else None,
             "input_max": float(np.max(np.abs(sig["M1"])))}
    return columns, facts

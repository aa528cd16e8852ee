"""The frequency response of a linearised chart over the one measured in data: the Bode figure.

The measured response is Welch's H1 with its coherence (:mod:`flowchart2sdnn.analysis.response`); it is drawn
faint, phase left out, where the coherence is below 0.5.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..analysis.linearize import LinearModel
from ..analysis.response import Empirical
from .canvas import new_figure, require_matplotlib, save_png

__all__ = ["bode_figure", "write_bode"]

#: below this coherence the measured response is drawn faint and its phase left out
_COHERENT = 0.5


def _unit_ratio(out: str | None, inp: str | None) -> str:
    if not out and not inp:
        return ""
    return f" in ({out or '1'})/({inp or '1'})"


def bode_figure(model: LinearModel, estimates: list[Empirical] = (), f_max: float | None = None):
    """Magnitude, phase (and coherence, with estimates) of every input -> output pair of `model`."""
    pairs = [(o, i) for o in model.outputs for i in model.inputs]
    rows = 3 if estimates else 2
    fig, axes = new_figure(rows, len(pairs), width=6.5 * len(pairs), height=2.4, sharex="col")
    modes = [d for d in model.damp() if d["f_hz"] > 0]
    top = max([d["f_hz"] for d in modes] + [1.0])
    lo = min(e.f[0] for e in estimates) if estimates else 0.1 * min([d["f_hz"] for d in modes] + [1.0])
    hi = f_max or min([10 * top] + [e.f[-1] for e in estimates])
    f = np.logspace(math.log10(lo), math.log10(hi), 600)
    h = model.frequency_response(f)
    for col, (out, inp) in enumerate(pairs):
        mag, phase = axes[0, col], axes[1, col]
        o, i = model.outputs.index(out), model.inputs.index(inp)
        model_phase = np.degrees(np.unwrap(np.angle(h[:, o, i])))
        est = next((e for e in estimates if e.output == out and e.input == inp), None)
        if est is not None:
            keep = est.f <= hi
            fe, he, ce = est.f[keep], est.h[keep], est.coherence[keep]
            good = ce >= _COHERENT
            with np.errstate(divide="ignore", invalid="ignore"):
                db = 20 * np.log10(np.abs(he))
                # the measured phase as the model's unwrapped phase plus the difference wrapped to +-180:
                # unwrapping a noisy estimate on its own wanders off by whole turns
                ref = np.interp(fe, f, model_phase)
                diff = np.degrees(np.angle(he * np.conj(np.interp(fe, f, h[:, o, i].real)
                                                        + 1j * np.interp(fe, f, h[:, o, i].imag))))
            mag.semilogx(fe, np.where(good, db, np.nan), color="0.35", lw=0.9,
                         label=f"measured (Welch H1, {est.nperseg}-sample segments)")
            mag.semilogx(fe, np.where(good, np.nan, db), color="0.75", lw=0.6,
                         label=f"measured, coherence < {_COHERENT:g}")
            phase.semilogx(fe, np.where(good, ref + diff, np.nan), color="0.35", lw=0.9)
            coh = axes[2, col]
            coh.semilogx(fe, ce, color="tab:green", lw=0.8)
            coh.axhline(_COHERENT, color="0.5", lw=0.6, ls="--")
            coh.set_ylim(0, 1.05)
            coh.set_ylabel("coherence")
            coh.grid(alpha=0.3, which="both")
            coh.set_xlabel("frequency in Hz")
        with np.errstate(divide="ignore"):
            mag.semilogx(f, 20 * np.log10(np.abs(h[:, o, i])), color="tab:red", lw=1.3, label="linearised model")
        phase.semilogx(f, model_phase, color="tab:red", lw=1.3)
        for d in modes:
            if lo <= d["f_hz"] <= hi:
                for ax in (mag, phase):
                    ax.axvline(d["f_hz"], color="tab:blue", lw=0.8, ls=":")
                mag.annotate(f" mode {d['f_hz']:.3g} Hz, ζ {d['zeta']:.2g}", (d["f_hz"], 0.97),
                             xycoords=("data", "axes fraction"), fontsize="small", color="tab:blue",
                             ha="left", va="top")
        mag.set_title(f"{inp} → {out}", fontsize="medium", loc="left")
        mag.set_ylabel("magnitude in dB" + _unit_ratio(model.units.get(out), model.units.get(inp)))
        phase.set_ylabel("phase in degrees")
        for ax in (mag, phase):
            ax.grid(alpha=0.3, which="both")
        mag.legend(loc="lower left", fontsize="small", framealpha=0.85)
        if not estimates:
            phase.set_xlabel("frequency in Hz")
        mag.set_xlim(lo, hi)
    point = ", ".join(f"{k} = {v:g}" for k, v in model.at.items())
    # the operating point on a line of its own, wrapped: a drive with many states has a long one
    fig.suptitle(f"{model.name}: Bode plot of the model linearised at\n{point}", fontsize="medium", wrap=True)
    return fig


def write_bode(model: LinearModel, path: str | Path, estimates: list[Empirical] = ()) -> Path:
    require_matplotlib()
    return save_png(bode_figure(model, list(estimates)), path)

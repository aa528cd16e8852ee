"""Does the residual still follow a held input at lag 0? Then the input was probably not held between samples.

Both the input and its change over the sample interval are tried: a model that sees the input half a sample
late leaves about T/2 times the response to the input's rate (which follows the change, or, where the fit
absorbed part of it into the parameters, the input itself).

A held input (the default, `intersample: hold`) acts from its sample to the next. When the real input moves
smoothly between samples (a measured voltage, about ten samples per period), the model sees it half a sample
late, and the free-run residual keeps a part that moves with the input itself: on the issue's hardening-spring
record r = -0.7 at lag 0 after the fit. The fix is `intersample: linear` (or a dead time) on that input.

"Beyond chance": the sample correlation of two autocorrelated series has, under independence, the variance
(1/n) sum_k rho_e(k) rho_u(k) (Bartlett); for smooth signals that is far more than 1/n. The warning needs
|r| above LAG_ZERO_Z of those standard deviations and above LAG_ZERO_MIN.

Layer: identify (reads a Problem and a point; numpy only).
"""

from __future__ import annotations

import numpy as np

from ... import rules
from ...notices import Notice

__all__ = ["LAG_ZERO_Z", "LAG_ZERO_MIN", "lag_zero_correlations", "lag_zero_warnings"]

#: standard deviations of the chance correlation the lag-0 correlation must exceed
LAG_ZERO_Z = rules.value("lag_zero_z")
#: ... and at least this correlation (a long record makes tiny correlations significant and harmless)
LAG_ZERO_MIN = rules.value("lag_zero_min")
#: lags summed in Bartlett's variance
MAX_LAG = rules.value("lag_zero_max_lag")


def lag_zero_correlations(problem, x) -> dict[tuple[str, str, str], tuple[float, float]]:
    """{(input, output, "u" or "du"): (r, chance standard deviation)} of the free-run residual against each held
    input ("u") and its change over the sample ("du") at lag 0 over the training records; empty when the run
    diverges."""
    x = np.asarray(x, dtype=float)
    if x.shape != (len(problem.names),):  # a point of another shape (the per-record values' mean): not the fit's
        return {}
    e_all = problem.residual(x)
    if e_all is None:
        return {}
    net = problem.network
    n_out = len(problem.compiled.output_names)
    held = [i for i, spec in enumerate(net.inputs) if spec.intersample == "hold" and spec.delay is None]
    pairs: dict[tuple[int, int], list[tuple[np.ndarray, np.ndarray]]] = {}
    at = 0
    for s in problem.segments:
        m = s.targets.size
        e = e_all[at:at + m].reshape(s.targets.shape)
        at += m
        # residual row i is the data row after the network input row i (zoh) or row i itself (direct)
        u = s.inputs[1:] if problem.alignment == "zoh" else s.inputs
        du = np.diff(s.inputs, axis=0) if problem.alignment == "zoh" else np.diff(s.inputs, axis=0, prepend=s.inputs[:1])
        e = e[:len(u)]
        for i in held:
            for o in range(n_out):
                pairs.setdefault((i, o, "u"), []).append((e[:, o], u[:, i]))
                pairs.setdefault((i, o, "du"), []).append((e[:, o], du[:len(e), i]))
    out = {}
    for (i, o, what), parts in pairs.items():
        e = np.concatenate([p[0] - p[0].mean() for p in parts])
        u = np.concatenate([p[1] - p[1].mean() for p in parts])
        if len(e) < 20 or not np.any(e) or not np.any(u):
            continue
        r = float(e @ u / np.sqrt((e @ e) * (u @ u)))
        out[(net.inputs[i].name, problem.compiled.output_names[o], what)] = (r, _chance_sd(e, u))
    return out


def _chance_sd(e: np.ndarray, u: np.ndarray) -> float:
    n = len(e)
    lags = min(MAX_LAG, n // 4)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    acf = []
    for v in (e, u):
        f = np.fft.rfft(v, size)
        a = np.fft.irfft(f * np.conj(f), size)[:lags + 1]
        acf.append(a / a[0])
    var = (1.0 + 2.0 * float(np.sum(acf[0][1:] * acf[1][1:]))) / n
    return float(np.sqrt(max(var, 1.0 / n)))


def lag_zero_warnings(problem, x) -> list[Notice]:
    """The warnings of :func:`lag_zero_correlations` beyond chance (one per input and output), naming the
    option to try."""
    found: dict[tuple[str, str], tuple[str, float, float]] = {}
    for (name, output, what), (r, sd) in lag_zero_correlations(problem, x).items():
        if abs(r) > max(LAG_ZERO_MIN, LAG_ZERO_Z * sd) and abs(r) > abs(found.get((name, output), ("", 0.0))[1]):
            found[(name, output)] = (what, r, sd)
    out = []
    for (name, output), (what, r, sd) in found.items():
        signal = name if what == "u" else f"the change of {name} over the sample"
        out.append(Notice(
            "LAG001", f"the residual on {output} follows {signal} at lag 0 (r = {r:+.2f}; by chance within about "
            f"+-{LAG_ZERO_Z * sd:.2f}): the held input {name} may move smoothly between its samples (a "
            f"measured signal rather than a held command): try `intersample: linear` on it (chart: inputs: "
            f"{{{name}: {{intersample: linear}}}}, or --intersample {name}=linear), or a dead time (inputs: "
            f"{{{name}: {{delay: tau}}}} with a parameter tau in s)",
            {"input": name, "output": output, "of": "change" if what != "u" else "value", "r": r,
             "chance": LAG_ZERO_Z * sd},
            f"try `intersample: linear` on {name}, or a dead time on it"))
    return out

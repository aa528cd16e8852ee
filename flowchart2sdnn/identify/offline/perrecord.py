"""Per-record parameters (`per_record: true`): their values per training record, with intervals, and the mean.

With several training records the Problem fits one value of such a parameter per record (identify.offline.problem:
the network's weight for it switches from record to record, the other parameters are shared). The chart's own
value, the `parameters` entry of RESULT.json and the identified chart's `init`, is the mean over the training
records: that is what a record without a fit of its own (a validation record without `--init-window`) runs
with. Its interval comes from the covariance of the per-record values: var(mean) = 1ᵀ Σ 1 / K².

Layer: identify.
"""

from __future__ import annotations

import numpy as np

__all__ = ["per_record_estimates"]


def per_record_estimates(problem, x: np.ndarray, evidence, paths) -> tuple[dict, dict]:
    """({name: [{record, value, stderr, ci95} per training record]}, {name: (mean, stderr, ci95)}).

    stderr and ci95 are None where the covariance is unavailable (as for any parameter).
    """
    per, means = {}, {}
    corr = evidence.uncertainty.correlation if evidence.uncertainty is not None else None
    for name, idx in problem.record_index().items():
        values = [float(x[i]) for i in idx]
        rows = []
        for path, i, v in zip(paths, idx, values, strict=True):
            se = half = None
            if evidence.stderr is not None and np.isfinite(evidence.stderr[i]):
                se, half = float(evidence.stderr[i]), float(evidence.half[i])
            rows.append({"record": path, "value": v, "stderr": se,
                         "ci95": None if se is None else [v - half, v + half]})
        per[name] = rows
        mean = float(np.mean(values))
        se = ci = None
        if corr is not None and all(r["stderr"] is not None for r in rows):
            s = np.array([r["stderr"] for r in rows])
            rho = np.array([[corr[a][b] if corr[a][b] is not None else 0.0 for b in idx] for a in idx])
            var = float(s @ rho @ s) / len(s) ** 2
            if np.isfinite(var) and var >= 0:
                se = float(np.sqrt(var))
                t = float(evidence.half[idx[0]] / evidence.stderr[idx[0]])  # the same Student t for all
                ci = (mean - t * se, mean + t * se)
        means[name] = (mean, se, ci)
    return per, means

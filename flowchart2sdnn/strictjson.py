"""Strict JSON for the documents the tool writes (RESULT.json, REPORT.json): NaN and infinities become null.

Layer: bottom (imports nothing of ours).
"""

from __future__ import annotations

import math

__all__ = ["strict_json", "finite_or_none"]


def strict_json(obj, path: str = "", bad: list[str] | None = None):
    """`obj` with every NaN/inf float replaced by None; the path of each (``a[1].b``) is appended to `bad`.

    Mapping keys become strings, tuples lists: the value is what ``json.dumps(..., allow_nan=False)`` takes.
    """
    if isinstance(obj, float):
        if math.isfinite(obj):
            return obj
        if bad is not None:
            bad.append(path or "(root)")
        return None
    if isinstance(obj, dict):
        return {str(k): strict_json(v, f"{path}.{k}" if path else str(k), bad) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v, f"{path}[{i}]", bad) for i, v in enumerate(obj)]
    return obj


def finite_or_none(x) -> float | None:
    """A number as a float, or None when it is None, NaN or infinite (a metric of a diverged run)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None

"""Plain aligned text tables, the one text layout every summary uses. Layer: bottom (imports nothing of ours)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

__all__ = ["table", "frame"]


def table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A plain aligned text table."""
    cells = [[str(h) for h in headers]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    out = []
    for n, r in enumerate(cells):
        out.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
        if n == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out) + "\n"


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return "" if value is None else str(value)


def frame(rows: Sequence[Mapping[str, object]], columns: Sequence[str]):
    """`rows` as a pandas DataFrame with these columns when pandas is installed, else as a list of dicts (pandas
    stays optional: the notebook tables are the same rows either way)."""
    try:
        import pandas
    except ImportError:
        return [dict(r) for r in rows]
    return pandas.DataFrame([dict(r) for r in rows], columns=list(columns))

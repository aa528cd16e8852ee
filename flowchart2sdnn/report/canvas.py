"""One matplotlib figure on its own Agg canvas, written as PNG bytes atomically: how every sdnn figure is made.

No pyplot and no global backend (a library must not change the caller's matplotlib state); PNGs carry no
Software/date metadata, so the same run gives the same bytes, and a reader never sees half a file.
"""

from __future__ import annotations

import io
from pathlib import Path

from ..atomic import atomic_write_bytes
from ..errors import SdnnError

__all__ = ["new_figure", "png_bytes", "save_png", "require_matplotlib"]

_INSTALL = "pip install flowchart2sdnn[plots]"


def require_matplotlib(option: str = "--plots") -> None:
    """Raise a one-line SdnnError (PLOT001) naming `option` and the install command when matplotlib is missing."""
    try:
        import matplotlib  # noqa: F401
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
    except ImportError:
        raise SdnnError.at("PLOT001", f"{option} needs matplotlib, which is not installed: {_INSTALL}", option,
                           hint=_INSTALL) from None


def new_figure(rows: int, cols: int = 1, width: float = 9.0, height: float = 2.4, **subplots):
    """(figure, axes array of shape (rows, cols)) on an Agg canvas; `height` per row, at least 3 inches."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, max(3.0, height * rows)), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, cols, squeeze=False, **subplots)


def png_bytes(fig, dpi: float | None = None) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", metadata={"Software": None}, dpi=dpi)
    return buffer.getvalue()


def save_png(fig, path: str | Path, dpi: float | None = None) -> Path:
    path = Path(path)
    atomic_write_bytes(path, png_bytes(fig, dpi))
    return path

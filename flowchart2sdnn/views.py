"""Where a view offers itself to the data classes that draw on request (``Identification.compare(plot=)``).

Computation never imports report/ (the layer test says so), yet a typed result may offer to draw itself, as a
pandas frame does through its plotting backend. The dependency points the right way round: report/ registers
its drawing functions here when the package loads (:mod:`flowchart2sdnn.report`), the data class asks for one
by name.

Layer: bottom (imports nothing of ours).
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["register", "view"]

_VIEWS: dict[str, Callable] = {}


def register(name: str, draw: Callable) -> None:
    """Offer `draw` under `name` (a later registration replaces an earlier one)."""
    _VIEWS[name] = draw


def view(name: str) -> Callable:
    """The drawing function registered as `name`; LookupError saying what to import when there is none."""
    try:
        return _VIEWS[name]
    except KeyError:
        raise LookupError(f"no view {name!r} is registered: import flowchart2sdnn.report") from None

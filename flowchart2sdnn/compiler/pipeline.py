"""compile_diagram: load -> validate -> lint -> loop analysis -> discretize -> emit.

Each pass is a pure function over frozen data; a pass that finds the chart unusable raises SdnnError with the
diagnostics of that pass.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from ..analysis.lint import lint_diagram
from ..analysis.loops import LoopReport, analyse_loops, delay_rule
from ..diagram.model import Diagram
from ..diagram.validate import load_diagram
from ..errors import Diagnostic, Location, SdnnError
from ..network.midstep import extrapolate_speed_torques
from ..network.model import Network
from .discretize import DiscreteChart, discretize
from .emit import emit_network
from .substeps import AUTO_BOUND_MIDPOINT, AUTO_CAP, SubstepChoice, choose_substeps

__all__ = ["Compilation", "compile_diagram", "compile_file"]


@dataclass(frozen=True)
class Compilation:
    """Everything the passes made, for `--explain` and `--dump-after`."""

    diagram: Diagram
    loops: LoopReport
    discrete: DiscreteChart
    network: Network
    warnings: tuple
    substeps: SubstepChoice = SubstepChoice(1, None)


@contextmanager
def _collector_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector while the passes build their (acyclic) graphs and tables.

    Every few thousand new containers the collector re-scans everything alive, the whole chart included: at
    1000 masses that was 40 % of the compile time. Reference counting still frees all acyclic garbage, and
    the collector runs again (catching any cycle) as soon as the pass is done.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def compile_diagram(diagram: Diagram, seed: int = 0, substeps: int | str | None = None) -> Compilation:
    """Lint, analyse loops, discretize and emit; SdnnError with the lint errors when the chart is unusable.

    `substeps` (an int >= 1 or "auto") overrides the chart's `substeps` (see :mod:`.substeps`).
    """
    with _collector_paused():
        return _compile(diagram, seed, substeps)


def _compile(diagram: Diagram, seed: int, substeps: int | str | None = None) -> Compilation:
    diagnostics = lint_diagram(diagram)
    errors = [d for d in diagnostics if d.severity == "error"]
    if errors:
        raise SdnnError(errors)
    loops = analyse_loops(diagram)
    built: dict[int, tuple[DiscreteChart, Network]] = {}

    def emitted(n: int) -> Network:
        if n not in built:
            discrete = discretize(diagram, loops, seed, n)
            built[n] = (discrete, emit_network(diagram, discrete, loops, seed, n))
        return built[n][1]

    if delay_rule(diagram) == "midpoint":  # the torques rule's delays, then the speed torques at mid-step
        choice, network = choose_substeps(diagram, lambda n: extrapolate_speed_torques(emitted(n)), substeps,
                                          probe=emitted, bound=AUTO_BOUND_MIDPOINT)
    else:
        choice, network = choose_substeps(diagram, emitted, substeps)
    warnings = [d for d in diagnostics if d.severity != "error"]
    if choice.capped:
        warnings.append(Diagnostic(
            "COMPILE010", "warning", f"substeps: auto wants more than {AUTO_CAP} steps per sample (fastest mode "
            f"at rest {choice.omega_max:.4g} rad/s); using {AUTO_CAP}, so the discretization error may exceed "
            "the auto target", Location(diagram.file, None),
            hint="a steep curve at zero speed reads as a fast mode; or give substeps: N"))
    return Compilation(diagram, loops, built[choice.substeps][0], network, tuple(warnings), choice)


def compile_file(path: str | Path, seed: int = 0, substeps: int | str | None = None) -> Compilation:
    """Load, validate and compile a chart file (`substeps` as in :func:`compile_diagram`)."""
    with _collector_paused():
        return _compile(load_diagram(path), seed, substeps)


def check_file(path: str | Path) -> list[Diagnostic]:
    """Every problem of the chart file at `path`, errors and warnings (what `sdnn lint` reports).

    Parameters
    ----------
    path : str or Path
        The chart (YAML).

    Returns
    -------
    list of Diagnostic
        Those of loading and validating, of lint, and, when lint finds no error, of compiling (what only the
        compiler finds: a loop of gains, an overflowing weight). Empty for a clean chart; never raises
        SdnnError.
    """
    diagnostics: list[Diagnostic] = []
    try:
        diagram = load_diagram(path)
        diagnostics = lint_diagram(diagram)
        if not any(d.severity == "error" for d in diagnostics):
            compile_diagram(diagram)
    except SdnnError as exc:
        diagnostics = diagnostics + list(exc.diagnostics)
    return diagnostics

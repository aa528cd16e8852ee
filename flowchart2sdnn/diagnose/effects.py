"""The effects library: named, composable candidates for what a chart lacks (PySINDy's feature libraries).

Each effect is a small frozen object that knows

* ``places(diagram)`` - where it may attach (:class:`~.graph.Place`);
* ``options(diagram, place, scales)`` - the discrete choices to try there (a dead time's n, a saturation
  limit, a cogging harmonic, or the signal scale that sets a learned curve's neutral shape);
* ``patch(diagram, place, option)`` - a NEW chart with the effect added and its new quantities at values
  that are *neutral* when ``neutral`` is True (the patched chart's outputs equal the input chart's, so the
  score test of :mod:`.score` applies at the current fit); effects whose choice changes the model at once
  (dead time, a saturation limit inside the data range) are scored from the patched chart as it is;
* ``describe()`` and ``label(option)`` for reports.

The chart given is never mutated (every patch goes through :func:`dataclasses.replace`).

=============  ==================  =====================================================================
effect         attaches at         adds
=============  ==================  =====================================================================
friction       speed               nonlinear curve of the speed (tanh neurons with bias, v = 0) subtracted
                                   in its torque sum; or (option "coulomb") the terms of `coulomb`
damping        speed, speed diff.  viscous gain with a new parameter (0) in the torque sum(s)
(coulomb)      speed               Fc*sign_smooth(w) + c + dFv*max(w, 0), new parameters at 0: asymmetric
                                   Coulomb and viscous friction with physical parameters (an option of
                                   friction; not in the registry on its own)
dead_time      input               a dead time tau (s) on the input: n samples scanned, tau fitted within n -+ 1/2
saturation     input               L*sat((u - o)/L) + o: a hard clip at o -/+ L, L scanned in the data range
sensor_limit   output              the same clip on a measured output (a sensor or its converter at its range);
                                   the chart's block is renamed, the output reads the clipped signal (an
                                   `init: data` block keeps its start: `measured_by` the output)
sensor_offset  output (read)       the physics reads the measured output + o (o = 0): a sensor's zero offset
backlash       spring angle        c*x becomes c*x + an odd learned curve (v = 0) of x (a dead zone is learnable)
dead_zone      spring angle        c*x becomes c*(x - g*sat(x/g)): exact backlash of half gap g (scanned)
cogging        speed               A sin(p phi) + B cos(p phi) (A = B = 0) in the sum, phi the speed's position
                                   in the chart or a new integral of it; p = 1 an unbalance (p with a period
                                   beyond 2 RMS of a position the chart has: not offered) (:mod:`.positions`)
spring         position (sprung)   k*x to ground becomes k*x + an odd learned curve of x (v = 0) in its speed's
                                   sum: a hardening or softening spring (:mod:`.positions`)
overflow       integrator state    x' = f - K relu(x - L): x held at a learned level L (or above a lower one),
                                   the excess lost or routed into a downstream integrator (:mod:`.overflow`)
input_offset   input               the physics reads u + o (o = 0): an input's zero offset (:mod:`.lawterms`)
linear_term    power law f(x)      k*f(x) becomes k*f(x) + c*x (c = 0), f = sqrt, square, signed_square: a
                                   Torricelli outflow's laminar share, a drag's viscous share (:mod:`.lawterms`)
=============  ==================  =====================================================================
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol, runtime_checkable

from ..diagram.model import Diagram
from ..errors import SdnnError, did_you_mean
from .friction import Coulomb, Damping, Friction, Physical
from .graph import Place
from .lawterms import InputOffset, LinearTerm
from .overflow import Overflow
from .positions import Cogging, Spring
from .shafts import Backlash, DeadZone
from .signals import DeadTime, Saturation, SensorLimit, SensorOffset

__all__ = [
    "Scales",
    "Effect",
    "Friction",
    "Coulomb",
    "Physical",
    "Damping",
    "DeadTime",
    "Saturation",
    "SensorLimit",
    "SensorOffset",
    "Backlash",
    "DeadZone",
    "Cogging",
    "Spring",
    "Overflow",
    "LinearTerm",
    "InputOffset",
    "BUILTIN_EFFECTS",
    "builtin_effects",
    "effect_library",
    "select_effects",
]


@dataclass(frozen=True)
class Scales:
    """Magnitudes seen on the training record: they set neutral curve shapes and scanned options.

    Attributes
    ----------
    rms : mapping str -> float
        Root mean square of chart signals (from a simulation of the current fit) and of the inputs.
    lo, hi : mapping str -> float
        Smallest and largest value of each input and of each chart signal (the current fit's simulation).
    """

    rms: Mapping[str, float] = field(default_factory=dict)
    lo: Mapping[str, float] = field(default_factory=dict)
    hi: Mapping[str, float] = field(default_factory=dict)

    def scale(self, signal: str) -> float:
        value = float(self.rms.get(signal, 1.0))
        return value if value > 0 else 1.0

    def span(self, signal: str) -> float:
        """The largest |value| of the signal (a learned curve's basis spans it); 3 RMS where unknown."""
        if signal in self.lo and signal in self.hi:
            value = max(abs(float(self.lo[signal])), abs(float(self.hi[signal])))
            if value > 0 and math.isfinite(value):
                return value
        return 3.0 * self.scale(signal)


@runtime_checkable
class Effect(Protocol):
    """A named candidate the chart may lack. ``repeatable``: once accepted at a place, its other options stay on
    offer there (cogging harmonics add up); effects that do not say so are not repeatable."""

    name: str
    neutral: bool
    extra_dof: int

    def places(self, diagram: Diagram) -> tuple[Place, ...]: ...

    def options(self, diagram: Diagram, place: Place, scales: Scales) -> tuple: ...

    def patch(self, diagram: Diagram, place: Place, option=None) -> Diagram: ...

    def describe(self) -> str: ...

    def label(self, option) -> str: ...


# ------------------------------------------------------------------------------------------------ registry
BUILTIN_EFFECTS: dict[str, Effect] = {
    e.name: e for e in (Friction(), Damping(), DeadTime(), Saturation(), Backlash(), DeadZone(), Cogging(),
                        Spring(), Overflow(), SensorLimit(), SensorOffset(), InputOffset(), LinearTerm())
}


def builtin_effects() -> dict[str, Effect]:
    """A copy of the registry: name -> effect with its default options."""
    return dict(BUILTIN_EFFECTS)


def effect_library(dead_time_max: int | None = None, harmonics: Sequence[int] | None = None,
                   user: Mapping[str, Effect] | None = None) -> dict[str, Effect]:
    """The effects diagnose can choose from: the built-in ones with the scan options given, then the user's.

    Parameters
    ----------
    dead_time_max : int, optional
        dead_time scans n = 1..this many samples (default: DeadTime's).
    harmonics : sequence of int, optional
        The cogging harmonics p to try (default: Cogging's).
    user : mapping of str to Effect, optional
        User effects by name, e.g. from :func:`flowchart2sdnn.diagnose.usereffects.load_effects_file`.

    Returns
    -------
    dict of str to Effect
        Name -> effect, built-in ones first.

    Raises
    ------
    ValueError
        When a user effect has the name of a built-in effect.
    """
    library = builtin_effects()
    if dead_time_max is not None:
        library["dead_time"] = replace(library["dead_time"], max_samples=dead_time_max)
    if harmonics is not None:
        library["cogging"] = replace(library["cogging"], harmonics=tuple(harmonics))
    for name, effect in (user or {}).items():
        if name in library:
            raise ValueError(f"effect '{name}' has the name of a built-in effect")
        library[name] = effect
    return library


def select_effects(names: Sequence[str] | None, available: Mapping[str, Effect],
                   where: str = "--effects") -> tuple[Effect, ...]:
    """The effects named (all when `names` is None), in the order given; SdnnError for an unknown name."""
    if names is None:
        return tuple(available.values())
    out = []
    for n in names:
        n = n.strip()
        if not n:
            continue
        if n not in available:
            raise SdnnError.at("DIAG001", f"unknown effect {n!r}; known: {', '.join(available)}", where,
                               hint=did_you_mean(n, available))
        out.append(available[n])
    if not out:
        raise SdnnError.at("DIAG001", "no effect selected", where, hint=f"choose from {', '.join(available)}")
    return tuple(out)

"""Bounds through a change of variables (the MINUIT / lmfit transform).

The trainer never clips: it works on an unbounded internal coordinate ``u`` and maps it to the bounded
external value ``x`` (the physical quantity) by a smooth function whose range is exactly ``[min, max]``:

=============  ========================================  =============================
bounds         x(u)                                      dx/du
=============  ========================================  =============================
none           u                                         1
min only       min - 1 + sqrt(u**2 + 1)                  u / sqrt(u**2 + 1)
max only       max + 1 - sqrt(u**2 + 1)                  -u / sqrt(u**2 + 1)
min and max    min + (max - min) * (sin(u) + 1) / 2      (max - min) / 2 * cos(u)
=============  ========================================  =============================

A one-sided transform may bend within a width ``w`` other than 1 (:meth:`Bounds.with_width`):
``x = min + w * (sqrt((u/w)**2 + 1) - 1)``, straight (``dx/du`` near 1) once ``x - min`` exceeds a few ``w``.
With ``w = 1`` the bend sits at one *unit* of the quantity, so a friction coefficient of 0.024 N·m·s/rad lives
deep in the bend (``x`` about ``u**2 / 2``) while a stiffness of 570 N·m/rad does not, and plain LM steps crawl
along the transform's own curvature (benchmarks/bench_rough_init.py, coulomb chart). The trainer's
``bound_width`` sets ``w`` from the start values. It is not identify's default: a quantity whose minimum is its
bound then meets a bend 1/w times sharper there (docs/rough_init.md, "Speed"). The trainer's ``bounds = "box"``
(:mod:`.boxstep`) keeps the bounds without this transform; identify uses it on charts without learned curves.

The Jacobian of the model with respect to ``u`` follows from the chain rule, ``J_u = J_x * dx/du``.
At a bound ``dx/du`` is zero, so a quantity that *starts* exactly at a bound could never move;
:func:`Bounds.to_internal` therefore accepts such a value, and :meth:`Bounds.start` moves its internal
image a small, documented distance (``BOUND_NUDGE``) inside, as MINUIT does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import rules

__all__ = ["Bounds", "BOUND_NUDGE"]

#: Internal distance from a bound used when a start value lies exactly on it.  For ``min only`` this
#: moves x by about ``BOUND_NUDGE**2 / 2`` (5e-9); for two bounds by ``(max-min) * BOUND_NUDGE**2 / 4``.
BOUND_NUDGE = rules.value("bound_nudge")


def _as_bound_array(value, n: int, default: float, what: str) -> np.ndarray:
    if value is None:
        return np.full(n, default)
    arr = np.array(value, dtype=float).reshape(-1) if np.ndim(value) else np.full(n, float(value))
    if arr.shape != (n,):
        raise ValueError(f"`{what}` has {arr.size} entries, expected {n} (one per quantity)")
    if np.any(np.isnan(arr)):
        raise ValueError(f"`{what}` contains NaN; use -inf/inf (or None) for 'no bound'")
    return arr


def _fmt(v: float) -> str:
    return f"{v:.12g}"


@dataclass(frozen=True, eq=False)
class Bounds:
    """Lower and upper bounds of P named quantities and the transform between x and u.

    Parameters
    ----------
    names : tuple of str, length P
        Quantity names, used in error messages.
    lower, upper : ndarray, shape (P,)
        Bounds; ``-inf`` / ``inf`` mean "none".  Build with :meth:`Bounds.make`.
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    width: np.ndarray | None = None  # the one-sided transforms' widths w (None: 1 for every quantity)

    @classmethod
    def make(cls, names: Sequence[str], lower=None, upper=None) -> Bounds:
        """Validate and build; ``lower``/``upper`` may be None, a scalar or a length-P sequence."""
        names = tuple(str(n) for n in names)
        n = len(names)
        lo = _as_bound_array(lower, n, -np.inf, "lower")
        hi = _as_bound_array(upper, n, np.inf, "upper")
        for i, name in enumerate(names):
            if lo[i] == np.inf or hi[i] == -np.inf:
                raise ValueError(
                    f"`{name}` has an infinite bound on the wrong side (min {lo[i]}, max {hi[i]})"
                )
            if not lo[i] < hi[i]:
                raise ValueError(
                    f"`{name}` has min {_fmt(lo[i])} >= max {_fmt(hi[i])}; to hold a quantity constant mark it fixed"
                )
        lo.setflags(write=False)
        hi.setflags(write=False)
        return cls(names, lo, hi)

    def with_width(self, width) -> Bounds:
        """These bounds with one-sided transforms of width ``width`` (P,), each finite and > 0."""
        w = np.array(width, dtype=float).reshape(-1)
        if w.shape != (len(self.names),) or not np.all(np.isfinite(w) & (w > 0)):
            raise ValueError(f"`width` must hold {len(self.names)} finite numbers > 0, got {width!r}")
        w.setflags(write=False)
        return Bounds(self.names, self.lower, self.upper, w)

    def _w(self, mask: np.ndarray) -> np.ndarray | float:
        return 1.0 if self.width is None else self.width[mask]

    # ------------------------------------------------------------------ masks
    @property
    def _has_lo(self) -> np.ndarray:
        return np.isfinite(self.lower)

    @property
    def _has_hi(self) -> np.ndarray:
        return np.isfinite(self.upper)

    # ------------------------------------------------------------------ checks
    def check(self, x: np.ndarray, what: str = "x0") -> None:
        """Raise ValueError naming the first quantity of ``x`` outside ``[min, max]`` (bounds themselves are allowed)."""
        x = np.asarray(x, dtype=float)
        for i, name in enumerate(self.names):
            if not np.isfinite(x[i]):
                raise ValueError(f"`{name}` = {x[i]} in `{what}` is not finite")
            if x[i] < self.lower[i]:
                raise ValueError(f"`{name}` = {_fmt(x[i])} is below its min {_fmt(self.lower[i])}")
            if x[i] > self.upper[i]:
                raise ValueError(f"`{name}` = {_fmt(x[i])} is above its max {_fmt(self.upper[i])}")

    # ------------------------------------------------------------------ transform
    def to_external(self, u: np.ndarray) -> np.ndarray:
        """x(u), shape (P,) -> (P,); the result lies in ``[min, max]`` exactly (no rounding past a bound)."""
        u = np.asarray(u, dtype=float)
        x = u.copy()
        lo, hi, has_lo, has_hi = self.lower, self.upper, self._has_lo, self._has_hi
        only_lo = has_lo & ~has_hi
        only_hi = has_hi & ~has_lo
        both = has_lo & has_hi
        # sqrt(u^2+1) - 1 written as |u| * (|u| / (hypot(u, 1) + 1)): no cancellation near the bound,
        # never < 0, and no overflow of u^2 for a wild trial step
        w = np.ones_like(u) if self.width is None else self.width
        a = np.abs(u) / w
        r = w * (a * (a / (np.hypot(a, 1.0) + 1.0)))
        x[only_lo] = lo[only_lo] + r[only_lo]
        x[only_hi] = hi[only_hi] - r[only_hi]
        # half-width and centre written so that huge finite bounds do not overflow
        half = 0.5 * hi[both] - 0.5 * lo[both]
        centre = 0.5 * lo[both] + 0.5 * hi[both]
        x[both] = np.clip(centre + half * np.sin(u[both]), lo[both], hi[both])
        return x

    def to_internal(self, x: np.ndarray) -> np.ndarray:
        """u(x), the inverse of :meth:`to_external` (principal branch; ``u >= 0`` for one-sided bounds)."""
        x = np.asarray(x, dtype=float)
        self.check(x)
        u = x.copy()
        lo, hi, has_lo, has_hi = self.lower, self.upper, self._has_lo, self._has_hi
        only_lo = has_lo & ~has_hi
        only_hi = has_hi & ~has_lo
        both = has_lo & has_hi
        # sqrt((d+1)^2 - 1) = sqrt(d) * sqrt(d + 2): no cancellation for small d, no overflow for large d
        w = self._w(only_lo)
        d = (x[only_lo] - lo[only_lo]) / w
        u[only_lo] = w * np.sqrt(d) * np.sqrt(d + 2.0)
        w = self._w(only_hi)
        d = (hi[only_hi] - x[only_hi]) / w
        u[only_hi] = w * np.sqrt(d) * np.sqrt(d + 2.0)
        half = 0.5 * hi[both] - 0.5 * lo[both]
        centre = 0.5 * lo[both] + 0.5 * hi[both]
        u[both] = np.arcsin(np.clip((x[both] - centre) / half, -1.0, 1.0))
        return u

    def dx_du(self, u: np.ndarray) -> np.ndarray:
        """Derivative dx/du, shape (P,): the column scale of the chain rule J_u = J_x * dx/du."""
        u = np.asarray(u, dtype=float)
        d = np.ones_like(u)
        has_lo, has_hi = self._has_lo, self._has_hi
        only_lo = has_lo & ~has_hi
        only_hi = has_hi & ~has_lo
        both = has_lo & has_hi
        a = u if self.width is None else u / self.width
        s = a / np.hypot(a, 1.0)
        d[only_lo] = s[only_lo]
        d[only_hi] = -s[only_hi]
        d[both] = (0.5 * self.upper[both] - 0.5 * self.lower[both]) * np.cos(u[both])
        return d

    def start(self, x0: np.ndarray) -> np.ndarray:
        """Internal start for ``x0``: :meth:`to_internal`, moved ``BOUND_NUDGE`` inside where x0 sits on a bound.

        On a bound ``dx/du = 0``, the gradient in u vanishes and the quantity could never leave it.
        """
        u = self.to_internal(x0)
        has_lo, has_hi = self._has_lo, self._has_hi
        one_sided = has_lo ^ has_hi
        both = has_lo & has_hi
        w = np.ones_like(u) if self.width is None else self.width
        stuck_one = one_sided & (np.abs(u) < BOUND_NUDGE * w)
        u[stuck_one] = BOUND_NUDGE * w[stuck_one]
        stuck_both = both & (np.abs(np.abs(u) - np.pi / 2) < BOUND_NUDGE)
        u[stuck_both] = np.sign(u[stuck_both]) * (np.pi / 2 - BOUND_NUDGE)
        return u

"""Covariance of least-squares estimates and identifiability, from the Jacobian at the optimum.

``cov = sigma^2 (J^T J)^+`` with ``sigma^2 = e^T e / (M - P)``, computed from the SVD of the
column-scaled Jacobian (never by inverting J^T J).  Scaling the columns to unit norm first makes the rank
decision and the null-space directions independent of the parameters' units: a spring constant of 500
and an inverse inertia of 5 are judged by how *collinear* their columns are, not by their size.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import stdtrit

from .. import rules

__all__ = ["Covariance", "covariance", "RANK_RTOL", "CORRELATION_LIMIT"]

#: A singular value of the column-scaled Jacobian below RANK_RTOL * (largest) counts as zero.
RANK_RTOL = rules.value("rank_rtol")
#: Pairs with |correlation| above this are reported as (practically) interchangeable.
CORRELATION_LIMIT = rules.value("correlation_limit")
# A quantity takes part in a null direction when its diagonal of the null-space projector exceeds this.
_NULL_PART = rules.value("null_part")


@dataclass(frozen=True, eq=False)
class Covariance:
    """Uncertainty of fitted quantities; arrays are read-only.

    Attributes
    ----------
    names : tuple of str (P,)
    available : bool                 False when M <= P (then cov/stderr/ci95/correlation are None)
    reason : str or None             why not available
    n_data, n_params, dof : int      M, number of fitted parameters, M - n_params
    sigma2 : float or None           residual variance e^T e / dof
    cov : ndarray (P, P) or None     NaN in rows/columns of quantities in a null direction
    stderr : ndarray (P,) or None    sqrt(diag cov); inf for quantities in a null direction
    ci95 : ndarray (P,) or None      half-width of the 95 % confidence interval, t(0.975, dof) * stderr
    correlation : ndarray (P, P) or None   NaN where undefined
    singular_values : ndarray        of the column-scaled Jacobian, descending, padded with zeros to P
    condition_number : float         s_max / s_min of J as given (inf when singular)
    scaled_condition_number : float  the same for the column-scaled Jacobian
    unidentifiable : tuple of tuple of str   groups that cannot be told apart (null space or |r| > 0.999)
    correlated : tuple of (str, str, float)  pairs with |correlation| > CORRELATION_LIMIT
    warning : str or None            human-readable summary of the above
    """

    names: tuple[str, ...]
    available: bool
    reason: str | None
    n_data: int
    n_params: int
    dof: int
    sigma2: float | None
    cov: np.ndarray | None
    stderr: np.ndarray | None
    ci95: np.ndarray | None
    correlation: np.ndarray | None
    singular_values: np.ndarray
    condition_number: float
    scaled_condition_number: float
    unidentifiable: tuple[tuple[str, ...], ...]
    correlated: tuple[tuple[str, str, float], ...]
    warning: str | None


def _triangle(J: np.ndarray) -> np.ndarray:
    if J.shape[0] > J.shape[1]:
        return np.linalg.qr(J, mode="r")
    return J


def _ro(a: np.ndarray | None) -> np.ndarray | None:
    if a is not None:
        a = np.array(a, dtype=float)
        a.setflags(write=False)
    return a


def _components(n: int, links: list[tuple[int, int]], members: set[int]) -> list[list[int]]:
    """Connected components (sorted, deterministic) of `members` under `links`."""
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in links:
        parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in sorted(members):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values())


def _quote(names: Sequence[str]) -> str:
    return ", ".join(f"`{n}`" for n in names)


def covariance(
    J: np.ndarray,
    residual: np.ndarray,
    n_params: int | None = None,
    *,
    names: Sequence[str] | None = None,
) -> Covariance:
    """Covariance, standard errors, 95 % intervals and identifiability of least-squares estimates.

    Parameters
    ----------
    J : ndarray (M, P)
        Jacobian of the model output (or of the residual: the sign does not matter) at the optimum.
    residual : ndarray (M,)
        Residual e = y - yhat at the optimum.
    n_params : int, optional
        Number of fitted parameters for the degrees of freedom M - n_params; defaults to P.
    names : sequence of str (P,), optional
        Names used in ``unidentifiable`` and the warning; default ``p0, p1, ...``.

    Returns
    -------
    Covariance
    """
    J = np.asarray(J, dtype=float)
    e = np.asarray(residual, dtype=float).reshape(-1)
    if J.ndim != 2 or J.shape[1] == 0:
        raise ValueError(f"`J` must have shape (M, P) with P >= 1, got {J.shape}")
    m, p = J.shape
    if e.shape != (m,):
        raise ValueError(f"`residual` must have shape ({m},) to match `J`, got {e.shape}")
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(e))):
        raise ValueError("`J` and `residual` must be finite")
    n_params = p if n_params is None else int(n_params)
    if n_params < p:
        raise ValueError(f"`n_params` = {n_params} is less than the {p} columns of `J`")
    names = tuple(f"p{i}" for i in range(p)) if names is None else tuple(str(n) for n in names)
    if len(names) != p:
        raise ValueError(f"`names` has {len(names)} entries, `J` has {p} columns")

    # A tall J (M >> P) is reduced to its P x P triangle first: same singular values and right vectors,
    # without an M x M factor (M is the record length).
    raw_s = np.linalg.svd(_triangle(J), compute_uv=False)
    cond = float(raw_s[0] / raw_s[-1]) if len(raw_s) == p and raw_s[-1] > 0 else float("inf")

    # Unit-norm columns; a zero column (no effect at all) stays zero and shows up as a null direction.
    d = np.linalg.norm(J, axis=0)
    d_safe = np.where(d > 0, d, 1.0)
    Js = J / d_safe
    _, s, vt = np.linalg.svd(_triangle(Js), full_matrices=True)
    s = np.concatenate([s, np.zeros(p - s.size)])
    rel = s / s[0] if s[0] > 0 else np.zeros(p)
    null = rel < RANK_RTOL
    scond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")

    # The null-space projector is independent of the (arbitrary) basis the SVD returns.
    v0 = vt[null].T
    proj = v0 @ v0.T
    in_null = {i for i in range(p) if proj[i, i] > _NULL_PART}
    links = [(i, j) for i in in_null for j in in_null if i < j and abs(proj[i, j]) > _NULL_PART]

    # pseudo-inverse of Js^T Js on the range, then undo the column scaling
    keep = ~null
    vr = vt[keep].T
    c_scaled = (vr / s[keep] ** 2) @ vr.T
    c_unit = c_scaled / np.outer(d_safe, d_safe)  # (J^T J)^+ without sigma^2
    bad = np.array([i in in_null for i in range(p)])
    with np.errstate(invalid="ignore", divide="ignore"):
        sd_unit = np.sqrt(np.diag(c_unit))
        corr = c_unit / np.outer(sd_unit, sd_unit)
    corr[bad, :] = np.nan
    corr[:, bad] = np.nan
    np.fill_diagonal(corr, np.where(bad, np.nan, 1.0))
    correlated = []
    for i in range(p):
        for j in range(i + 1, p):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > CORRELATION_LIMIT:
                correlated.append((names[i], names[j], float(corr[i, j])))
                links.append((i, j))
    members = in_null | {i for a, b, _ in correlated for i in (names.index(a), names.index(b))}
    groups = _components(p, links, members)
    unidentifiable = tuple(tuple(names[i] for i in g) for g in groups)

    warning = _warning(groups, names, in_null, correlated)
    dof = m - n_params
    base = dict(
        names=names,
        n_data=m,
        n_params=n_params,
        dof=dof,
        singular_values=_ro(s),
        condition_number=cond,
        scaled_condition_number=scond,
        unidentifiable=unidentifiable,
        correlated=tuple(correlated),
        warning=warning,
    )
    if dof <= 0:
        reason = (
            f"{m} residuals for {n_params} parameters: a covariance needs more residuals than "
            "fitted parameters"
        )
        return Covariance(
            available=False,
            reason=reason,
            sigma2=None,
            cov=None,
            stderr=None,
            ci95=None,
            correlation=None,
            **base,
        )

    sigma2 = float(e @ e) / dof
    cov = sigma2 * c_unit
    cov[bad, :] = np.nan
    cov[:, bad] = np.nan
    stderr = np.sqrt(sigma2) * sd_unit
    stderr[bad] = np.inf
    t95 = float(stdtrit(dof, 0.975))  # Student t quantile; scipy.special loads far faster than scipy.stats
    return Covariance(
        available=True,
        reason=None,
        sigma2=sigma2,
        cov=_ro(cov),
        stderr=_ro(stderr),
        ci95=_ro(t95 * stderr),
        correlation=_ro(corr),
        **base,
    )


def _warning(groups, names, in_null, correlated) -> str | None:
    parts = []
    for g in groups:
        group_names = [names[i] for i in g]
        if len(g) == 1 and g[0] in in_null:
            parts.append(
                f"{_quote(group_names)} has no visible effect on the output and cannot be identified"
            )
        elif any(i in in_null for i in g):
            parts.append(
                f"{_quote(group_names)} cannot be told apart: only a combination of them affects the output "
                "(fix all but one, or change the model or the excitation)"
            )
        else:
            pairs = [f"`{a}`/`{b}` r = {r:+.4f}" for a, b, r in correlated if a in group_names]
            parts.append(f"{_quote(group_names)} are practically interchangeable ({', '.join(pairs)})")
    return "; ".join(parts) if parts else None

"""Grid convergence of a quantity on systematically refined meshes (pure Python + math).

Three solutions f1 (finest), f2, f3 (coarsest) on grids of element sizes h1 < h2 < h3, with
the refinement ratios r21 = h2 / h1 > 1 and r32 = h3 / h2 > 1 (Roache 1998; Celik et al.
2008, whose procedure admits unequal ratios):

- differences e21 = f2 - f1, e32 = f3 - f2 and their ratio R = e21 / e32: oscillatory for
  R < 0; for R > 0 the observed order p solves e32 / e21 = r21^p (r32^p - 1) / (r21^p - 1)
  (f = f0 + C h^p through the three points), which has a root p > 0 exactly when
  e32 / e21 > ln r32 / ln r21: monotone convergence; otherwise divergence. With r21 = r32 = r
  this is 0 < R < 1 and p = ln(e32 / e21) / ln r;
- Richardson extrapolation f_ext = f1 + (f1 - f2) / (r21^p - 1);
- grid convergence index of the finest grid GCI = Fs |(f1 - f2) / f1| / (r21^p - 1), with
  the safety factor Fs = 1.25 for three or more grids: a band around f1 (a fraction) that
  holds the grid-independent value with about 95 % confidence.

Outside monotone convergence p, f_ext and GCI are NaN and ``kind`` says why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

__all__ = ["SAFETY_FACTOR", "GridStudy", "grid_study", "grid_studies"]

SAFETY_FACTOR = 1.25  # Roache's Fs for three or more grids
_MAX_ORDER = 50.0  # an order above this is reported as this (the two finest agree)


class GridStudy(NamedTuple):
    """The convergence of one quantity on three grids (see the module docstring)."""

    kind: str  # monotone | oscillatory | divergent | constant | undefined
    ratio: float  # R = e21 / e32 (NaN if e32 = 0)
    order: float  # p
    extrapolated: float  # f_ext
    gci_fine: float  # GCI of the finest grid, a fraction of |f1|


def _order(growth: float, r21: float, r32: float) -> float:
    """The p > 0 with r21^p (r32^p - 1) / (r21^p - 1) = growth (bisection; the left side
    rises from ln r32 / ln r21 at p = 0)."""

    def phi(p: float) -> float:
        return r21**p * math.expm1(p * math.log(r32)) / math.expm1(p * math.log(r21))

    lo, hi = 0.0, 1.0
    while phi(hi) < growth:
        lo, hi = hi, 2.0 * hi
        if hi > _MAX_ORDER:
            return _MAX_ORDER
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if phi(mid) < growth else (lo, mid)
    return 0.5 * (lo + hi)


def grid_study(f1: float, f2: float, f3: float, r: float, r32: float | None = None) -> GridStudy:
    """Observed order, Richardson extrapolation and GCI from f1 (fine), f2, f3 (coarse).

    ``r`` > 1 is the element-size ratio h2 / h1 and ``r32`` (default ``r``) the ratio h3 / h2.
    A NaN input gives kind ``undefined``; equal values give kind ``constant`` (f_ext = f1,
    GCI 0).
    """
    r21 = r
    r32 = r if r32 is None or abs(r32 - r) <= 1e-12 * r else r32
    if not (r21 > 1 and r32 > 1):
        raise ValueError(f"the refinement ratios must exceed 1, got {r21!r} and {r32!r}")
    nan = math.nan
    if not all(math.isfinite(f) for f in (f1, f2, f3)):
        return GridStudy("undefined", nan, nan, nan, nan)
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0 and e32 == 0:
        return GridStudy("constant", nan, nan, f1, 0.0)
    if e32 == 0:
        return GridStudy("divergent", nan, nan, nan, nan)
    R = e21 / e32
    if R < 0:
        return GridStudy("oscillatory", R, nan, nan, nan)
    if R == 0:  # the two finest agree exactly: converged at f1
        return GridStudy("monotone", R, math.inf, f1, 0.0)
    growth = 1.0 / R
    # Equal ratios: the closed form (and exactly R < 1 as the monotone test).
    if r21 == r32:
        if R >= 1:
            return GridStudy("divergent", R, nan, nan, nan)
        p = math.log(growth) / math.log(r21)
    else:
        if growth <= math.log(r32) / math.log(r21):
            return GridStudy("divergent", R, nan, nan, nan)
        p = _order(growth, r21, r32)
    gain = r21**p - 1.0
    f_ext = f1 + (f1 - f2) / gain
    gci = SAFETY_FACTOR * abs((f1 - f2) / f1) / gain if f1 != 0 else nan
    return GridStudy("monotone", R, p, f_ext, gci)


def grid_studies(values: Sequence[float], r: float | Sequence[float]) -> list[GridStudy]:
    """`grid_study` of each consecutive triple of ``values`` ordered coarse to fine: entry k
    uses levels k, k+1, k+2 (the last entry is the finest triple). ``r`` is the constant
    element-size ratio between levels, or the element sizes of the levels (coarse to fine,
    strictly decreasing)."""
    v = [float(x) for x in values]
    if isinstance(r, (int, float)):
        return [grid_study(v[k + 2], v[k + 1], v[k], float(r)) for k in range(len(v) - 2)]
    h = [float(x) for x in r]
    if len(h) != len(v):
        raise ValueError(f"{len(v)} values but {len(h)} element sizes")
    return [
        grid_study(v[k + 2], v[k + 1], v[k], h[k + 1] / h[k + 2], h[k] / h[k + 1])
        for k in range(len(v) - 2)
    ]

"""Grid convergence of a quantity on systematically refined meshes (pure Python + math).

Three solutions f1 (finest), f2, f3 (coarsest) on grids whose element size shrinks by the
constant ratio r > 1 per level (Roache 1998; Celik et al. 2008):

- differences e21 = f2 - f1, e32 = f3 - f2 and their ratio R = e21 / e32: monotone
  convergence for 0 < R < 1, oscillatory for R < 0, divergence for R >= 1;
- observed order p = ln(e32 / e21) / ln r (monotone convergence only);
- Richardson extrapolation f_ext = f1 + (f1 - f2) / (r^p - 1);
- grid convergence index of the finest grid GCI = Fs |(f1 - f2) / f1| / (r^p - 1), with the
  safety factor Fs = 1.25 for three or more grids: a band around f1 (a fraction) that holds
  the grid-independent value with about 95 % confidence.

Outside monotone convergence p, f_ext and GCI are NaN and ``kind`` says why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

__all__ = ["SAFETY_FACTOR", "GridStudy", "grid_study", "grid_studies"]

SAFETY_FACTOR = 1.25  # Roache's Fs for three or more grids


class GridStudy(NamedTuple):
    """The convergence of one quantity on three grids (see the module docstring)."""

    kind: str  # monotone | oscillatory | divergent | constant | undefined
    ratio: float  # R = e21 / e32 (NaN if e32 = 0)
    order: float  # p
    extrapolated: float  # f_ext
    gci_fine: float  # GCI of the finest grid, a fraction of |f1|


def grid_study(f1: float, f2: float, f3: float, r: float) -> GridStudy:
    """Observed order, Richardson extrapolation and GCI from f1 (fine), f2, f3 (coarse).

    ``r`` > 1 is the element-size ratio between consecutive grids. A NaN input gives kind
    ``undefined``; equal values give kind ``constant`` (f_ext = f1, GCI 0).
    """
    if not r > 1:
        raise ValueError(f"the refinement ratio must exceed 1, got {r!r}")
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
    if R >= 1:
        return GridStudy("divergent", R, nan, nan, nan)
    if R == 0:  # the two finest agree exactly: converged at f1
        return GridStudy("monotone", R, math.inf, f1, 0.0)
    p = math.log(1.0 / R) / math.log(r)
    gain = r**p - 1.0
    f_ext = f1 + (f1 - f2) / gain
    gci = SAFETY_FACTOR * abs((f1 - f2) / f1) / gain if f1 != 0 else nan
    return GridStudy("monotone", R, p, f_ext, gci)


def grid_studies(values: Sequence[float], r: float) -> list[GridStudy]:
    """`grid_study` of each consecutive triple of ``values`` ordered coarse to fine: entry k
    uses levels k, k+1, k+2 (the last entry is the finest triple)."""
    v = [float(x) for x in values]
    return [grid_study(v[k + 2], v[k + 1], v[k], r) for k in range(len(v) - 2)]

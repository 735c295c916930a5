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

Four or more grids that are not nested scatter about the error's power law, and a triple of
them can look oscillatory when the law still holds. `fit_study` then fits the law to all
of them by least squares (after Eca and Hoekstra 2014, J. Comput. Phys. 262: 104-130), with
the element sizes h_i:

- the power law f_i = f0 + a h_i^p (p by a scan and golden-section refinement, f0 and a by
  linear least squares at each p): monotone convergence for p > 0, divergence for p <= 0,
  unless the data scatter (below);
- when 0.5 <= p < 2.1 that fit is the estimate, with Fs = 1.25; otherwise the fixed-order
  fits f0 + a h and f0 + a h^2 are made and the one with the smaller standard deviation is
  the estimate, with Fs = 3 (Eca and Hoekstra also try f0 + a h + b h^2, which can turn
  back inside the data and put f0 on the wrong side of them);
- the fit's standard deviation sigma = sqrt(SS / (n - k)) (k its number of parameters) and
  the data range D = (max f - min f) / (n - 1);
- when the power law's sigma >= D no trend stands above the scatter, whatever p: kind
  ``scattered``, the limit is the levels' mean, sigma their standard deviation and
  U_i = |f_i - mean| + 2 sigma (this case is ours, not Eca and Hoekstra's);
- otherwise the uncertainty of level i, with its error estimate e_i = |fit(h_i) - f0|:
  U_i = Fs e_i + sigma + |f_i - fit(h_i)|, or 3 sigma / D (e_i + sigma + |f_i - fit(h_i)|)
  when the estimate's sigma >= D (``scattered`` true).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

__all__ = ["SAFETY_FACTOR", "FitStudy", "GridStudy", "fit_study", "grid_study", "grid_studies"]

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


# Least-squares fits (`fit_study`).
FIT_SAFETY_FACTOR = 3.0  # Fs of a fixed-order fit (the observed order is not trusted)
FIT_ORDER_RANGE = (0.5, 2.1)  # observed orders whose power-law fit is the estimate
_ORDER_SCAN = (-4.0, 8.0, 481)  # p scanned on this grid (bounds, points), then refined
# Values that differ by less than this (relative to max(1, |f|)) are equal: e.g. a stage-2
# closure gap of 1e-16 mm at every level.
_ROUNDOFF = 1e-12


class FitStudy(NamedTuple):
    """The least-squares convergence of one quantity on four or more grids (module docstring)."""

    kind: str  # monotone | scattered | divergent | constant | undefined
    fit: str  # power | order 1 | order 2 | mean (the estimate's form; "" if none)
    order: float  # p of the power-law fit
    extrapolated: float  # f0 of the estimate
    sigma: float  # standard deviation of the estimate's residuals
    scattered: bool  # the estimate's sigma >= the data range D
    safety_factor: float  # Fs (NaN for the mean of scattered data)
    uncertainty: tuple[float, ...]  # U_i per level (same units as the values), coarse to fine


def _linear_fit(columns: list[list[float]], f: list[float]) -> tuple[list[float], float]:
    """Least-squares coefficients of f ~ sum_j c_j columns[j] and the residual sum of squares
    (normal equations, solved by Gaussian elimination; at most 3 columns)."""
    k = len(columns)
    a = [[sum(x * y for x, y in zip(columns[i], columns[j])) for j in range(k)] for i in range(k)]
    b = [sum(x * y for x, y in zip(columns[i], f)) for i in range(k)]
    for i in range(k):
        piv = max(range(i, k), key=lambda r: abs(a[r][i]))
        a[i], a[piv], b[i], b[piv] = a[piv], a[i], b[piv], b[i]
        if abs(a[i][i]) < 1e-300:
            return [math.nan] * k, math.inf
        for r in range(i + 1, k):
            m = a[r][i] / a[i][i]
            a[r] = [x - m * y for x, y in zip(a[r], a[i])]
            b[r] -= m * b[i]
    c = [0.0] * k
    for i in reversed(range(k)):
        c[i] = (b[i] - sum(a[i][j] * c[j] for j in range(i + 1, k))) / a[i][i]
    fit = [sum(c[j] * columns[j][n] for j in range(k)) for n in range(len(f))]
    return c, sum((x - y) ** 2 for x, y in zip(f, fit))


def _power_fit(t: list[float], f: list[float]) -> tuple[float, float, float, float]:
    """(p, f0, a, SS) of the least-squares f0 + a t^p (t scaled so that min t = 1)."""
    ones = [1.0] * len(t)

    def ss(p: float) -> float:
        return _linear_fit([ones, [x**p for x in t]], f)[1] if p != 0 else math.inf

    lo, hi, n = _ORDER_SCAN
    grid = [lo + (hi - lo) * i / (n - 1) for i in range(n)]
    values = [ss(p) for p in grid]
    i = min(range(n), key=values.__getitem__)
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, n - 1)]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - g * (b - a), a + g * (b - a)
    sc, sd = ss(c), ss(d)
    for _ in range(100):  # golden section inside the bracket of the best grid point
        if sc < sd:
            b, d, sd = d, c, sc
            c = b - g * (b - a)
            sc = ss(c)
        else:
            a, c, sc = c, d, sd
            d = a + g * (b - a)
            sd = ss(d)
    p = 0.5 * (a + b)
    (f0, amp), res = _linear_fit([ones, [x**p for x in t]], f)
    return p, f0, amp, res


def fit_study(values: Sequence[float], sizes: Sequence[float]) -> FitStudy:
    """Least-squares order, extrapolation and uncertainties of ``values`` (coarse to fine) on
    grids of element sizes ``sizes`` (strictly decreasing); kind ``undefined`` with fewer
    than four values or a NaN."""
    f = [float(v) for v in values]
    h = [float(x) for x in sizes]
    if len(h) != len(f):
        raise ValueError(f"{len(f)} values but {len(h)} element sizes")
    if any(b >= a for a, b in zip(h, h[1:])) or min(h, default=1.0) <= 0:
        raise ValueError("the element sizes must be positive and decrease")
    n, nan = len(f), math.nan
    if n < 4 or not all(math.isfinite(v) for v in f):
        return FitStudy("undefined", "", nan, nan, nan, False, nan, (nan,) * n)
    if max(f) - min(f) <= _ROUNDOFF * max(1.0, max(abs(v) for v in f)):
        return FitStudy("constant", "", nan, f[0], 0.0, False, SAFETY_FACTOR, (0.0,) * n)
    t = [x / h[-1] for x in h]
    p, f0, amp, res = _power_fit(t, f)
    data_range = (max(f) - min(f)) / (n - 1)
    if math.sqrt(res / (n - 3)) >= data_range:  # no trend above the scatter
        mean = sum(f) / n
        sd = math.sqrt(sum((v - mean) ** 2 for v in f) / (n - 1))
        u = tuple(abs(v - mean) + 2 * sd for v in f)
        return FitStudy("scattered", "mean", p, mean, sd, True, nan, u)
    if p <= 0:
        return FitStudy("divergent", "", p, nan, nan, False, nan, (nan,) * n)
    ones = [1.0] * n
    fits: list[tuple[float, str, float, Callable[[float], float]]] = []
    if FIT_ORDER_RANGE[0] <= p < FIT_ORDER_RANGE[1]:
        sigma = math.sqrt(res / (n - 3))
        fits.append((sigma, "power", SAFETY_FACTOR, lambda x: f0 + amp * x**p))
    else:
        for q in (1, 2):
            c, r = _linear_fit([ones, [x**q for x in t]], f)
            sigma = math.sqrt(r / (n - 2))

            def order_model(x: float, c: list[float] = c, q: int = q) -> float:
                return c[0] + c[1] * x**q

            fits.append((sigma, f"order {q}", FIT_SAFETY_FACTOR, order_model))
    sigma, name, fs, model = min(fits, key=lambda item: item[0])
    limit = model(0.0)
    scattered = sigma >= data_range
    unc: list[float] = []
    for x, v in zip(t, f):
        e, dev = abs(model(x) - limit), abs(v - model(x))
        unc.append(
            fs * e + sigma + dev if not scattered else 3 * sigma / data_range * (e + sigma + dev)
        )
    return FitStudy("monotone", name, p, limit, sigma, scattered, fs, tuple(unc))

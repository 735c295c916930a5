"""Von Mises along three lines of the reference configuration (the paper's Figure 2 analysis).

With L the patch half-length, w the wound width, T the total thickness, x = 0 the wound's
edge at the surface and y_c the patch centre (0), each line holds `PROFILE_POINTS` evenly
spaced points:

- ``along_wound``: x = 0, z = 0, y from -L to L (the skin surface on the wound's edge; for the
  excision, whose patch is 2L + l long, over the patch's length, tangent to the outline at its
  widest);
- ``through_thickness``: x = 0, y = 0, z from -T to 0;
- ``across_patch``: y = 0, z = 0, x from -L to L + w (NaN over the wound opening).

Von Mises is constant per P1 cell; a point takes the value of the cell that contains it in
the reference configuration (on a face between cells, the one it lies deepest in).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..core.schema import PROFILE_LINES, PROFILE_POINTS, WOUND_TAGS

if TYPE_CHECKING:
    from .domain import WoundDomain

__all__ = [
    "wound_edge_x",
    "line_maxima",
    "locate_cells",
    "profile_lines",
    "sample_profiles",
]

# The coordinate (x 0, y 1, z 2) that runs along each line.
_AXIS = {"along_wound": 1, "through_thickness": 2, "across_patch": 0}


def profile_lines(points: np.ndarray, x_edge: float | None = None) -> np.ndarray:
    """(3, PROFILE_POINTS, 3) reference coordinates (mm) of the lines in `PROFILE_LINES` order,
    from the patch's bounding box (of the mesh ``points``). ``x_edge``, the wound's edge, is
    by default the bounding box's x_min + L, right for the trenches, whose patch extends L
    beside the wound and along y (`wound_edge_x` gives it for the excision)."""
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    L, y_c, z_top = 0.5 * (hi[1] - lo[1]), 0.5 * (lo[1] + hi[1]), hi[2]
    x_edge = lo[0] + L if x_edge is None else x_edge
    t = np.linspace(0.0, 1.0, PROFILE_POINTS)
    one = np.ones_like(t)
    pts = np.empty((3, PROFILE_POINTS, 3))
    pts[0] = np.c_[x_edge * one, y_c - L + 2 * L * t, z_top * one]
    pts[1] = np.c_[x_edge * one, y_c * one, lo[2] + (z_top - lo[2]) * t]
    pts[2] = np.c_[lo[0] + (hi[0] - lo[0]) * t, y_c * one, z_top * one]
    return pts


def wound_edge_x(points: np.ndarray, facets: np.ndarray, facet_tags: np.ndarray) -> float | None:
    """x of the wound's left edge at the skin surface when the bounding-box rule of
    `profile_lines` misses it (the excision's patch is longer in y than beside the wound);
    None where the rule holds (the trenches) or there is no wound."""
    wound = np.unique(facets[np.isin(facet_tags, WOUND_TAGS)])
    if len(wound) == 0:
        return None
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    p = points[wound]
    edge = float(p[p[:, 2] >= hi[2] - 1e-9 * float(np.ptp(points[:, 2])), 0].min())
    rule = lo[0] + 0.5 * (hi[1] - lo[1])
    return None if abs(edge - rule) <= 1e-6 * float(hi[0] - lo[0]) else edge


def locate_cells(domain: WoundDomain, points: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Index (mesh cell order) of the cell holding each point, -1 where none does.

    Barycentric coordinates from the reference cell maps; the cell whose smallest coordinate
    is largest wins, accepted if that coordinate is >= -tol.
    """
    X0 = domain.X[domain.cell_vertices[:, 0]]
    out = np.full(len(points), -1, dtype=np.int64)
    for i, p in enumerate(np.asarray(points, dtype=float)):
        lam = np.einsum("mij,mj->mi", domain.Dm_inv, p - X0)
        low = np.minimum(lam.min(axis=1), 1.0 - lam.sum(axis=1))
        best = int(np.argmax(low))
        if low[best] >= -tol:
            out[i] = best
    return out


def sample_profiles(cells: np.ndarray, vm: np.ndarray) -> np.ndarray:
    """Cellwise ``vm`` at located points (``cells`` from `locate_cells`, any shape); NaN at -1."""
    vals = np.asarray(vm, dtype=float)[np.maximum(cells, 0)]
    return np.where(cells >= 0, vals, np.nan)


def line_maxima(points: np.ndarray, profiles: np.ndarray) -> dict[str, float]:
    """Per line the largest von Mises (kPa) and the running coordinate (mm) where it is."""
    out: dict[str, float] = {}
    for k, name in enumerate(PROFILE_LINES):
        vals = profiles[k]
        if not np.isfinite(vals).any():
            continue
        i = int(np.nanargmax(vals))
        out[f"profile_{name}_max_kPa"] = float(vals[i])
        out[f"profile_{name}_max_at_mm"] = float(points[k, i, _AXIS[name]])
    return out

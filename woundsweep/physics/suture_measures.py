"""What a sutured (or Dirichlet-closed) state of a fusiform excision measures (docs/model.md,
"Sutures"): the force in each suture, along the wound the surface gap, the contact pressure
and the surface von Mises, and at the apices the dog-ear height.

- Gap: per mirror pair of the zone at the skin surface, x_R - x_L deformed (as
  `woundsweep.physics.closure`), at the pair's reference y.
- Contact pressure: per contact point of the left flank p = k_V (-g) / h (kPa), the largest per
  bin of the closure line's bins along y.
- Surface von Mises: the cell value at `EDGE_OFFSET_mm` outside the wound's edge and below the
  surface, at `EDGE_POINTS` positions along the left edge (reference configuration).
- Dog-ear height: at each apex the largest rise u_z of the top surface's nodes within one wound
  width of it, above the far field (the median u_z of the top nodes on the x faces).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..config.fusiform import Lens
from .closure import ClosureMeasures
from .profiles import locate_cells

if TYPE_CHECKING:
    from .model import WoundModel

__all__ = [
    "EDGE_OFFSET_mm",
    "EDGE_POINTS",
    "SurfacePatch",
    "SutureState",
    "measure_state",
    "surface_patch",
]

EDGE_OFFSET_mm = 0.1
EDGE_POINTS = 61


class SutureState(NamedTuple):
    """One state's measures (mm, mN, kPa)."""

    suture_y_mm: np.ndarray  # (n,) the sutures' y (empty before suturing)
    suture_force_mN: np.ndarray  # (n,) each member's tension
    closure: ClosureMeasures
    gap_y_mm: np.ndarray  # surface pairs, sorted by y
    gap_mm: np.ndarray
    pressure_y_mm: np.ndarray  # bin centres
    contact_pressure_kPa: np.ndarray  # largest per bin (0 without contact)
    edge_y_mm: np.ndarray
    edge_von_mises_kPa: np.ndarray
    dog_ear_mm: tuple[float, float]  # at y = -l/2 and y = +l/2
    max_von_mises_kPa: float

    @property
    def dog_ear_height_mm(self) -> float:
        return float(max(self.dog_ear_mm))


def _dog_ears(model: WoundModel, lens: Lens, u: np.ndarray) -> tuple[float, float]:
    d = model.domain
    X = d.X
    top = np.flatnonzero(np.abs(X[:, 2] - d.z_top) <= 1e-9 * d.ell)
    uz = u.reshape(-1, 3)[:, 2]
    far = np.intersect1d(top, d.x_face_nodes)
    ref = float(np.median(uz[far])) if len(far) else 0.0
    out = []
    for y_apex in (-lens.a, lens.a):
        r = np.hypot(X[top, 0] - lens.x_c, X[top, 1] - y_apex)
        near = top[r <= 2 * lens.b]
        out.append(float(uz[near].max() - ref) if len(near) else float("nan"))
    return out[0], out[1]


def _pressure(model: WoundModel) -> tuple[np.ndarray, np.ndarray]:
    line = model.closure_line
    assert line is not None, "a fusiform excision's model has a closure line"
    edges = line.edges
    centres = 0.5 * (edges[1:] + edges[:-1])
    c = model.contact
    p_bins = np.zeros(len(centres))
    if c is None or c.k_V_kPa <= 0.0:
        return centres, p_bins
    ps = c.passes[0]  # the left flank's points
    gap = c.gaps(model.u)[: len(ps.nodes)]
    depth = np.where(np.isfinite(gap), np.maximum(-gap, 0.0), 0.0)
    p = c.k_V_kPa * depth / ps.size_mm
    y = model.domain.X[ps.nodes, 1]
    idx = np.clip(np.searchsorted(edges, y, side="right") - 1, 0, len(centres) - 1)
    np.maximum.at(p_bins, idx, p)
    return centres, p_bins


def measure_state(
    model: WoundModel, lens: Lens, suture_y_mm: np.ndarray, suture_force_mN: np.ndarray
) -> SutureState:
    """The measures of ``model``'s current state (a `WoundModel` of a fusiform excision) with
    the sutures at ``suture_y_mm`` carrying ``suture_force_mN`` (empty before suturing)."""
    d = model.domain
    u = model.u
    line = model.closure_line
    assert line is not None, "a fusiform excision's model has a closure line"
    m = line.measure(u)
    x = d.X[:, 0] + u.reshape(-1, 3)[:, 0]
    pairs = line.surface
    gy = d.X[pairs[:, 0], 1]
    order = np.argsort(gy)
    gap = (x[pairs[:, 1]] - x[pairs[:, 0]])[order]
    py, pk = _pressure(model)
    ey = np.linspace(-lens.a, lens.a, EDGE_POINTS + 2)[1:-1]
    ex = np.array([lens.x_c - lens.half_width(y) - EDGE_OFFSET_mm for y in ey])
    pts = np.column_stack([ex, ey, np.full_like(ey, d.z_top - EDGE_OFFSET_mm)])
    cells = locate_cells(d, pts)
    vm = model.forms.von_mises_cells()
    evm = np.where(cells >= 0, vm[np.maximum(cells, 0)], np.nan)
    return SutureState(
        np.asarray(suture_y_mm, dtype=float),
        np.asarray(suture_force_mN, dtype=float),
        m,
        gy[order],
        gap,
        py,
        pk,
        ey,
        evm,
        _dog_ears(model, lens, u),
        float(np.nanmax(vm)),
    )


class SurfacePatch(NamedTuple):
    """The deformed skin surface around the wound, for a picture (mm)."""

    points: np.ndarray  # (k, 3) deformed
    triangles: np.ndarray  # (m, 3) into points
    rise_mm: np.ndarray  # (k,) u_z above the far field
    sutures: np.ndarray  # (n, 2, 3) each suture's bites, deformed


def surface_patch(
    model: WoundModel, lens: Lens, suture_y_mm: np.ndarray, bite_width_mm: float, reach: float = 0.8
) -> SurfacePatch:
    """The top surface's triangles within ``reach`` wound lengths of the wound's centre,
    deformed, with their rise above the far field, and the sutures as segments between the
    top nodes nearest their bites."""
    from ..core.schema import TOP

    d = model.domain
    u = model.displacement_input()
    pts = d.points
    tri = d.facets[d.facet_tags == TOP]
    centre = np.array([lens.x_c, 0.0])
    near = np.all(np.abs(pts[tri][:, :, :2] - centre).max(axis=2) <= reach * 2 * lens.a, axis=1)
    tri = tri[near]
    used, inv = np.unique(tri, return_inverse=True)
    xf = pts[used] + u[used]
    top = np.flatnonzero(np.abs(pts[:, 2] - d.z_top) <= 1e-9 * d.ell)
    tol = 1e-9 * d.ell
    x = pts[top, 0]
    far = top[(np.abs(x - x.min()) <= tol) | (np.abs(x - x.max()) <= tol)]
    ref = float(np.median(u[far, 2])) if len(far) else 0.0
    segs = []
    for y in np.asarray(suture_y_mm, dtype=float):
        half = lens.half_width(y)
        ends = []
        for x in (lens.x_c - half - bite_width_mm, lens.x_c + half + bite_width_mm):
            k = top[np.argmin(np.hypot(pts[top, 0] - x, pts[top, 1] - y))]
            ends.append(pts[k] + u[k])
        segs.append(ends)
    return SurfacePatch(xf, inv.reshape(-1, 3), u[used, 2] - ref, np.array(segs).reshape(-1, 2, 3))

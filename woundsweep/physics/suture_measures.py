"""What a sutured (or Dirichlet-closed) state of a fusiform excision measures (docs/model.md,
"Sutures"): the force in each suture, along the wound the surface gap, the contact pressure
and the surface von Mises, and at the apices the dog-ear height.

- Gap: per mirror pair of the zone at the skin surface, x_R - x_L deformed (as
  `woundsweep.physics.closure`), at the pair's reference y.
- Contact pressure: per contact point of the left flank p = k_V (-g) / h (kPa), the largest per
  bin of the closure line's bins along y.
- Surface von Mises: the cell value at `EDGE_OFFSET_mm` outside the wound's edge and below the
  surface, at `EDGE_POINTS` positions along the left edge (reference configuration).
- Pressure under the bites: per suture, the largest compressive principal Cauchy stress
  (-min eigenvalue, kPa, 0 if none is compressive) at the stress rule's points of the cells
  whose reference centroid lies within the anchor radius of any of its thread's turns, on
  the turn's side (`bite_pressure`).
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
    from .domain import WoundDomain
    from .model import WoundModel

__all__ = [
    "EDGE_OFFSET_mm",
    "EDGE_POINTS",
    "SurfacePatch",
    "SutureState",
    "bite_points",
    "bite_pressure",
    "closest_approach",
    "measure_state",
    "surface_gaps",
    "surface_patch",
    "wound_rim",
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


def surface_gaps(model: WoundModel) -> tuple[np.ndarray, np.ndarray]:
    """The surface pairs' reference y (sorted) and their gaps x_R - x_L (mm) at the current
    state."""
    d, line = model.domain, model.closure_line
    assert line is not None, "a fusiform excision's model has a closure line"
    x = d.X[:, 0] + model.u.reshape(-1, 3)[:, 0]
    pairs = line.surface
    y = d.X[pairs[:, 0], 1]
    order = np.argsort(y)
    return y[order], (x[pairs[:, 1]] - x[pairs[:, 0]])[order]


def closest_approach(
    model: WoundModel, ys: np.ndarray, window_mm: float, depth_mm: float
) -> np.ndarray:
    """Per y in ``ys``: the walls' closest approach (mm) within ``window_mm`` of it along the
    wound and ``depth_mm`` of the surface (reference positions) at the current state. Where
    the right wall is near a point of the left one, the contact's normal gap (a signed
    distance to the right wall's deformed surface, so the flanks' slip along the wound does
    not bias it); elsewhere, and where no contact is modelled, the zone's mirror pairs' gap
    across the wound (x_R - x_L)."""
    d, line = model.domain, model.closure_line
    assert line is not None, "a fusiform excision's model has a closure line"
    X, u = d.X, model.u
    top = d.z_top - depth_mm - 1e-9
    x = X[:, 0] + u.reshape(-1, 3)[:, 0]
    pairs = line.pairs[X[line.pairs[:, 0], 2] >= top]
    py, pgap = X[pairs[:, 0], 1], x[pairs[:, 1]] - x[pairs[:, 0]]
    cy, cgap = np.zeros(0), np.zeros(0)
    c = model.contact
    if c is not None:
        nodes = c.passes[0].nodes  # the left flank's points
        g = c.gaps(u)[: len(nodes)]
        keep = np.isfinite(g) & (X[nodes, 2] >= top)
        cy, cgap = X[nodes[keep], 1], g[keep]
    out = np.empty(len(ys))
    for k, y in enumerate(np.asarray(ys, dtype=float)):
        near = np.abs(cy - y) <= window_mm
        if near.any():
            out[k] = float(cgap[near].min())
            continue
        near = np.abs(py - y) <= window_mm
        if not near.any():  # a window narrower than the pairs' spacing: the nearest pair
            near = np.abs(py - y) == np.abs(py - y).min()
        out[k] = float(pgap[near].min())
    return out


def bite_pressure(model: WoundModel, tracks_mm: np.ndarray, radius_mm: float) -> np.ndarray:
    """Per suture (``tracks_mm`` (n, 2, 2, 3) from `needle_track`), the pressure under its
    bites (module docstring; kPa). The thread's load is spread over the anchor radius, so
    this is the tissue's stress at that spread, not under the 0.2 mm thread itself."""
    d = model.domain
    centroid = d.X[d.cell_vertices].mean(axis=1)
    sigma = model.forms.stress_tensor_samples().cauchy  # (cells, k, 3, 3)
    out = np.zeros(len(tracks_mm))
    for i, track in enumerate(np.asarray(tracks_mm, dtype=float)):
        near = np.zeros(len(centroid), dtype=bool)
        for side, flank in zip((-1.0, 1.0), track):
            on_side = side * (centroid[:, 0] - d.x_c) > 0
            for point in flank:
                near |= on_side & (np.linalg.norm(centroid - point, axis=1) < radius_mm)
        if near.any():
            lowest = np.linalg.eigvalsh(sigma[near])[..., 0]
            out[i] = max(0.0, -float(np.nanmin(lowest)))
    return out


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
    gy, gap = surface_gaps(model)
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
        gy,
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

    points: np.ndarray  # (k, 3) deformed nodes (P2: the edges' midpoint nodes too)
    triangles: np.ndarray  # (m, 3) into points (P2: four flat triangles per facet)
    rise_mm: np.ndarray  # (k,) u_z above the far field
    sutures: np.ndarray  # (n, 2, 3) each suture's bites, deformed
    outline: np.ndarray = np.zeros((0, 2, 3))  # (e, 2, 3) the wound's rim, deformed segments


def wound_rim(domain: WoundDomain) -> np.ndarray:
    """(e, 2) the edges (input point indices) where the top surface meets the wound's walls:
    the excision's outline at the skin surface, both flanks."""
    from ..core.schema import TOP, WOUND_TAGS

    d = domain

    def edges(tri: np.ndarray) -> np.ndarray:
        e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        return np.unique(np.sort(e, axis=1), axis=0)

    top = edges(d.facets[d.facet_tags == TOP])
    wall = edges(d.facets[np.isin(d.facet_tags, WOUND_TAGS)])
    n = len(d.points)
    return top[np.isin(top[:, 0] * n + top[:, 1], wall[:, 0] * n + wall[:, 1])]


def bite_points(
    domain: WoundDomain, lens: Lens, suture_y_mm: np.ndarray, bite_width_mm: float
) -> np.ndarray:
    """(n, 2) per suture the top surface's input points nearest its two bites, ``bite_width_mm``
    outside the wound's edge on either side at the suture's y (reference configuration)."""
    d = domain
    top = np.flatnonzero(np.abs(d.points[:, 2] - d.z_top) <= 1e-9 * d.ell)
    out = []
    for y in np.asarray(suture_y_mm, dtype=float):
        half = lens.half_width(y)
        for x in (lens.x_c - half - bite_width_mm, lens.x_c + half + bite_width_mm):
            out.append(top[np.argmin(np.hypot(d.points[top, 0] - x, d.points[top, 1] - y))])
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)


def surface_patch(
    model: WoundModel, lens: Lens, suture_y_mm: np.ndarray, bite_width_mm: float, reach: float = 0.8
) -> SurfacePatch:
    """The top surface's triangles within ``reach`` wound lengths of the wound's centre,
    deformed (through every node of the element: P2 facets split at their edges' midpoints),
    with their rise above the far field, the sutures as segments between the top nodes
    nearest their bites (`bite_points`) and the wound's rim (`wound_rim`)."""
    from ..core.schema import TOP

    d = model.domain
    u = model.displacement_input()
    U = model.u.reshape(-1, 3)
    pts = d.points
    tri = d.facets[d.facet_tags == TOP]
    centre = np.array([lens.x_c, 0.0])
    near = np.all(np.abs(pts[tri][:, :, :2] - centre).max(axis=2) <= reach * 2 * lens.a, axis=1)
    sub = d.element.sub_triangles(d.input_node[tri[near]])
    used, inv = np.unique(sub, return_inverse=True)
    xf = d.X[used] + U[used]
    top = np.flatnonzero(np.abs(pts[:, 2] - d.z_top) <= 1e-9 * d.ell)
    tol = 1e-9 * d.ell
    x = pts[top, 0]
    far = top[(np.abs(x - x.min()) <= tol) | (np.abs(x - x.max()) <= tol)]
    ref = float(np.median(u[far, 2])) if len(far) else 0.0
    bites = bite_points(d, lens, suture_y_mm, bite_width_mm)
    segs = (pts[bites] + u[bites]).reshape(-1, 2, 3)
    rim = d.input_node[wound_rim(d)]
    if d.element.degree == 2 and len(rim):  # each edge through its midpoint node
        mid = d.element.midpoints(rim[:, 0], rim[:, 1])
        rim = np.concatenate([np.c_[rim[:, 0], mid], np.c_[mid, rim[:, 1]]])
    outline = (d.X + U)[rim].reshape(-1, 2, 3)
    return SurfacePatch(xf, inv.reshape(-1, 3), U[used, 2] - ref, segs, outline)

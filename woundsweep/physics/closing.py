"""The closing tractions of stages 3-6 (docs/model.md, "Closure load"): a uniform traction
that pulls each flank toward the wound's mid-plane, given by its nodal forces per unit
amplitude, and the published code's rule for its amplitude.

A closing traction of amplitude p acts on a wound facet with reference normal n (outward
from the tissue) as p |n_x| along x, toward the mid-plane: a dead load, x only, as the
published code applies it. Its consistent nodal forces on a flat facet of area A: A/3 at
each vertex (P1), A/3 at each edge midpoint and none at the vertices (P2).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..contact.surfaces import triangle_areas
from ..core.schema import DERMIS, WOUND_TAGS, WOUND_ZONE
from .domain import dof_rows
from .materials import first_piola

if TYPE_CHECKING:
    from .domain import WoundDomain
    from .materials import JobMaterials

__all__ = [
    "CODE_FACTOR",
    "CODE_SAMPLES",
    "code_traction_facets",
    "code_traction_kPa",
    "dermal_zone_facets",
    "surface_width",
    "traction_shape",
]

# The published code's amplitude: the largest |P_xx| on its sampling line times 1.3, and
# the form times 1.4 (reference-findings, "The closure as the published code does it").
CODE_FACTOR = 1.3 * 1.4
CODE_SAMPLES = 100


def surface_width(d: WoundDomain) -> float:
    """The wound's opening at the skin surface, w (mm)."""
    wound = np.unique(d.wound_facets())
    top = wound[np.abs(d.X[wound, 2] - d.z_top) <= 1e-9 * d.ell]
    return float(np.ptp(d.X[top, 0]))


def _wound_facets(d: WoundDomain, tags: tuple[int, ...]) -> np.ndarray:
    """Wound facets (k, 3 vertex nodes) with one of ``tags``."""
    return d.input_node[d.facets[np.isin(d.facet_tags, tags)]]


def code_traction_facets(d: WoundDomain) -> np.ndarray:
    """The published code's traction region: the wound facets within half the patch's
    half-length of its centre along y and less than w below the surface (centroids)."""
    tri = _wound_facets(d, WOUND_TAGS)
    c = d.X[tri].mean(axis=1)
    keep = (np.abs(c[:, 1] - d.y_c) < 0.5 * d.half_length_y) & (
        d.z_top - c[:, 2] < surface_width(d)
    )
    return tri[keep]


def dermal_zone_facets(d: WoundDomain) -> np.ndarray:
    """The closure zone's facets in the dermis (centroid above the dermis' lower face)."""
    tri = _wound_facets(d, (WOUND_ZONE,))
    z_dermis = float(d.points[d.cells[d.cell_tags == DERMIS]][..., 2].min())
    return tri[d.X[tri].mean(axis=1)[:, 2] >= z_dermis]


def traction_shape(d: WoundDomain, tri: np.ndarray) -> np.ndarray:
    """Nodal forces (flat dofs, mN per kPa) of a unit closing traction on the facets ``tri``
    (k, 3 vertex nodes; module docstring)."""
    tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
    f = np.zeros(d.n_dofs)
    if len(tri) == 0:
        return f
    p = d.X[tri]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    toward = np.sign(d.x_c - p.mean(axis=1)[:, 0])  # +1 on the left flank
    share = triangle_areas(p) * np.abs(normal[:, 0]) * toward / 3.0
    if d.degree == 1:
        nodes = tri
    else:
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        el = d.element
        nodes = np.stack([el.midpoints(a, b), el.midpoints(b, c), el.midpoints(c, a)], axis=1)
    np.add.at(f, dof_rows(nodes.ravel(), 0), np.repeat(share, 3))
    return f


def code_traction_kPa(d: WoundDomain, u: np.ndarray, materials: JobMaterials) -> float:
    """The published code's amplitude at the displacement ``u`` (its stage-2 state):
    `CODE_FACTOR` times the largest |P_xx| at `CODE_SAMPLES` points on the surface line
    y = y_c from the patch's edge to the left flank's edge (just below the surface), each
    the cell mean of P_xx of the cell holding the point."""
    from .profiles import locate_cells

    lo = float(d.bbox[0][0])
    edge = d.x_c - 0.5 * surface_width(d)
    depth = 1e-6 * (d.z_top - float(d.bbox[0][2]))
    x = np.linspace(lo, edge, CODE_SAMPLES)
    pts = np.column_stack([x, np.full_like(x, d.y_c), np.full_like(x, d.z_top - depth)])
    cells = locate_cells(d, pts)
    cells = cells[cells >= 0]
    grads = d.grad(u).reshape(len(d.cells), -1, 3, 3)  # P2: the rule's points per cell
    largest = 0.0
    for cell in np.unique(cells):
        F = np.eye(3) + grads[cell].mean(axis=0)
        tag = d.cell_tags[d.cell_input[cell]]
        mat = materials.dermis if tag == DERMIS else materials.subcutis
        largest = max(largest, abs(float(first_piola(mat, F)[0, 0])))
    return CODE_FACTOR * largest

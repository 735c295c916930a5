"""Mesh geometry the viewers need, in numpy: the closure zone's facets, the exterior surface
with its cellwise stress, the zone's outline and the deformed location of the maximum.

`closure_zone_facets` applies `ClosureZone`'s rule to the mesh arrays the way the solver's
`WoundDomain` does (the same facets; a fem test compares them), so the viewers need no DOLFINx.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..contact.geometry import owning_cells
from ..schema import WOUND

__all__ = ["Surface", "closure_zone_facets", "max_cell_point", "surface_of", "zone_outline"]


def closure_zone_facets(
    points: np.ndarray, facets: np.ndarray, facet_tags: np.ndarray, zone: Any
) -> np.ndarray:
    """Mask over ``facets``: wound facets whose three nodes lie in the closure zone.

    The zone: |y - y_c| <= y_fraction * L_y (y_c, L_y the patch's centre and half length in
    y) and z >= z_top - depth_fraction * depth (depth from the top to the wound's lowest node).
    """
    wound = facet_tags == WOUND
    mask = np.zeros(len(facets), dtype=bool)
    if not wound.any():
        return mask
    lo, hi = points.min(axis=0), points.max(axis=0)
    tol = 1e-9 * float(np.linalg.norm(hi - lo))
    y_c, half_y, z_top = 0.5 * (lo[1] + hi[1]), 0.5 * (hi[1] - lo[1]), float(hi[2])
    wound_pts = np.unique(facets[wound])
    depth = z_top - points[wound_pts, 2].min()
    y_lim = zone.y_fraction * half_y + tol
    z_lim = z_top - zone.depth_fraction * depth - tol
    in_zone = np.zeros(len(points), dtype=bool)
    p = points[wound_pts]
    in_zone[wound_pts] = (np.abs(p[:, 1] - y_c) <= y_lim) & (p[:, 2] >= z_lim)
    mask[wound] = np.all(in_zone[facets[wound]], axis=1)
    return mask


class Surface(NamedTuple):
    """The exterior triangles in a compact numbering of their own nodes."""

    nodes: np.ndarray  # (s,) indices into the mesh points
    triangles: np.ndarray  # (k, 3) indices into ``nodes``
    owner: np.ndarray  # (k,) the cell each triangle is a face of
    zone: np.ndarray  # (k,) bool, closure zone


def surface_of(
    points: np.ndarray, cells: np.ndarray, facets: np.ndarray, zone: np.ndarray
) -> Surface:
    """The exterior surface of the mesh, each triangle with the cell it bounds."""
    nodes, inverse = np.unique(facets, return_inverse=True)
    triangles = inverse.reshape(facets.shape).astype(np.int32)
    owner = owning_cells(cells, facets, len(points))
    return Surface(nodes.astype(np.int64), triangles, owner, np.asarray(zone, bool))


def zone_outline(triangles: np.ndarray, zone: np.ndarray) -> np.ndarray:
    """Edges (e, 2) on the border of the zone's triangles (an edge of exactly one of them)."""
    tri = triangles[zone]
    if len(tri) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    return uniq[count == 1]


def max_cell_point(
    points: np.ndarray, cells: np.ndarray, u: np.ndarray, vm: np.ndarray
) -> tuple[int, np.ndarray, np.ndarray]:
    """The cell of the largest von Mises, its reference and its deformed midpoint (mm)."""
    i = int(np.nanargmax(vm))
    ref = points[cells[i]].mean(axis=0)
    return i, ref, ref + np.asarray(u, float)[cells[i]].mean(axis=0)

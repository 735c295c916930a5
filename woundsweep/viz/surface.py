"""Mesh geometry the viewers need, in numpy: the closure zone's facets, the exterior surface
with its cellwise stress, the zone's outline and the deformed location of the maximum.

The closure zone is the mesh's own facet tag (`woundsweep.core.schema.WOUND_ZONE`), the facets the
solver's `WoundDomain` uses (a fem test compares them), so the viewers need no DOLFINx.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..contact.geometry import owning_cells
from ..core.schema import WOUND_ZONE

__all__ = [
    "ExteriorSurface",
    "PlaneSlice",
    "closure_zone_facets",
    "max_cell_point",
    "plane_slice",
    "surface_of",
    "zone_outline",
]


def closure_zone_facets(facet_tags: np.ndarray) -> np.ndarray:
    """Mask over the facets: the closure zone's, tagged ``WOUND_ZONE`` by the mesh."""
    return np.asarray(facet_tags) == WOUND_ZONE


class ExteriorSurface(NamedTuple):
    """The exterior triangles in a compact numbering of their own nodes."""

    nodes: np.ndarray  # (s,) indices into the mesh points
    triangles: np.ndarray  # (k, 3) indices into ``nodes``
    owner: np.ndarray  # (k,) the cell each triangle is a face of
    zone: np.ndarray  # (k,) bool, closure zone


def surface_of(
    points: np.ndarray, cells: np.ndarray, facets: np.ndarray, zone: np.ndarray
) -> ExteriorSurface:
    """The exterior surface of the mesh, each triangle with the cell it bounds."""
    nodes, inverse = np.unique(facets, return_inverse=True)
    triangles = inverse.reshape(facets.shape).astype(np.int32)
    owner = owning_cells(cells, facets, len(points))
    return ExteriorSurface(nodes.astype(np.int64), triangles, owner, np.asarray(zone, bool))


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


class PlaneSlice(NamedTuple):
    """The cut of a tetrahedral mesh by a plane: its points on mesh edges and triangles."""

    edge_a: np.ndarray  # (e,) mesh node at one end of each cut edge
    edge_b: np.ndarray  # (e,) the other end
    edge_t: np.ndarray  # (e,) the point is (1 - t) x_a + t x_b
    triangles: np.ndarray  # (k, 3) indices into the edges
    owner: np.ndarray  # (k,) the tetrahedron each triangle lies in


def plane_slice(points: np.ndarray, cells: np.ndarray, axis: int, value: float) -> PlaneSlice:
    """The cut of the tetrahedra by the plane ``x[axis] = value`` (reference configuration):
    a triangle where one vertex is alone on its side, two where the sides split two-two."""
    d = np.asarray(points, float)[:, axis] - value
    side = d[cells] > 0
    n_pos = side.sum(axis=1)
    edges: dict[tuple[int, int], int] = {}
    ea: list[int] = []
    eb: list[int] = []
    tris: list[list[int]] = []
    owner: list[int] = []

    def edge(a: int, b: int) -> int:
        key = (a, b) if a < b else (b, a)
        if key not in edges:
            edges[key] = len(ea)
            ea.append(key[0])
            eb.append(key[1])
        return edges[key]

    for c in np.flatnonzero((n_pos > 0) & (n_pos < 4)):
        v = [int(x) for x in cells[c]]
        pos = [x for x, s in zip(v, side[c]) if s]
        neg = [x for x, s in zip(v, side[c]) if not s]
        if len(pos) == 2:  # a quadrilateral p0-n0, p0-n1, p1-n1, p1-n0
            q = [
                edge(pos[0], neg[0]),
                edge(pos[0], neg[1]),
                edge(pos[1], neg[1]),
                edge(pos[1], neg[0]),
            ]
            tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
            owner += [int(c), int(c)]
        else:
            lone, rest = (pos[0], neg) if len(pos) == 1 else (neg[0], pos)
            tris.append([edge(lone, r) for r in rest])
            owner.append(int(c))
    a, b = np.asarray(ea, np.int64), np.asarray(eb, np.int64)
    t = d[a] / (d[a] - d[b]) if len(a) else np.zeros(0)
    return PlaneSlice(
        a, b, t, np.asarray(tris, np.int64).reshape(-1, 3), np.asarray(owner, np.int64)
    )

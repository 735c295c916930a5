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

__all__ = ["ExteriorSurface", "closure_zone_facets", "max_cell_point", "surface_of", "zone_outline"]


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

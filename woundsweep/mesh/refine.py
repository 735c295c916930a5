"""Uniform refinement of a `MeshData`: every tetrahedron into eight, every facet into four.

The new nodes are the edges' midpoints, so the refined mesh is nested in the coarse one
(every coarse node and face is kept) and its element sizes are half the coarse ones: a
sequence of refinements is systematic in the strict sense the grid convergence index
assumes. Each tetrahedron keeps its four corner tetrahedra; the octahedron left inside is
cut along its shortest diagonal, which keeps the shapes from degrading over repeated
refinements. Tags pass to the children. The boundary stays the coarse mesh's: a curved
wound keeps its facets, so the refined levels converge to the faceted geometry's solution.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..core.errors import GeometryError
from .build import MeshData, signed_volumes
from .sizing import MAX_CELLS

__all__ = ["refine_uniform"]

# The six edges of a tetrahedron (local vertex pairs), in the order of the midpoints below.
_EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])


def _midpoints(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, Callable]:
    """The points with the edges' midpoints appended, each cell's six midpoint node numbers
    (in `_EDGES` order) and a function (nodes p, q) -> the midpoint node of each edge p-q."""
    edges = np.sort(cells[:, _EDGES], axis=2).reshape(-1, 2)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    first = len(points)
    new_points = np.vstack([points, 0.5 * (points[unique[:, 0]] + points[unique[:, 1]])])
    # np.unique sorts the edges lexicographically, so their (low, high) keys are sorted too.
    keys = unique[:, 0] * first + unique[:, 1]

    def midpoint(p: np.ndarray, q: np.ndarray) -> np.ndarray:
        return first + np.searchsorted(keys, np.minimum(p, q) * first + np.maximum(p, q))

    return new_points, first + inverse.reshape(-1, 6), midpoint


def _children(points: np.ndarray, cells: np.ndarray, mid: np.ndarray) -> np.ndarray:
    """(cells, 8, 4): the four corner tetrahedra and the octahedron's four, around its
    shortest diagonal."""
    v0, v1, v2, v3 = cells.T
    m01, m02, m03, m12, m13, m23 = mid.T
    corners = [
        np.c_[v0, m01, m02, m03],
        np.c_[m01, v1, m12, m13],
        np.c_[m02, m12, v2, m23],
        np.c_[m03, m13, m23, v3],
    ]
    # Each diagonal joins opposite midpoints; the other four ring it, neighbours sharing a
    # vertex of the parent.
    rings = (
        (m01, m23, (m02, m03, m13, m12)),
        (m02, m13, (m01, m03, m23, m12)),
        (m03, m12, (m01, m02, m23, m13)),
    )
    lengths = np.stack([np.linalg.norm(points[a] - points[b], axis=1) for a, b, _ in rings], 1)
    shortest = lengths.argmin(axis=1)
    inner = np.zeros((len(cells), 4, 4), dtype=np.int64)
    for k, (a, b, ring) in enumerate(rings):
        sel = shortest == k
        for i in range(4):
            inner[sel, i] = np.c_[a, b, ring[i], ring[(i + 1) % 4]][sel]
    return np.concatenate([np.stack(corners, axis=1), inner], axis=1)


def refine_uniform(mesh: MeshData) -> MeshData:
    """The mesh with every cell split into eight and every facet into four (tags kept;
    children positively oriented; ``info`` copied with the new cell count). GeometryError
    when the refined mesh would exceed `sizing.MAX_CELLS` cells (before anything is built)."""
    if 8 * len(mesh.cells) > MAX_CELLS:
        raise GeometryError(
            f"a uniform refinement of {len(mesh.cells):,} cells gives {8 * len(mesh.cells):,}, "
            f"above the cap of {MAX_CELLS:,}"
        )
    points, mid, midpoint = _midpoints(mesh.points, mesh.cells)
    cells = _children(points, mesh.cells, mid).reshape(-1, 4)
    flip = signed_volumes(points, cells) < 0
    cells[flip] = cells[flip][:, [1, 0, 2, 3]]
    a, b, c = mesh.facets.T
    ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
    # The corner triangles keep the parent's orientation, as does the middle one.
    facets = np.stack(
        [np.c_[a, ab, ca], np.c_[ab, b, bc], np.c_[ca, bc, c], np.c_[ab, bc, ca]], axis=1
    ).reshape(-1, 3)
    info = dict(mesh.info)
    info["cells"] = len(cells)
    info["refinements"] = int(info.get("refinements", 0)) + 1
    return MeshData(
        points,
        cells,
        np.repeat(mesh.cell_tags, 8).astype(mesh.cell_tags.dtype),
        facets.astype(np.int64),
        np.repeat(mesh.facet_tags, 4).astype(mesh.facet_tags.dtype),
        info,
    )

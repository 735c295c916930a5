"""Structured tetrahedral meshes of the verification cases, as `MeshData` (numpy only).

Every box is a tensor grid whose boxes are split into six tetrahedra around their main
diagonal (Kuhn), so two grids that share a face triangulate it alike. Facet tags follow the
mesh contract (`woundsweep.core.schema`): X_MIN .. TOP on a box's faces, WOUND_ZONE on a
slit's walls; the cell tag selects the material (DERMIS: Fung, SUBCUTIS: Mooney-Rivlin).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..core.schema import BOTTOM, TOP, WOUND_ZONE, X_MAX, X_MIN, Y_MAX, Y_MIN, MeshData

__all__ = [
    "boundary_facets",
    "grid_tets",
    "join",
    "mirrored",
    "retagged",
    "slab",
    "slit_walls",
    "unit_cube",
]

_KUHN = ((0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6))
_CORNERS = ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))


def grid_tets(xs: np.ndarray, ys: np.ndarray, zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tensor grid of the coordinate arrays, each grid box split into six tetrahedra.
    Returns (points (n, 3), cells (m, 4))."""
    nx, ny, nz = len(xs) - 1, len(ys) - 1, len(zs) - 1
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]

    def idx(i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        return (i * (ny + 1) + j) * (nz + 1) + k

    ii, jj, kk = (a.ravel() for a in np.meshgrid(range(nx), range(ny), range(nz), indexing="ij"))
    V = np.stack([idx(ii + a, jj + b, kk + c) for a, b, c in _CORNERS], axis=1)
    return pts, np.concatenate([V[:, list(t)] for t in _KUHN]).astype(np.int64)


def boundary_facets(cells: np.ndarray) -> np.ndarray:
    """The faces that belong to one cell only (k, 3)."""
    faces = np.concatenate(
        [cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]], cells[:, [0, 1, 2]]]
    )
    uniq, count = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    return uniq[count == 1]


def _face_tags(pts: np.ndarray, facets: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """X_MIN .. TOP for the facets on the faces of the box [lo, hi], 0 for the others."""
    c = pts[facets].mean(axis=1)
    tol = 1e-9 * float(np.max(hi - lo))
    tags = np.zeros(len(facets), dtype=np.int32)
    for axis, (t_lo, t_hi) in enumerate(((X_MIN, X_MAX), (Y_MIN, Y_MAX), (BOTTOM, TOP))):
        tags[np.abs(c[:, axis] - lo[axis]) < tol] = t_lo
        tags[np.abs(c[:, axis] - hi[axis]) < tol] = t_hi
    return tags


def slab(
    xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, cell_tag: Callable[[np.ndarray], np.ndarray]
) -> MeshData:
    """The grid box of the coordinate arrays, its faces tagged X_MIN .. TOP, each cell tagged
    by ``cell_tag(midpoints)``."""
    pts, cells = grid_tets(np.asarray(xs), np.asarray(ys), np.asarray(zs))
    facets = boundary_facets(cells)
    tags = _face_tags(pts, facets, pts.min(axis=0), pts.max(axis=0))
    ctags = np.asarray(cell_tag(pts[cells].mean(axis=1)), dtype=np.int32)
    return MeshData(pts, cells, ctags, facets, tags, {})


def unit_cube(n: int, cell_tag: int) -> MeshData:
    """[0, 1]^3 in n^3 grid boxes (6 n^3 cells), every cell tagged ``cell_tag``."""
    s = np.linspace(0.0, 1.0, n + 1)
    return slab(s, s, s, lambda mid: np.full(len(mid), cell_tag))


def join(
    parts: Sequence[MeshData], retag: Callable[[np.ndarray, np.ndarray], np.ndarray]
) -> MeshData:
    """Disjoint bodies as one mesh (their nodes not shared). ``retag(centroids, tags)`` gives
    the joined mesh's facet tags from each facet's centroid and its body's tag; facets it
    tags 0 are left out."""
    pts, cells, ctags, facets, ftags, first = [], [], [], [], [], 0
    for p in parts:
        pts.append(p.points)
        cells.append(p.cells + first)
        ctags.append(p.cell_tags)
        facets.append(p.facets + first)
        ftags.append(p.facet_tags)
        first += len(p.points)
    P, F = np.vstack(pts), np.vstack(facets)
    tags = np.asarray(retag(P[F].mean(axis=1), np.concatenate(ftags)), dtype=np.int32)
    keep = tags > 0
    return MeshData(P, np.vstack(cells), np.concatenate(ctags), F[keep], tags[keep], {})


def slit_walls(mesh: MeshData, x_walls: tuple[float, float]) -> MeshData:
    """``mesh`` with its facets on the planes x = x_walls tagged WOUND_ZONE."""
    c = mesh.points[mesh.facets].mean(axis=1)[:, 0]
    tags = mesh.facet_tags.copy()
    for x in x_walls:
        tags[np.abs(c - x) < 1e-12 + 1e-9 * abs(x)] = WOUND_ZONE
    return mesh._replace(facet_tags=tags)


def mirrored(mesh: MeshData, axis: int, at: float, *, merge: bool) -> MeshData:
    """``mesh`` and its mirror image about the plane x_axis = ``at`` as one mesh: the nodes
    on the plane shared (``merge``) or the two bodies disjoint. The image's cells are the
    mirror images of the original's, so the mesh maps onto itself (a Kuhn grid mirrored
    does not: its diagonals turn). Facets: the boundary, tagged by `retagged`."""
    pts = mesh.points.copy()
    pts[:, axis] = 2.0 * at - pts[:, axis]
    cells = mesh.cells[:, [1, 0, 2, 3]]  # orientation kept
    P = np.vstack([mesh.points, pts])
    C = np.vstack([mesh.cells, cells + len(mesh.points)])
    if merge:
        scale = float(np.ptp(P, axis=0).max())
        key = np.round(P / (1e-9 * scale)).astype(np.int64)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        P, C = P[first], inverse.ravel()[C]
    tags = np.concatenate([mesh.cell_tags, mesh.cell_tags])
    return retagged(MeshData(P, C.astype(np.int64), tags, np.zeros((0, 3), np.int64),
                             np.zeros(0, np.int32), {}))  # fmt: skip


def retagged(mesh: MeshData) -> MeshData:
    """``mesh`` with its boundary facets, tagged X_MIN .. TOP on its bounding box's faces
    and 0 elsewhere."""
    facets = boundary_facets(mesh.cells)
    tags = _face_tags(mesh.points, facets, mesh.points.min(axis=0), mesh.points.max(axis=0))
    return mesh._replace(facets=facets, facet_tags=tags)

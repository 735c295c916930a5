"""Independent interpenetration audit: flank nodes inside the other side's deformed tissue.

The contact (`woundsweep.contact.smooth`) measures penetration on smooth implicit surfaces of
the flanks; this audit uses only the deformed mesh, so it can catch what that surface misses
(a node past a master's rim, through a thin fade, or deep enough to leave the kernel).

A flank node of one side is *inside* the other side's tissue when its deformed position lies
in a deformed tetrahedron of that side's cells (barycentric coordinates >= -1e-9). Its
*depth* is the Euclidean distance from the point to the nearest of a set of deformed
triangles of the other side: by default the whole boundary of its cells (the faces its cells
do not share among themselves, the interface under the wound included: the distance the
node would have to move to get out), in `audit_model` that side's flank (the penetration
through the wound surface, as the contact's -g measures it; a node that crossed the flank
near the skin is then not hidden by the nearby skin surface). The distance to the nearest
face of the containing tetrahedron is not used: it is capped by the cell's size and is near
0 for a deep node close to an interior face. A node is counted when its depth exceeds
``depth_tol_mm``; nodes of the other side's cells (shared nodes, where the flanks meet) are
on its surface and never counted.

Cells are straight tetrahedra through their vertices; a P2 mesh's cells are split into eight
through their ten nodes (`linear_cells`), as the contact splits the P2 facets into four.

Units: mm.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = ["AuditResult", "P2_SUB_TETS", "audit_interpenetration", "audit_model", "linear_cells"]

# The eight straight tetrahedra through a P2 cell's ten nodes (vertices 0-3, then the edge
# midpoints in `woundsweep.physics.element.EDGES` order: 4 = (2,3), 5 = (1,3), 6 = (1,2),
# 7 = (0,3), 8 = (0,2), 9 = (0,1)): four corner tetrahedra and the inner octahedron cut along
# its diagonal (0,1)-(2,3).
P2_SUB_TETS = np.array(
    [[0, 9, 8, 7], [1, 9, 6, 5], [2, 8, 6, 4], [3, 7, 5, 4],
     [9, 4, 8, 7], [9, 4, 7, 5], [9, 4, 5, 6], [9, 4, 6, 8]],
    dtype=np.int64,
)  # fmt: skip

_BARY_TOL = 1e-9  # a point on a face (within rounding) counts as inside, at depth ~0
_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


class AuditResult(NamedTuple):
    """Flank nodes inside the other side's deformed tissue."""

    n_inside: int  # nodes deeper than the tolerance (both sides)
    max_depth_mm: float  # largest depth of any inside node (counted or not; 0 if none)
    nodes: np.ndarray  # the counted nodes' indices


def _triple(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, np.cross(b, c))


def _inside(points: np.ndarray, xt: np.ndarray) -> np.ndarray:
    """Mask of ``points`` (n, 3) inside any tetrahedron ``xt`` (k, 4, 3)."""
    from scipy.spatial import cKDTree

    hit = np.zeros(len(points), dtype=bool)
    if len(points) == 0 or len(xt) == 0:
        return hit
    cen = 0.25 * xt.sum(axis=1)
    diff = xt - cen[:, None, :]
    rad = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff).max(axis=1))
    # A point inside a cell is within the cell's radius of its centroid: only the cells near
    # the points' bounding box are searched, in classes of similar radius, so a graded
    # mesh's coarse far cells do not widen the search around the fine flank cells.
    lo, hi = points.min(axis=0), points.max(axis=0)
    near_box = np.all((cen >= lo - rad[:, None]) & (cen <= hi + rad[:, None]), axis=1)
    box = np.flatnonzero(near_box & (rad > 0.0))
    if len(box) == 0:
        return hit
    r_min = float(rad[box].min())
    cls = np.floor(np.log2(rad[box] / r_min)).astype(np.int64)
    order = np.argsort(cls, kind="stable")
    bounds = np.flatnonzero(np.diff(cls[order])) + 1
    tree_p = cKDTree(points)
    for group in np.split(order, bounds):
        cells = box[group]
        tree_c = cKDTree(cen[cells])
        pairs = tree_p.sparse_distance_matrix(
            tree_c, float(rad[cells].max()), output_type="ndarray"
        )
        i, j = pairs["i"], cells[pairs["j"]]
        near = pairs["v"] <= rad[j]
        i, j = i[near], j[near]
        if len(i) == 0:
            continue
        p = points[i]
        a, b, cc, d = (xt[j, k] for k in range(4))
        vol = _triple(b - a, cc - a, d - a)
        ok = np.abs(vol) > 1e-14 * np.maximum(rad[j], 1e-300) ** 3  # degenerate cells: skip
        vol = np.where(ok, vol, 1.0)
        lam = (
            np.stack(
                [
                    _triple(b - p, cc - p, d - p),
                    _triple(p - a, cc - a, d - a),
                    _triple(b - a, p - a, d - a),
                    _triple(b - a, cc - a, p - a),
                ],
                axis=1,
            )
            / vol[:, None]
        )
        inside = ok & (lam.min(axis=1) >= -_BARY_TOL)
        hit[i[inside]] = True
    return hit


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Faces (f, 3) of the tetrahedra ``tets`` (k, 4) that no other of them shares."""
    faces = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
    n = int(faces.max(initial=0)) + 1
    if float(n) ** 3 >= 2.0**62:  # no room for an int64 key: the slower row-wise unique
        uniq, count = np.unique(faces, axis=0, return_counts=True)
        return uniq[count == 1]
    # One int64 key per face: a 1-D unique is several times faster than a row-wise one.
    key = (faces[:, 0] * n + faces[:, 1]) * n + faces[:, 2]
    _, first, count = np.unique(key, return_index=True, return_counts=True)
    return faces[first[count == 1]]


def _point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Distance from each point p (P, 3) to its triangle tri (P, 3, 3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01**2
    ok = den > 1e-14 * np.maximum(d00 * d11, 1e-300)
    den = np.where(ok, den, 1.0)
    s = (d11 * d20 - d01 * d21) / den
    t = (d00 * d21 - d01 * d20) / den
    n = np.cross(v0, v1)
    n_len = np.where(ok, np.linalg.norm(n, axis=1), 1.0)
    plane = np.abs(np.einsum("ij,ij->i", v2, n)) / n_len
    # The closest point is the projection if it lies in the triangle, else on an edge.
    dist = np.where(ok & (s >= 0) & (t >= 0) & (s + t <= 1), plane, np.inf)
    for q0, q1 in ((a, b), (b, c), (c, a)):
        e = q1 - q0
        ee = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
        lam = np.clip(np.einsum("ij,ij->i", p - q0, e) / ee, 0.0, 1.0)
        dist = np.minimum(dist, np.linalg.norm(p - q0 - lam[:, None] * e, axis=1))
    return dist


def _depth(points: np.ndarray, x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Distance from each of ``points`` to the nearest of the triangles ``x[faces]``."""
    from scipy.spatial import cKDTree

    if len(points) == 0:
        return np.zeros(0)
    tri = x[faces]
    cen = tri.mean(axis=1)
    r_tri = float(np.linalg.norm(tri - cen[:, None, :], axis=2).max())
    tree = cKDTree(cen)
    d0, _ = tree.query(points)
    # The nearest triangle is no farther than the nearest centroid, so its centroid lies
    # within d0 + the largest triangle radius: every candidate is checked exactly.
    cand = tree.query_ball_point(points, d0 + r_tri)
    counts = np.array([len(cnd) for cnd in cand], dtype=np.int64)
    pi = np.repeat(np.arange(len(points)), counts)
    fi = np.concatenate([np.asarray(cnd, dtype=np.int64) for cnd in cand])
    dist = _point_triangle_distance(points[pi], tri[fi])
    out = np.full(len(points), np.inf)
    np.minimum.at(out, pi, dist)
    return out


def audit_interpenetration(
    X: np.ndarray,
    u: np.ndarray,
    cell_vertices: np.ndarray,
    left_nodes: np.ndarray,
    right_nodes: np.ndarray,
    left_cells: np.ndarray,
    right_cells: np.ndarray,
    depth_tol_mm: float,
    *,
    left_faces: np.ndarray | None = None,
    right_faces: np.ndarray | None = None,
) -> AuditResult:
    """Flank nodes of each side inside the other side's deformed tissue deeper than
    ``depth_tol_mm`` (module docstring).

    ``X`` (n, 3) reference coordinates, ``u`` flat displacement dofs (3 n) or (n, 3);
    ``cell_vertices`` (m, 4) node indices of straight tetrahedra; ``left_nodes`` and
    ``right_nodes`` the flanks' node indices; ``left_cells`` and ``right_cells`` indices of the
    rows of ``cell_vertices`` that make each side's tissue. ``left_faces`` and
    ``right_faces`` (k, 3): the triangles a node's depth in that side is measured to (its
    flank: the penetration through it); default the whole boundary of the side's cells.
    """
    x = np.asarray(X, dtype=float) + np.asarray(u, dtype=float).reshape(-1, 3)
    tets = np.asarray(cell_vertices, dtype=np.int64)
    counted: list[np.ndarray] = []
    max_depth = 0.0
    sides = ((left_nodes, right_cells, right_faces), (right_nodes, left_cells, left_faces))
    for nodes, cells, faces in sides:
        other = tets[np.asarray(cells, dtype=np.int64)]
        # A node of the other side's cells lies on that tissue's boundary (it is a flank
        # node of this side too): depth 0 whatever the state.
        of_other = np.zeros(len(x), dtype=bool)
        of_other[other.ravel()] = True
        nodes = np.asarray(nodes, dtype=np.int64)
        nodes = nodes[~of_other[nodes]]
        inside = nodes[_inside(x[nodes], x[other])]
        if len(inside) == 0:
            continue
        faces = boundary_faces(other) if faces is None else np.asarray(faces, dtype=np.int64)
        depth = _depth(x[inside], x, faces.reshape(-1, 3))
        max_depth = max(max_depth, float(depth.max()))
        counted.append(inside[depth > depth_tol_mm])
    found = np.unique(np.concatenate(counted)) if counted else np.zeros(0, dtype=np.int64)
    return AuditResult(len(found), max_depth, found)


def linear_cells(cell_nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Straight tetrahedra (k, 4) through the nodes of ``cell_nodes`` ((m, 4) P1: themselves;
    (m, 10) P2: eight per cell, `P2_SUB_TETS`) and each one's parent cell (k,)."""
    cn = np.asarray(cell_nodes, dtype=np.int64)
    m = len(cn)
    if cn.shape[1] == 4:
        return cn, np.arange(m)
    if cn.shape[1] != 10:
        raise ValueError(f"expected 4 or 10 nodes per cell, got {cn.shape[1]}")
    return cn[:, P2_SUB_TETS].reshape(-1, 4), np.repeat(np.arange(m), len(P2_SUB_TETS))


def audit_model(model: Any, depth_tol_mm: float, u: np.ndarray | None = None) -> AuditResult:
    """`audit_interpenetration` of a `WoundModel` at ``u`` (default: its current state).

    The flank nodes are those of ``model.flanks`` (flat triangles, (k, 3)), and a node's
    depth is measured to the other flank's triangles; a cell is left tissue if its reference
    midpoint has x < ``model.domain.x_c``. A model without a wound gives an empty result.
    """
    if model.flanks is None:
        return AuditResult(0, 0.0, np.zeros(0, dtype=np.int64))
    d = model.domain
    tets, parent = linear_cells(d.cell_nodes)
    left = (np.asarray(d.midpoints)[:, 0] < d.x_c)[parent]
    left_f, right_f = model.flanks
    return audit_interpenetration(
        d.X,
        model.u if u is None else u,
        tets,
        np.unique(left_f),
        np.unique(right_f),
        np.flatnonzero(left),
        np.flatnonzero(~left),
        depth_tol_mm,
        left_faces=left_f,
        right_faces=right_f,
    )

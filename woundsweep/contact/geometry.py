"""Geometry of triangle surfaces for contact: gaps, projections and their exact derivatives.

Vectorised over leading axes (no Python loop over points). A gap is the signed distance of a
point to the plane of a triangle, positive on the side its normal (right-hand rule) points to.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "barycentric_derivatives",
    "edge_distance",
    "expand_hessian",
    "facing_mask",
    "fade_weight",
    "gap_derivatives",
    "orient_outward",
    "owning_cells",
    "point_triangle_distance",
    "projection",
    "split_wound_flanks",
]


def _cross_matrix(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) matrices [v]x with [v]x w = v x w."""
    z = np.zeros(v.shape[:-1])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            np.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            np.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def gap_derivatives(
    xs: np.ndarray, x1: np.ndarray, x2: np.ndarray, x3: np.ndarray, hessian: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Signed gap g = (xs - x1) . n and its exact first and second derivatives.

    Inputs (N, 3). Returns g (N,), dg/dq (N, 12) and d2g/dq2 (N, 12, 12) (or None) with
    q = (xs, x1, x2, x3). With d = xs - x1, a = x2 - x1, b = x3 - x1, m = a x b, mu = |m|,
    n = m / mu, c = (d - g n) / mu:  dg/dd = n, dg/da = b x c, dg/db = c x a;
    d2g/dd dm = (I - n n^T) / mu, d2g/dm2 = (3 g n n^T - g I - d n^T - n d^T) / mu^2, and
    the bilinear m(a, b) adds 2 c . (da x db).
    """
    d, a, b = xs - x1, x2 - x1, x3 - x1
    m = np.cross(a, b)
    mu = np.linalg.norm(m, axis=1)
    n = m / mu[:, None]
    g = _dot(d, n)
    c = (d - g[:, None] * n) / mu[:, None]
    ga, gb = np.cross(b, c), np.cross(c, a)
    grad = np.concatenate([n, -n - ga - gb, ga, gb], axis=1)
    if not hessian:
        return g, grad, None
    N = len(g)
    eye = np.broadcast_to(np.eye(3), (N, 3, 3))
    nn = n[:, :, None] * n[:, None, :]
    Mm = np.concatenate([-_cross_matrix(b), _cross_matrix(a)], axis=2)  # dm / d(a, b): (N,3,6)
    P = (eye - nn) / mu[:, None, None]
    g2 = g[:, None, None]
    gmm = 3.0 * g2 * nn - g2 * eye - d[:, :, None] * n[:, None, :] - n[:, :, None] * d[:, None, :]
    gmm /= (mu**2)[:, None, None]
    H9 = np.zeros((N, 9, 9))
    Hdab = P @ Mm  # (N, 3, 6)
    H9[:, 0:3, 3:9] = Hdab
    H9[:, 3:9, 0:3] = np.transpose(Hdab, (0, 2, 1))
    Hab = np.transpose(Mm, (0, 2, 1)) @ gmm @ Mm
    C = _cross_matrix(c)
    Hab[:, 0:3, 3:6] -= C
    Hab[:, 3:6, 0:3] += C
    H9[:, 3:9, 3:9] = Hab
    # (d, a, b) = T q with q = (xs, x1, x2, x3): d = xs - x1, a = x2 - x1, b = x3 - x1.
    T = np.zeros((9, 12))
    for k, (col_pos, col_neg) in enumerate(((0, 3), (6, 3), (9, 3))):
        T[3 * k : 3 * k + 3, col_pos : col_pos + 3] = np.eye(3)
        T[3 * k : 3 * k + 3, col_neg : col_neg + 3] -= np.eye(3)
    H = np.einsum("ai,nab,bj->nij", T, H9, T)
    return g, grad, H


def projection(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Signed plane distance g = (p - a) . n and the barycentric coordinates (..., 3) (for a, b,
    c) of the orthogonal projection of p onto the triangle's plane (broadcast)."""
    e0, e1, v = b - a, c - a, p - a
    nrm = np.cross(e0, e1)
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    d00, d01, d11 = _dot(e0, e0), _dot(e0, e1), _dot(e1, e1)
    d20, d21 = _dot(v, e0), _dot(v, e1)
    den = d00 * d11 - d01 * d01
    beta = (d11 * d20 - d01 * d21) / den
    gamma = (d00 * d21 - d01 * d20) / den
    return _dot(v, nrm), np.stack([1.0 - beta - gamma, beta, gamma], axis=-1)


def point_triangle_distance(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, with_bary: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact distance from points to triangles (broadcast over leading axes).

    Returns (distance, signed plane distance g = (p - a) . n, smallest barycentric coordinate
    of the orthogonal projection onto the triangle's plane; >= 0 means inside). With
    ``with_bary`` the last item is all three coordinates (..., 3) (for a, b, c).
    """
    g, lam = projection(p, a, b, c)
    bary_min = lam.min(axis=-1)
    dist = np.abs(g)
    out = bary_min < 0.0
    if out.any():  # projection outside: the distance is to the nearest edge
        shape = out.shape
        dist[out] = edge_distance(*(np.broadcast_to(z, (*shape, 3))[out] for z in (p, a, b, c)))
    if with_bary:
        return dist, g, lam
    return dist, g, bary_min


def edge_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from points to the nearest edge of triangles ((N, 3) each)."""

    def seg(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        e = q1 - q0
        t = np.clip(_dot(p - q0, e) / _dot(e, e), 0.0, 1.0)
        return np.linalg.norm(p - q0 - t[..., None] * e, axis=-1)

    return np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a))


def barycentric_derivatives(
    xq: np.ndarray, x1: np.ndarray, x2: np.ndarray, x3: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates of the orthogonal projection of ``xq`` onto the plane of the
    triangle (x1, x2, x3) and their exact gradients.

    Inputs (N, 3). Returns lam (N, 3) and dlam/dq (N, 3, 12) with q = (xq, x1, x2, x3).
    lam_i = A_i . m / (m . m) with A_i = (x_j - xq) x (x_k - xq), (i, j, k) cyclic and
    m = (x2 - x1) x (x3 - x1) (the component of xq along m drops out of A_i . m).
    """
    V = (x1, x2, x3)
    a0, b0 = x2 - x1, x3 - x1
    m = np.cross(a0, b0)
    s = _dot(m, m)
    Ca0, Cb0 = _cross_matrix(a0), _cross_matrix(b0)
    dm = (Cb0 - Ca0, -Cb0, Ca0)  # dm/dx1, dm/dx2, dm/dx3, each (N, 3, 3)
    N = len(xq)
    lam = np.zeros((N, 3))
    dlam = np.zeros((N, 3, 12))
    mT = m[:, None, :]
    for i, (j, k) in enumerate(((1, 2), (2, 0), (0, 1))):
        a, b = V[j] - xq, V[k] - xq
        A = np.cross(a, b)
        lam[:, i] = _dot(A, m) / s
        Ca, Cb = _cross_matrix(a), _cross_matrix(b)
        dA = {0: Cb - Ca, 1 + j: -Cb, 1 + k: Ca}  # dA/d(q block)
        for blk in range(4):
            g = np.zeros((N, 3))
            if blk in dA:
                g += (mT @ dA[blk])[:, 0, :]  # (dA/dz)^T m
            if blk >= 1:
                dmb = dm[blk - 1]
                g += (A[:, None, :] @ dmb)[:, 0, :] - 2.0 * lam[:, i, None] * (mT @ dmb)[:, 0, :]
            dlam[:, i, 3 * blk : 3 * blk + 3] = g / s[:, None]
    return lam, dlam


def fade_weight(lam: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weight w = phi(lam_1) phi(lam_2) phi(lam_3), dw/dlam and d2w/dlam2 ((N, 3) inputs).

    phi(lam) = 1 - 3 t^2 + 2 t^3 with t = clip(-lam / width, 0, 1): 1 on the facet, 0 at
    ``width`` beyond an edge (in barycentric units), C1 at both ends.
    """
    t = np.clip(-lam / width, 0.0, 1.0)
    band = (t > 0.0) & (t < 1.0)
    phi = 1.0 - 3.0 * t**2 + 2.0 * t**3
    d1 = np.where(band, 6.0 * t * (1.0 - t) / width, 0.0)
    d2 = np.where(band, -(6.0 - 12.0 * t) / width**2, 0.0)
    w = phi.prod(axis=1)
    N = len(lam)
    dw = np.empty((N, 3))
    d2w = np.empty((N, 3, 3))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        dw[:, i] = d1[:, i] * phi[:, j] * phi[:, k]
        d2w[:, i, i] = d2[:, i] * phi[:, j] * phi[:, k]
        d2w[:, i, j] = d1[:, i] * d1[:, j] * phi[:, k]
        d2w[:, j, i] = d2w[:, i, j]
    return w, dw, d2w


def facing_mask(n: np.ndarray, m: np.ndarray, m_norm: np.ndarray, cos: float) -> np.ndarray:
    """Whether master facets of normal ``m`` (length ``m_norm``) face slave facets of unit
    normal ``n`` (broadcast): n . m <= cos |m|."""
    return np.einsum("...i,...i->...", n, m) <= cos * m_norm


def _face_keys(tri: np.ndarray, n: int) -> np.ndarray:
    t = np.sort(np.asarray(tri, dtype=np.int64), axis=1)
    return (t[:, 0] * n + t[:, 1]) * n + t[:, 2]


def owning_cells(cells: np.ndarray, facets: np.ndarray, n_points: int) -> np.ndarray:
    """Index of a cell (m, 4) of which each facet (k, 3) is a face (same node numbering)."""
    cells = np.asarray(cells, dtype=np.int64)
    faces = np.concatenate([cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]],
                            cells[:, [0, 1, 2]]])  # fmt: skip
    owner = np.tile(np.arange(len(cells)), 4)
    keys = _face_keys(faces, n_points)
    order = np.argsort(keys)
    want = _face_keys(facets, n_points)
    pos = np.minimum(np.searchsorted(keys, want, sorter=order), len(order) - 1)
    if not np.all(keys[order[pos]] == want):
        raise ValueError("a boundary facet is not a face of any cell")
    return owner[order[pos]]


def orient_outward(X: np.ndarray, cells: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Boundary facets (node indices) reordered so that their normal points out of the body.

    ``X`` (n, 3) node coordinates, ``cells`` (m, 4) tetrahedra in the same node numbering.
    """
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 3)
    owner = np.asarray(cells, dtype=np.int64)[owning_cells(cells, facets, len(X))]
    apex = owner[np.all(owner[:, :, None] != facets[:, None, :], axis=2)]  # node off the facet
    inner = X[apex]
    p = X[facets]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = _dot(nrm, inner - p[:, 0]) > 0.0  # normal points toward the cell: flip it
    out = facets.copy()
    out[flip, 1], out[flip, 2] = facets[flip, 2], facets[flip, 1]
    return out


def split_wound_flanks(
    X: np.ndarray, cells: np.ndarray, wound_facets: np.ndarray, x_c: float
) -> tuple[np.ndarray, np.ndarray]:
    """The wound facets (node indices) split into (left, right) flanks by reference centroid
    x < x_c, each oriented outward (`orient_outward`)."""
    wound_facets = orient_outward(X, cells, wound_facets)
    left = X[wound_facets].mean(axis=1)[:, 0] < x_c
    return wound_facets[left], wound_facets[~left]


def expand_hessian(H12: np.ndarray, bary: np.ndarray, linear_q: bool = False) -> np.ndarray:
    """A Hessian over q = (x_q, x1, x2, x3) (N, 12, 12) mapped to the 18 dofs of the 3 slave and
    3 master nodes with x_q = sum_i N_i x_si. ``linear_q``: the x_q x_q block is zero."""
    na = len(H12)
    H = np.zeros((na, 18, 18))
    N = bary
    sm = (N[:, :, None, None] * H12[:, None, 0:3, 3:12]).reshape(na, 9, 9)
    H[:, 0:9, 9:18] = sm
    H[:, 9:18, 0:9] = np.transpose(sm, (0, 2, 1))
    H[:, 9:18, 9:18] = H12[:, 3:12, 3:12]
    if not linear_q:
        qq = N[:, :, None, None, None] * N[:, None, None, :, None] * H12[:, None, 0:3, None, 0:3]
        H[:, 0:9, 0:9] = qq.reshape(na, 9, 9)
    return H

"""Penalty contact of the two wound flanks (stages 4-6; paper: "material depth contact model").

Formulation: two-pass surface-to-surface penalty at contact points, in the DEFORMED
configuration. Units: lengths mm, k_V kPa (1 GPa = 1e6 kPa), forces mN, energy mN mm.

- Surfaces. The wound surface (facet tag WOUND) is split into two flanks by the reference
  facet centroid, x < x_c (left) and x >= x_c (right), x_c the wound's mirror plane. Each
  facet is oriented so that its normal points out of the body (into the wound cavity). Any two
  facet sets can be given (the tests use two blocks).
- Contact points. Each facet of one flank (the slave in that pass) carries six points: the
  symmetric 3-point rule (barycentric (2/3, 1/6, 1/6), 1/4 of the facet area each) and three
  points near the vertices ((1 - 2a, a, a), a = 1/50, 1/12 of the area each), so no corner of
  a flank can cross the other flank unseen. Point q has the reference area A_q it carries and
  the size h_q of its facet (side of the equilateral triangle of the facet's reference area).
- Gap. For a point at deformed position x_q and a facet (x_1, x_2, x_3) of the other (master)
  flank, g = (x_q - x_1) . n with n = (x_2 - x_1) x (x_3 - x_1) / |...| the deformed unit
  normal; g < 0 means that the point is behind the master surface: -g is its depth in the
  master body, measured normal to the master surface (the "material depth").
- Pairing: the master facet of a point is chosen among the ``neighbours`` facets with the
  nearest deformed centroids (scipy cKDTree) that are valid for it: no node shared with the
  point's own facet, facing it (n_q . n <= normal_cos, n_q the deformed normal of the slave
  facet: this keeps the two flanks of a smooth wound bottom, which are continuous and
  coplanar there, from being taken for penetration), and the orthogonal projection of x_q
  less than ``fade_width`` = 0.25 (barycentric units) beyond the facet's edges. The valid
  facet with the smallest score wins: exact point-triangle distance + (1 - phi) * facet size,
  phi the edge fade below (past the edge between two facets the distances tie, the fades do
  not). Only valid facets compete: an invalid closest facet hiding a valid one made pairings
  flip. Two modes: live (default; searched afresh at every new state, the residual is a
  function of u alone) and frozen (`freeze`: the pairing of one state is kept, only
  engagement and fades follow the state; used by the wound model, see Linearisation). The
  point is engaged when g < touch_rel * h_q (touching counts; ``touch_rel`` = 1e-9), phi > 0
  and the depth -g <= max_depth_mm (deeper points are counted as ``n_deep`` and carry no
  force; the wound model uses the wound depth).
- Edge fade. A point whose projection leaves its master facet across an edge where no other
  facet takes over (the rim of a flank, the line where the flanks meet, facets skipped as
  the point's own neighbours) used to drop out of contact with its whole force at once, and
  Newton cycled between the two pairings (measured: a deep 90-degree wedge, 4 points in a
  2-cycle of 2 mN jumps; the lips of a 45-degree cylinder). Each point's energy is therefore
  multiplied by phi = prod_i s(lam_i), lam_i the barycentric coordinates of the projection
  and s(lam) = 1 - 3 t^2 + 2 t^3 with t = clip(-lam / fade_width, 0, 1): phi = 1 on the
  facet, falls to 0 at fade_width beyond an edge, and is C1, so the force fades instead of
  jumping. Penetration is reported only for points with phi = 1 (`summary`).
- Energy. Pi_c = sum over engaged points of phi (w / 2) (k_V / h_q) A_q g^2 with w = 1/2 because
  each flank is slave once and master once (two-pass): when both passes see the same
  overlap, each carries half the load. The contact pressure per reference area is therefore
  p = k_V (-g) / h_q: k_V has stress units, like the paper's "material depth" penalty (a
  layer of thickness h with modulus k_V), and the penetration at pressure p is
  -g = p h / k_V, relative to the element size p / k_V (1e-4 at p = 100 kPa, k_V = 1 GPa).
  The point stiffness c = w k_V A_q / h_q is in mN/mm, the normal force c (-g) in mN.
- Linearisation. Residual c (phi g dg/dq + g^2 / 2 dphi/dq) and tangent
  c (phi (dg/dq dg/dq^T + g d2g/dq2) + g (dg/dq dphi/dq^T + dphi/dq dg/dq^T)
  + g^2 / 2 d2phi/dq2) over the coordinates of the slave facet's and the master facet's
  nodes, for a given pairing: g, dg, d2g and dlam analytic (`gap_derivatives`,
  `barycentric_derivatives`), d2lam by central differences of dlam (only for the few points
  with phi < 1; agrees with finite differences of the force to 1e-6 in the tests).
  ``exact_depth_rel`` can drop the geometric term g d2g/dq2 where |g| > exact_depth_rel h
  (a quasi-Newton option, off by default). The pairing itself is piecewise constant in u, and a live pairing that changes between Newton
  iterates (points sliding over facet edges) made Newton cycle. The wound model therefore
  solves each load increment with the pairing frozen (a smooth problem apart from the
  engagement kink at g = 0) and, once Newton has converged, re-searches it (`refresh`): if
  the new pairing changes the contact forces by more than the residual tolerance, Newton
  continues from there with it; the increment converges only when the state is an
  equilibrium of its own pairing (an outer fixed point checked on the residual).
- Pairing 2-cycles. That outer fixed point can cycle: a point penetrating near a convex edge
  of the master surface is pushed along facet A's normal into the region where B is
  closer, and along B's normal back to A (measured at 45 degrees: residual jumps of about
  1 mN at every refresh, each pairing converging quadratically, for hundreds of steps). A
  point whose master goes A -> B -> A over successive searches (``share_cycles``) keeps
  both, each with half its area, so its force is the mean of the two facets' forces (a
  discrete stand-in for the edge's normal), for as long as the search gives it A or B and
  the other facet stays valid for it; the energy is still a sum over (point, facet) pairs,
  so residual and tangent are unchanged in form. The pairing (and its history) of the last
  accepted refresh is kept: a load increment retried after a failure starts from it, so the
  converged state it starts from is again an equilibrium of its pairing (a new search there
  could have lost a shared point and started the retry 0.08 mN out of balance, measured).
- Assembly. Residual contributions are summed into the flat dof vector with ``np.bincount``;
  tangent blocks go to the PETSc matrix as one CSR batch (``Mat.setValuesCSR``, ADD_VALUES).
  Couplings across the wound are not in the finite-element sparsity pattern: the matrix may
  grow (``NEW_NONZERO_ALLOCATION_ERR`` off) and MUMPS redoes its symbolic analysis when the
  pattern changes (PETSc tracks the nonzero state).

All evaluation is vectorised over contact points (no Python loop over points or cells); the
last pairing is cached by the flank node positions, so a Jacobian at the state of the last
residual costs no second search. Dof layout: node i has dofs 3 i, 3 i + 1, 3 i + 2 (blocked P1).
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "GPA_TO_KPA",
    "ContactPairs",
    "ContactSummary",
    "FlankContact",
    "Surface",
    "barycentric_derivatives",
    "fade_weight",
    "gap_derivatives",
    "orient_outward",
    "owning_cells",
    "point_triangle_distance",
    "split_wound_flanks",
]

GPA_TO_KPA = 1.0e6  # stiffness in GPa -> kPa
TWO_PASS_WEIGHT = 0.5  # each flank is slave once and master once


class Surface(NamedTuple):
    """One contact surface in node numbering (reference configuration)."""

    facets: np.ndarray  # (nf, 3) node indices, normal (right-hand rule) points out of the body
    nodes: np.ndarray  # (ns,) the facets' nodes, sorted
    size_mm: np.ndarray  # (ns,) element size at each node (mean over its facets)


class ContactPairs(NamedTuple):
    """Active contact points of both passes at one state."""

    slave: np.ndarray  # (na, 3) nodes of the slave facet that holds the point
    bary: np.ndarray  # (na, 3) the point's shape function values on that facet
    master: np.ndarray  # (na, 3) master facet nodes
    gap_mm: np.ndarray  # (na,) signed gap: < 0 penetrating, tiny >= 0 touching (no force)
    stiffness: np.ndarray  # (na,) c = w k_V A_q / h, mN/mm
    size_mm: np.ndarray  # (na,) h of the slave facet
    n_deep: int  # points left out because -g > max_depth_mm (0 when all is well)
    weight: np.ndarray  # (na,) edge fade w in (0, 1]; 1 where the projection is on the facet


class ContactSummary(NamedTuple):
    """Scalars of a contact state (the StageResult contact fields plus diagnostics)."""

    n_penetrating: int  # contact points with g < 0
    max_penetration_mm: float  # max -g (0 if none)
    max_penetration_rel: float  # max -g / h_s
    contact_force_mN: float  # total normal contact force, sum of c (-g)
    n_deep: int


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


def _projection(
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
    g, lam = _projection(p, a, b, c)
    bary_min = lam.min(axis=-1)
    dist = np.abs(g)
    out = bary_min < 0.0
    if out.any():  # projection outside: the distance is to the nearest edge
        shape = out.shape
        dist[out] = _edge_distance(*(np.broadcast_to(z, (*shape, 3))[out] for z in (p, a, b, c)))
    if with_bary:
        return dist, g, lam
    return dist, g, bary_min


def _edge_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
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


def _facing(n: np.ndarray, m: np.ndarray, m_norm: np.ndarray, cos: float) -> np.ndarray:
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


def _surface(X: np.ndarray, facets: np.ndarray) -> Surface:
    p = X[facets]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    nodes, inv = np.unique(facets.ravel(), return_inverse=True)
    tri_area = np.bincount(inv, weights=np.repeat(area, 3), minlength=len(nodes))
    count = np.bincount(inv, minlength=len(nodes))
    size = np.sqrt(4.0 * (tri_area / count) / np.sqrt(3.0))  # side of the equilateral triangle
    return Surface(facets, nodes, size)


def split_wound_flanks(
    X: np.ndarray, cells: np.ndarray, wound_facets: np.ndarray, x_c: float
) -> tuple[np.ndarray, np.ndarray]:
    """The wound facets (node indices) split into (left, right) flanks by reference centroid
    x < x_c, each oriented outward (`orient_outward`)."""
    wound_facets = orient_outward(X, cells, wound_facets)
    left = X[wound_facets].mean(axis=1)[:, 0] < x_c
    return wound_facets[left], wound_facets[~left]


# Contact points per slave facet (barycentric coordinates, share of the facet's area): the
# symmetric 3-point rule (2/3, 1/6, 1/6) carries 3/4 of the area, and three points close to
# the vertices (1 - 2 a, a, a) with a = 1/50 carry 1/12 each, so that no corner of a flank can
# cross the other flank unseen (with the 3-point rule alone the top corners of a closed wound
# crossed by 6% of an element). The points stay inside the facet: no point sits on a vertex or
# an edge, where the master facet of a mirror-image mesh would be ambiguous.
_A = 1.0 / 50.0
RULE_BARY = np.concatenate(
    [
        np.array([[4.0, 1.0, 1.0], [1.0, 4.0, 1.0], [1.0, 1.0, 4.0]]) / 6.0,
        np.array([[1 - 2 * _A, _A, _A], [_A, 1 - 2 * _A, _A], [_A, _A, 1 - 2 * _A]]),
    ]
)
RULE_WEIGHT = np.array([0.25, 0.25, 0.25, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 12.0])


class _Points(NamedTuple):
    """Contact points of one slave surface (``len(RULE_WEIGHT)`` per facet)."""

    carrier: np.ndarray  # (nq, 3) nodes of the slave facet that holds the point
    bary: np.ndarray  # (nq, 3) the point's shape function values on that facet
    area_mm2: np.ndarray  # (nq,) reference area carried by the point
    size_mm: np.ndarray  # (nq,) h of the facet
    facet: np.ndarray  # (nq,) slave facet index


def _contact_points(X: np.ndarray, facets: np.ndarray) -> _Points:
    p = X[facets]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    size = np.sqrt(4.0 * area / np.sqrt(3.0))  # side of the equilateral triangle of that area
    nq = len(RULE_WEIGHT)
    facet = np.repeat(np.arange(len(facets)), nq)
    return _Points(
        facets[facet],
        np.tile(RULE_BARY, (len(facets), 1)),
        (area[:, None] * RULE_WEIGHT).ravel(),
        size[facet],
        facet,
    )


class _Closest(NamedTuple):
    facet: np.ndarray  # (N,) master facet index (valid where ok)
    gap: np.ndarray  # (N,) signed plane distance to it
    ok: np.ndarray  # (N,) projection inside the facet's fade band, not excluded, facing


class _Candidates(NamedTuple):
    """Contact candidates of both passes found by one search."""

    carrier: np.ndarray  # (nc, 3) slave facet nodes
    bary: np.ndarray  # (nc, 3)
    master: np.ndarray  # (nc, 3) master facet nodes
    area_mm2: np.ndarray  # (nc,)
    size_mm: np.ndarray  # (nc,)
    engaged: np.ndarray  # (nc,) bool: engaged (g < touch_rel h)
    pid: np.ndarray  # (nc,) contact point id (both passes numbered together)
    mkey: np.ndarray  # (nc,) master facet id (both surfaces numbered together)
    n_deep: int


class _Local(NamedTuple):
    pairs: ContactPairs
    dofs: np.ndarray  # (na, 18)
    grad_g: np.ndarray  # (na, 18) gap gradient
    grad_w: np.ndarray  # (na, 18) fade weight gradient (0 off the fade bands)
    hess_g: np.ndarray | None  # (na, 18, 18) gap Hessian
    hess_w: np.ndarray | None  # (na, 18, 18) fade weight Hessian (None: no point fades)


def _expand_hessian(H12: np.ndarray, bary: np.ndarray, linear_q: bool = False) -> np.ndarray:
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


class FlankContact:
    """Two-pass surface-to-surface penalty between two surfaces (see the module docstring).

    ``X`` (n, 3) reference node coordinates; ``left`` and ``right`` (k, 3) outward-oriented
    facets in node numbering. ``k_V_kPa`` (attribute) is the penalty; 0 switches contact off
    (pairs and penetrations are still measured).
    """

    def __init__(
        self,
        X: np.ndarray,
        left: np.ndarray,
        right: np.ndarray,
        *,
        max_depth_mm: float,
        neighbours: int = 12,
        normal_cos: float = 0.0,
        touch_rel: float = 1e-9,
        exact_depth_rel: float = np.inf,
        near_rel: float = 1.0,
        fade_width: float = 0.25,
        share_cycles: bool = True,
    ) -> None:
        self.X = np.asarray(X, dtype=float)
        self.n_dofs = 3 * len(self.X)
        a, b = _surface(self.X, np.asarray(left)), _surface(self.X, np.asarray(right))
        self.surfaces = (a, b)
        self.points = (_contact_points(self.X, a.facets), _contact_points(self.X, b.facets))
        # Points whose facet has a node on the other surface (where the flanks meet): only
        # they can have a master candidate that is excluded as their own neighbour.
        self._shares = tuple(
            np.isin(self.points[i].carrier, self.surfaces[1 - i].nodes).any(axis=1) for i in (0, 1)
        )
        self.fade_width = float(fade_width)
        self.share_cycles = bool(share_cycles)
        n_pts = (len(self.points[0].area_mm2), len(self.points[1].area_mm2))
        self._pid0 = (0, n_pts[0])
        self._mkey0 = (0, len(a.facets))
        self._all_facets = np.concatenate([a.facets, b.facets])
        # Pairing history per contact point (master facet ids; -1 none): current, previous,
        # and the two facets it shares after a 2-cycle.
        self._cur, self._prev, self._sh_a, self._sh_b = (
            np.full(sum(n_pts), -1, dtype=np.int64) for _ in range(4)
        )
        self.nodes = np.union1d(a.nodes, b.nodes)  # every node whose position matters
        self.max_depth_mm = float(max_depth_mm)
        self.neighbours = int(neighbours)
        self.normal_cos = float(normal_cos)
        self.touch_rel = float(touch_rel)
        self.exact_depth_rel = float(exact_depth_rel)
        self.k_V_kPa = 0.0
        self.near_rel = float(near_rel)
        self._found: _Candidates | None = None  # the pairing in use
        self._raw: _Candidates | None = None  # the last search
        # Flank node positions, pairing and pairing history of the last accepted refresh.
        self._accepted: tuple[Any, ...] | None = None
        self._search_x: np.ndarray | None = None
        self.frozen = False  # True: `pairs` reuses the pairing of the last `freeze`
        self._cand: tuple[np.ndarray, np.ndarray, np.ndarray] = (np.zeros(0),) * 3
        self._version = 0
        self._cache_x: np.ndarray | None = None
        self._cache_key: tuple[float, int] = (-1.0, -1)
        self._cache: ContactPairs | None = None
        self.reset_timers()

    # -- geometry at a state -------------------------------------------------------------------

    def positions(self, u: np.ndarray) -> np.ndarray:
        """Deformed coordinates (n, 3) of all nodes for flat displacement dofs ``u``."""
        return self.X + np.asarray(u).reshape(-1, 3)

    def _closest(
        self,
        x: np.ndarray,
        pts: np.ndarray,
        normals: np.ndarray,
        exclude: np.ndarray,
        master: Surface,
        shares: np.ndarray,
    ) -> _Closest:
        """Master facet of each point: the best valid one (score: exact distance, plus the fade
        deficit times the facet size) among the ``neighbours`` facets with the nearest centroids.
        Valid: no node shared with ``exclude`` (N, j), facing the point's facet, projection
        inside the fade band. ``shares`` (N,) marks the points whose ``exclude`` nodes are on
        the master surface at all (the others cannot share a node: their check is skipped)."""
        tri = master.facets
        k = min(self.neighbours, len(tri))
        _, cand = cKDTree(x[tri].mean(axis=1)).query(pts, k=k)
        cand = np.asarray(cand).reshape(len(pts), k)
        ct = tri[cand]  # (N, k, 3)
        v = x[ct]
        v0, v1, v2 = v[..., 0, :], v[..., 1, :], v[..., 2, :]
        g, lam = _projection(pts[:, None, :], v0, v1, v2)
        own = np.zeros(cand.shape, dtype=bool)
        rows = np.flatnonzero(shares)
        own[rows] = np.any(ct[rows, :, :, None] == exclude[rows, None, None, :], axis=(2, 3))
        m = np.cross(v1 - v0, v2 - v0)
        mu = np.linalg.norm(m, axis=-1)
        facing = _facing(normals[:, None, :], m, mu, self.normal_cos)
        # A point stays paired up to fade_width beyond the facet's edges (its weight fading
        # to 0 there); where the surface goes on, a neighbour takes over first. Only valid
        # facets compete, so a point is dropped only when none is left (a closest facet that
        # is not valid must not hide a valid one behind it: that made pairings flip).
        lam_min = lam.min(axis=2)
        valid = ~own & facing & (lam_min > -self.fade_width)
        # Exact distance: |g| where the projection is on the facet, else to the nearest edge,
        # computed for valid candidates only (most of the k are far outside their facet).
        dist = np.abs(g)
        fading = valid & (lam_min < 0.0)
        if fading.any():
            pp = np.broadcast_to(pts[:, None, :], v0.shape)[fading]
            dist[fading] = _edge_distance(pp, v0[fading], v1[fading], v2[fading])
        # Prefer the facet that the projection falls into: past the edges between facets the
        # exact distances tie (distance to the shared edge), the weights do not.
        deficit = np.zeros(lam.shape[:2])
        deficit[fading] = 1.0 - fade_weight(lam[fading], self.fade_width)[0]
        score = np.where(valid, dist + deficit * np.sqrt(mu), np.inf)
        best = np.argmin(score, axis=1)
        r = np.arange(len(pts))
        facet = cand[r, best]
        ok = valid[r, best]
        return _Closest(facet, g[r, best], ok)

    def _detect_one(self, x: np.ndarray, side: int) -> _Candidates:
        """Candidate points of one pass: a valid master facet and g < near_rel h (in front
        but close, touching, or penetrating up to max_depth_mm)."""
        sl, ms, qp = self.surfaces[side], self.surfaces[1 - side], self.points[side]
        sf = qp.carrier
        pts = np.einsum("qi,qij->qj", qp.bary, x[sf])
        p = x[sl.facets]
        normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[qp.facet]
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        cl = self._closest(x, pts, normals, sf, ms, self._shares[side])
        cand = cl.ok & (cl.gap < self.near_rel * qp.size_mm)
        deep = cand & (-cl.gap > self.max_depth_mm)
        keep = cand & ~deep
        engaged = cl.gap[keep] < self.touch_rel * qp.size_mm[keep]
        pid = self._pid0[side] + np.flatnonzero(keep)
        mkey = self._mkey0[1 - side] + cl.facet[keep]
        return _Candidates(
            sf[keep], qp.bary[keep], ms.facets[cl.facet[keep]], qp.area_mm2[keep],
            qp.size_mm[keep], engaged, pid, mkey, int(deep.sum()),
        )  # fmt: skip

    def _search(self, u: np.ndarray) -> np.ndarray:
        """Find the contact candidates of both passes at ``u`` (nothing to do if the last
        search was at the same flank positions); returns the deformed positions."""
        t0 = time.perf_counter()
        x = self.positions(u)
        xn = x[self.nodes]
        if self._found is not None and np.array_equal(xn, self._search_x):
            return x
        self._search_x = xn.copy()
        parts = [self._detect_one(x, side) for side in (0, 1)]
        found = _Candidates(*(np.concatenate([p[i] for p in parts]) for i in range(8)),
                            sum(p[8] for p in parts))  # fmt: skip
        self._raw = self._found = found
        self._version += 1
        self.detect_time_s += time.perf_counter() - t0
        self.searches += 1
        return x

    def freeze(self, u: np.ndarray) -> None:
        """Search the pairing at ``u`` and keep it (master facet of every candidate point)
        until the next `freeze`, `refresh` or `unfreeze`; engagement (g < touch) stays live.
        A point whose master flips back to one it had before shares the two
        (`_share_cycles`). At the state of the last accepted `refresh` (a converged state: the
        start of a retried load increment or of the next stage) the pairing and its history
        are restored as they were, so the state is again an equilibrium of its own pairing."""
        acc = self._accepted
        if acc is not None and np.array_equal(self.positions(u)[self.nodes], acc[0]):
            self._found = acc[1]
            for a, b in zip((self._cur, self._prev, self._sh_a, self._sh_b), acc[2:], strict=True):
                a[:] = b
            self._version += 1
        else:
            self._pair(u)
        self.frozen = True

    def _pair(self, u: np.ndarray) -> None:
        """The pairing in use: the search at ``u``, with 2-cycles shared if enabled."""
        x = self._search(u)
        raw = self._raw
        assert raw is not None
        self._found = self._share_cycles(raw, x) if self.share_cycles else raw
        self._version += 1

    def _share_cycles(self, raw: _Candidates, x: np.ndarray) -> _Candidates:
        """Resolve pairing 2-cycles: a point whose master goes A -> B -> A over successive
        searches (`freeze`, `refresh`) keeps both, each with half its area (its force is then
        the mean of the two facets' forces), while the search gives it A or B and the other
        facet is still valid for it at ``x`` (facing it, projection inside its fade band)."""
        m = raw.mkey
        cur, prev = self._cur[raw.pid], self._prev[raw.pid]
        moved = (cur >= 0) & (m != cur)
        back = moved & (m == prev)
        self._sh_a[raw.pid[back]], self._sh_b[raw.pid[back]] = cur[back], m[back]
        self._prev[raw.pid[moved]] = cur[moved]
        self._cur[raw.pid] = m
        a, b = self._sh_a[raw.pid], self._sh_b[raw.pid]
        pair = (a >= 0) & ((m == a) | (m == b))
        other = np.where(m == a, b, a)
        if pair.any():
            # The partner facet must still be a valid master of the point here.
            idx = np.flatnonzero(pair)
            xq = np.einsum("qi,qij->qj", raw.bary[idx], x[raw.carrier[idx]])
            pm = x[self._all_facets[other[idx]]]
            lam = _projection(xq, pm[:, 0], pm[:, 1], pm[:, 2])[1]
            ps = x[raw.carrier[idx]]
            ns = np.cross(ps[:, 1] - ps[:, 0], ps[:, 2] - ps[:, 0])
            ns /= np.linalg.norm(ns, axis=1, keepdims=True)
            nm = np.cross(pm[:, 1] - pm[:, 0], pm[:, 2] - pm[:, 0])
            facing = _facing(ns, nm, np.linalg.norm(nm, axis=1), self.normal_cos)
            pair[idx[~(facing & (lam.min(axis=1) > -self.fade_width))]] = False
        drop = raw.pid[(a >= 0) & ~pair]  # moved on: a single master again
        self._sh_a[drop] = self._sh_b[drop] = -1
        if not pair.any():
            return raw
        area = raw.area_mm2.copy()
        area[pair] *= 0.5
        return _Candidates(
            np.concatenate([raw.carrier, raw.carrier[pair]]),
            np.concatenate([raw.bary, raw.bary[pair]]),
            np.concatenate([raw.master, self._all_facets[other[pair]]]),
            np.concatenate([area, area[pair]]),
            np.concatenate([raw.size_mm, raw.size_mm[pair]]),
            np.concatenate([raw.engaged, raw.engaged[pair]]),
            np.concatenate([raw.pid, raw.pid[pair]]),
            np.concatenate([m, other[pair]]),
            raw.n_deep,
        )

    def unfreeze(self) -> None:
        """Search afresh at every new state again (the last search is kept: it is reused
        while the flank nodes stay where it was made, e.g. by the next stage's first
        `freeze` at the converged state of this one)."""
        self.frozen = False
        self._version += 1

    def refresh(self, u: np.ndarray, tol: float) -> bool:
        """Re-search the pairing at ``u`` (frozen mode); True when the new pairing changes the
        contact forces by more than ``tol`` (mN, Euclidean norm): ``u`` is then not yet an
        equilibrium of its own pairing (the outer fixed-point check, module docstring)."""
        if not self.frozen or self.k_V_kPa <= 0.0:
            return False
        before = self.force_vector(u)
        self._pair(u)
        after = self.force_vector(u)
        self.refreshes += 1
        changed = bool(np.linalg.norm(after - before) > tol)
        if not changed:  # accepted: keep what a retry from this state must start from
            history = (a.copy() for a in (self._cur, self._prev, self._sh_a, self._sh_b))
            self._accepted = (self._search_x, self._found, *history)  # _pair searched at u
        return changed

    def pairs(self, u: np.ndarray) -> ContactPairs:
        """Engaged contact points at displacement ``u``; cached by the flank node positions."""
        x = self.positions(u)
        xn = x[self.nodes]
        key = (self.k_V_kPa, self._version)
        if self._cache is not None and self._cache_key == key and np.array_equal(xn, self._cache_x):
            return self._cache
        if not self.frozen or self._found is None:
            self._search(u)
        key = (self.k_V_kPa, self._version)
        fr = self._found
        assert fr is not None
        t0 = time.perf_counter()
        xq = np.einsum("qi,qij->qj", fr.bary, x[fr.carrier])
        pm = x[fr.master]
        g, lam = _projection(xq, pm[:, 0], pm[:, 1], pm[:, 2])
        w = fade_weight(lam, self.fade_width)[0]
        stiff_all = TWO_PASS_WEIGHT * self.k_V_kPa * fr.area_mm2 / fr.size_mm
        self._cand = (g, fr.size_mm, stiff_all, w)
        act = (g < self.touch_rel * fr.size_mm if self.frozen else fr.engaged) & (w > 0.0)
        out = ContactPairs(
            fr.carrier[act], fr.bary[act], fr.master[act], g[act], stiff_all[act],
            fr.size_mm[act], fr.n_deep, w[act],
        )  # fmt: skip
        self._cache, self._cache_x, self._cache_key = out, xn.copy(), key
        self.evaluations += 1
        self.assembly_time_s += time.perf_counter() - t0
        return out

    # -- energy, forces, tangent ------------------------------------------------------------------

    def _local(self, u: np.ndarray, hessian: bool) -> _Local:
        """Pairs, their 18 dofs (3 slave + 3 master nodes), gradients of the gap and of the fade
        weight, and the Hessian of the gap."""
        pr = self.pairs(u)
        x = self.positions(u)
        nodes = np.concatenate([pr.slave, pr.master], axis=1)  # (na, 6)
        dofs = (3 * nodes[:, :, None] + np.arange(3)).reshape(-1, 18)
        na = len(pr.gap_mm)
        grad_w = np.zeros((na, 18))
        if na == 0:
            H0 = np.zeros((0, 18, 18)) if hessian else None
            return _Local(pr, dofs, np.zeros((0, 18)), grad_w, H0, None)
        xq = np.einsum("qi,qij->qj", pr.bary, x[pr.slave])
        x1, x2, x3 = x[pr.master[:, 0]], x[pr.master[:, 1]], x[pr.master[:, 2]]
        _, g12, H12 = gap_derivatives(xq, x1, x2, x3, hessian)

        def to18(d12: np.ndarray, bary: np.ndarray) -> np.ndarray:
            # x_q = sum_i N_i x_si: d/d(slave node i) = N_i d/dx_q.
            slave = (bary[:, :, None] * d12[:, None, 0:3]).reshape(len(d12), 9)
            return np.concatenate([slave, d12[:, 3:12]], axis=1)

        grad = to18(g12, pr.bary)
        fb = np.flatnonzero(pr.weight < 1.0)
        Hw = None
        if len(fb):
            q = np.concatenate([xq[fb], x1[fb], x2[fb], x3[fb]], axis=1)  # (nb, 12)
            lam, dlam = barycentric_derivatives(q[:, 0:3], q[:, 3:6], q[:, 6:9], q[:, 9:12])
            _, dw, d2w = fade_weight(lam, self.fade_width)
            grad_w[fb] = to18(np.einsum("ni,nij->nj", dw, dlam), pr.bary[fb])
            if hessian:
                # d2w/dq2 = sum_ij d2w/dlam_i dlam_j dlam_i dlam_j^T + sum_i dw/dlam_i d2lam_i;
                # d2lam by central differences of the exact dlam (only fade-band points).
                eps = 1e-6 * pr.size_mm[fb]
                d2lam = np.empty((len(fb), 3, 12, 12))
                for c in range(12):
                    e = np.zeros((len(fb), 12))
                    e[:, c] = eps
                    qp, qm = q + e, q - e
                    dp = barycentric_derivatives(qp[:, 0:3], qp[:, 3:6], qp[:, 6:9], qp[:, 9:12])[1]
                    dm = barycentric_derivatives(qm[:, 0:3], qm[:, 3:6], qm[:, 6:9], qm[:, 9:12])[1]
                    d2lam[:, :, :, c] = (dp - dm) / (2.0 * eps[:, None, None])
                d2lam = 0.5 * (d2lam + np.transpose(d2lam, (0, 1, 3, 2)))
                H12w = np.einsum("nij,nia,njb->nab", d2w, dlam, dlam)
                H12w += np.einsum("ni,niab->nab", dw, d2lam)
                Hw = np.zeros((na, 18, 18))
                Hw[fb] = _expand_hessian(H12w, pr.bary[fb])
        if not hessian:
            return _Local(pr, dofs, grad, grad_w, None, None)
        assert H12 is not None
        return _Local(pr, dofs, grad, grad_w, _expand_hessian(H12, pr.bary, linear_q=True), Hw)

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        pr = self.pairs(u)
        return float(0.5 * np.sum(pr.stiffness * pr.weight * pr.gap_mm**2))

    def force_vector(self, u: np.ndarray) -> np.ndarray:
        """Contact contribution to the residual, dPi_c/du (flat, mN)."""
        lo = self._local(u, hessian=False)
        pr = lo.pairs
        t0 = time.perf_counter()
        c, g = pr.stiffness[:, None], pr.gap_mm[:, None]
        f = c * pr.weight[:, None] * g * lo.grad_g + 0.5 * c * g**2 * lo.grad_w
        out = np.bincount(lo.dofs.ravel(), weights=f.ravel(), minlength=self.n_dofs)
        self.assembly_time_s += time.perf_counter() - t0
        return out

    def tangent_coo(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact tangent d2Pi_c/du2 as COO triplets (rows, cols, values; duplicates add)."""
        lo = self._local(u, hessian=True)
        pr, dofs, grad, gw, H, Hw = lo
        t0 = time.perf_counter()
        assert H is not None
        c = pr.stiffness[:, None, None]
        w = pr.weight[:, None, None]
        # The geometric term, unless dropped beyond exact_depth_rel (module docstring).
        g0 = pr.gap_mm[:, None, None]
        g = np.where(np.abs(pr.gap_mm) <= self.exact_depth_rel * pr.size_mm, pr.gap_mm, 0.0)
        K = c * w * (grad[:, :, None] * grad[:, None, :] + g[:, None, None] * H)
        K += c * g0 * (grad[:, :, None] * gw[:, None, :] + gw[:, :, None] * grad[:, None, :])
        if Hw is not None:
            K += 0.5 * c * g0**2 * Hw
        rows = np.repeat(dofs, 18, axis=1).ravel()
        cols = np.tile(dofs, (1, 18)).ravel()
        self.assembly_time_s += time.perf_counter() - t0
        return rows, cols, K.ravel()

    def tangent_csr(self, u: np.ndarray) -> Any:
        """Contact tangent as a scipy CSR matrix (n_dofs square)."""
        import scipy.sparse

        rows, cols, vals = self.tangent_coo(u)
        t0 = time.perf_counter()
        K = scipy.sparse.coo_matrix((vals, (rows, cols)), shape=(self.n_dofs, self.n_dofs)).tocsr()
        K.sum_duplicates()
        self.assembly_time_s += time.perf_counter() - t0
        return K

    def add_residual(self, b: Any, u: np.ndarray) -> None:
        """Add the contact forces to an assembled PETSc residual vector ``b`` (serial)."""
        if self.k_V_kPa <= 0.0:
            return
        f = self.force_vector(u)
        arr = b.getArray()
        arr += f[: len(arr)]

    def add_jacobian(self, A: Any, u: np.ndarray) -> None:
        """Add the contact tangent to an assembled PETSc matrix ``A`` and re-finalise it.

        New couplings grow the sparsity pattern (allocation errors are switched off for ``A``).
        """
        if self.k_V_kPa <= 0.0:
            return
        from petsc4py import PETSc

        K = self.tangent_csr(u)
        if K.nnz == 0:
            return
        t0 = time.perf_counter()
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        A.setValuesCSR(
            K.indptr.astype(PETSc.IntType),
            K.indices.astype(PETSc.IntType),
            K.data.astype(PETSc.ScalarType),
            addv=PETSc.InsertMode.ADD_VALUES,
        )
        A.assemble()
        self.assembly_time_s += time.perf_counter() - t0

    # -- reporting ------------------------------------------------------------------------------

    def summary(self, u: np.ndarray) -> ContactSummary:
        """Penetration and compressive normal force of the state ``u`` at the current
        ``k_V_kPa``, over all contact candidates at ``u``. Penetration counts only points whose
        projection lies on their master facet (weight 1): in a fade band the point is past the
        facet's edge, where its plane is no longer the body's surface."""
        pr = self.pairs(u)
        g, size, stiff, w = self._cand
        depth = np.maximum(-g, 0.0)
        force = float(np.sum(stiff * w * depth))
        depth = np.where(w >= 1.0, depth, 0.0)
        pen = depth > 0.0
        if not pen.any():
            return ContactSummary(0, 0.0, 0.0, force, pr.n_deep)
        return ContactSummary(
            int(pen.sum()),
            float(depth.max()),
            float(np.max(depth / size)),
            force,
            pr.n_deep,
        )

    def reset_timers(self) -> None:
        """Zero the counters: search time, assembly time, evaluations, searches, refreshes."""
        self.detect_time_s = 0.0  # cumulative: candidate searches
        self.assembly_time_s = 0.0  # cumulative: gaps, residual and tangent contributions
        self.evaluations = 0
        self.searches = 0
        self.refreshes = 0

"""Penalty contact of the two wound flanks (stages 4-6; paper: "material depth contact model").

Formulation: two-pass node-to-surface penalty, evaluated in the DEFORMED configuration.

- Surfaces. The wound surface (facet tag WOUND) is split into two flanks by the reference
  facet centroid, x < x_c (left) and x >= x_c (right), x_c the wound's mirror plane. Each
  facet is oriented so that its normal points out of the body (into the wound cavity). For a
  generic pair of bodies (tests) any two facet sets can be given.
- Gap. For a slave node s of one flank at deformed position x_s and a facet (x_1, x_2, x_3) of
  the opposite (master) flank, g = (x_s - x_1) . n with n = (x_2 - x_1) x (x_3 - x_1) / |...|
  the deformed unit normal. g < 0 means that s is behind the master surface (penetration);
  -g is the depth of s in the master body, measured normal to the master surface.
- Pairing (recomputed at every evaluation, so the residual is a function of u alone): the
  master facet of s is the one closest to x_s (exact point-triangle distance) among the
  ``neighbours`` facets with the nearest centroids (scipy cKDTree over the deformed master
  centroids; facets that contain s are skipped). The pair is active when g < 0, the
  orthogonal projection of x_s lies inside the facet (barycentric coordinates >= -bary_tol),
  the depth -g <= max_depth_mm, and the flanks face each other there
  (n_s . n <= normal_cos, n_s the area-weighted deformed normal of the slave flank at s):
  this last condition keeps the two flanks of a smooth wound bottom (a cylinder's lowest
  line, where the flanks are continuous and coplanar) from being taken for penetration.
- Energy. Per active pair, Pi_c = (w / 2) (k_V / h_s) A_s g^2, with A_s the slave's tributary
  reference area (one third of the reference area of each flank facet around s), h_s the
  local element size (the side of the equilateral triangle whose area is the mean reference
  area of the flank facets around s), and w = 1/2 because each flank is slave once and master
  once (two-pass): when both passes see the same overlap, each carries half of the load.
  The contact pressure per reference area is therefore p = k_V * (-g) / h_s: k_V has stress
  units, like the paper's "material depth" penalty (a layer of thickness h_s with modulus
  k_V). Units: k_V in kPa (1 GPa = 1e6 kPa), lengths in mm, so k_V / h_s is in kPa/mm, the
  pair stiffness c = w k_V A_s / h_s in mN/mm, the normal force c (-g) in mN, energy in
  mN mm. Penetration at a pressure p is -g = p h_s / k_V, i.e. relative to the element size
  p / k_V (1e-4 at p = 100 kPa and k_V = 1 GPa).
- Linearisation. Residual c g dg/dq and tangent c (dg/dq dg/dq^T + g d2g/dq2) over the 12
  coordinates q = (x_s, x_1, x_2, x_3), both exact (analytic, see `gap_derivatives`) for the
  current pairing. The pairing itself (which facet, which pairs are active) is piecewise
  constant in u: Newton sees the exact derivative wherever it is defined; a change of pairing
  between steps is an ordinary non-smooth event of a penalty method, absorbed by the
  relaxation of `woundsweep.newton`. Nothing is frozen within a Newton step.
- Assembly. Residual contributions are summed into the flat dof vector with ``np.bincount``;
  tangent blocks go to the PETSc matrix as one CSR batch (``Mat.setValuesCSR``, ADD_VALUES).
  Couplings across the wound are not in the finite-element sparsity pattern: the matrix is
  allowed to grow (``NEW_NONZERO_ALLOCATION_ERR`` off, ``KEEP_NONZERO_PATTERN`` keeps what
  was added) and MUMPS redoes its symbolic analysis when the pattern changes (PETSc tracks the
  nonzero state).

All evaluation is vectorised over slave nodes (no Python loop over points or cells); the last
pairing is cached by the flank node positions, so a Jacobian at the state of the last residual
costs no second search. Dof layout: node i has dofs 3 i, 3 i + 1, 3 i + 2 (blocked P1).
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
    "gap_derivatives",
    "orient_outward",
    "point_triangle_distance",
    "split_wound_flanks",
]

GPA_TO_KPA = 1.0e6  # stiffness in GPa -> kPa
TWO_PASS_WEIGHT = 0.5  # each flank is slave once and master once


class Surface(NamedTuple):
    """One contact surface in node numbering (reference configuration)."""

    facets: np.ndarray  # (nf, 3) node indices, normal (right-hand rule) points out of the body
    nodes: np.ndarray  # (ns,) the facets' nodes, sorted
    area_mm2: np.ndarray  # (ns,) tributary reference area of each node
    size_mm: np.ndarray  # (ns,) local element size h_s of each node


class ContactPairs(NamedTuple):
    """Active slave/master pairs at one state (both passes together)."""

    slave: np.ndarray  # (na,) slave node
    master: np.ndarray  # (na, 3) master facet nodes
    gap_mm: np.ndarray  # (na,) signed gap: < 0 penetrating, tiny >= 0 touching (no force)
    stiffness: np.ndarray  # (na,) c = w k_V A_s / h_s, mN/mm
    size_mm: np.ndarray  # (na,) h_s
    n_deep: int  # pairs left out because -g > max_depth_mm (0 when all is well)


class ContactSummary(NamedTuple):
    """Scalars of a contact state (the StageResult contact fields plus diagnostics)."""

    n_penetrating: int  # distinct slave nodes with g < 0 in an active pair
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
    gmm = (3.0 * g2 * nn - g2 * eye - d[:, :, None] * n[:, None, :] - n[:, :, None] * d[:, None, :])
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


def point_triangle_distance(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact distance from points to triangles (broadcast over leading axes).

    Returns (distance, signed plane distance g = (p - a) . n, smallest barycentric coordinate
    of the orthogonal projection onto the triangle's plane; >= 0 means inside).
    """
    e0, e1, v = b - a, c - a, p - a
    nrm = np.cross(e0, e1)
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    g = _dot(v, nrm)
    d00, d01, d11 = _dot(e0, e0), _dot(e0, e1), _dot(e1, e1)
    d20, d21 = _dot(v, e0), _dot(v, e1)
    den = d00 * d11 - d01 * d01
    beta = (d11 * d20 - d01 * d21) / den
    gamma = (d00 * d21 - d01 * d20) / den
    bary_min = np.minimum(np.minimum(beta, gamma), 1.0 - beta - gamma)

    def seg(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        e = q1 - q0
        t = np.clip(_dot(p - q0, e) / _dot(e, e), 0.0, 1.0)
        return np.linalg.norm(p - q0 - t[..., None] * e, axis=-1)

    edge = np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a))
    dist = np.where(bary_min >= 0.0, np.abs(g), edge)
    return dist, g, bary_min


def _face_keys(tri: np.ndarray, n: int) -> np.ndarray:
    t = np.sort(np.asarray(tri, dtype=np.int64), axis=1)
    return (t[:, 0] * n + t[:, 1]) * n + t[:, 2]


def orient_outward(X: np.ndarray, cells: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Boundary facets (node indices) reordered so that their normal points out of the body.

    ``X`` (n, 3) node coordinates, ``cells`` (m, 4) tetrahedra in the same node numbering.
    """
    cells = np.asarray(cells, dtype=np.int64)
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 3)
    n = len(X)
    opposite = [(1, 2, 3, 0), (0, 2, 3, 1), (0, 1, 3, 2), (0, 1, 2, 3)]
    faces = np.concatenate([cells[:, list(o[:3])] for o in opposite])
    apex = np.concatenate([cells[:, o[3]] for o in opposite])
    keys = _face_keys(faces, n)
    order = np.argsort(keys)
    want = _face_keys(facets, n)
    pos = np.minimum(np.searchsorted(keys, want, sorter=order), len(order) - 1)
    if not np.all(keys[order[pos]] == want):
        raise ValueError("a contact facet is not a face of any cell")
    inner = X[apex[order[pos]]]
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
    mean_area = tri_area / count
    size = np.sqrt(4.0 * mean_area / np.sqrt(3.0))  # side of the equilateral triangle
    return Surface(facets, nodes, tri_area / 3.0, size)


def split_wound_flanks(
    X: np.ndarray, cells: np.ndarray, wound_facets: np.ndarray, x_c: float
) -> tuple[np.ndarray, np.ndarray]:
    """The wound facets (node indices) split into (left, right) flanks by reference centroid
    x < x_c, each oriented outward (`orient_outward`)."""
    wound_facets = orient_outward(X, cells, wound_facets)
    left = X[wound_facets].mean(axis=1)[:, 0] < x_c
    return wound_facets[left], wound_facets[~left]


class _Pass(NamedTuple):
    slave: Surface
    master: Surface


class FlankContact:
    """Two-pass node-to-surface penalty between two surfaces (see the module docstring).

    ``X`` (n, 3) reference node coordinates; ``left`` and ``right`` (k, 3) outward-oriented
    facets in node numbering. ``k_V_kPa`` (attribute) is the penalty; 0 switches contact off.
    """

    def __init__(
        self,
        X: np.ndarray,
        left: np.ndarray,
        right: np.ndarray,
        *,
        max_depth_mm: float,
        neighbours: int = 12,
        bary_tol: float = 1e-3,
        normal_cos: float = 0.0,
        touch_rel: float = 1e-9,
    ) -> None:
        self.X = np.asarray(X, dtype=float)
        self.n_dofs = 3 * len(self.X)
        a, b = _surface(self.X, np.asarray(left)), _surface(self.X, np.asarray(right))
        self.surfaces = (a, b)
        self.passes = (_Pass(a, b), _Pass(b, a))
        self.nodes = np.union1d(a.nodes, b.nodes)  # every node whose position matters
        self.max_depth_mm = float(max_depth_mm)
        self.neighbours = int(neighbours)
        self.bary_tol = float(bary_tol)
        self.normal_cos = float(normal_cos)
        self.touch_rel = float(touch_rel)
        self.k_V_kPa = 0.0
        self._cache_x: np.ndarray | None = None
        self._cache_k = -1.0
        self._cache: ContactPairs | None = None
        self.detect_time_s = 0.0  # cumulative: search and pairing
        self.assembly_time_s = 0.0  # cumulative: residual and tangent contributions
        self.evaluations = 0

    # -- geometry at a state -------------------------------------------------------------------

    def positions(self, u: np.ndarray) -> np.ndarray:
        """Deformed coordinates (n, 3) of all nodes for flat displacement dofs ``u``."""
        return self.X + np.asarray(u).reshape(-1, 3)

    @staticmethod
    def _node_normals(x: np.ndarray, surf: Surface) -> np.ndarray:
        p = x[surf.facets]
        nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # area-weighted
        idx = np.searchsorted(surf.nodes, surf.facets.ravel())
        acc = np.zeros((len(surf.nodes), 3))
        for k in range(3):
            acc[:, k] = np.bincount(idx, weights=np.repeat(nrm[:, k], 3), minlength=len(acc))
        return acc / np.linalg.norm(acc, axis=1, keepdims=True)

    def _pairs_one(self, x: np.ndarray, ps: _Pass) -> tuple[np.ndarray, ...]:
        sl, ms = ps.slave, ps.master
        xs = x[sl.nodes]
        tri = ms.facets
        centroids = x[tri].mean(axis=1)
        k = min(self.neighbours, len(tri))
        _, cand = cKDTree(centroids).query(xs, k=k)
        cand = np.asarray(cand).reshape(len(xs), k)
        verts = x[tri[cand]]  # (ns, k, 3, 3)
        p = xs[:, None, :]
        dist, g, bmin = point_triangle_distance(p, verts[..., 0, :], verts[..., 1, :], verts[..., 2, :])
        own = np.any(tri[cand] == sl.nodes[:, None, None], axis=2)
        inside = bmin >= -self.bary_tol
        # Ties on shared edges go to a facet that the projection falls into.
        h = sl.size_mm[:, None]
        score = np.where(own, np.inf, dist + np.where(inside, 0.0, 1e-9 * h))
        best = np.argmin(score, axis=1)
        r = np.arange(len(xs))
        g_b, in_b, own_b = g[r, best], inside[r, best], own[r, best]
        facet = cand[r, best]
        n_s = self._node_normals(x, sl)
        pm = x[tri[facet]]
        n_m = np.cross(pm[:, 1] - pm[:, 0], pm[:, 2] - pm[:, 0])
        n_m /= np.linalg.norm(n_m, axis=1, keepdims=True)
        facing = _dot(n_s, n_m) <= self.normal_cos
        # Touching pairs (0 <= g < touch_rel h_s) carry no force but enter the tangent.
        cand_ok = (g_b < self.touch_rel * sl.size_mm) & in_b & ~own_b & facing
        deep = cand_ok & (-g_b > self.max_depth_mm)
        act = cand_ok & ~deep
        stiff = TWO_PASS_WEIGHT * self.k_V_kPa * sl.area_mm2[act] / sl.size_mm[act]
        return (sl.nodes[act], tri[facet[act]], g_b[act], stiff, sl.size_mm[act], int(deep.sum()))

    def pairs(self, u: np.ndarray) -> ContactPairs:
        """Active pairs of both passes at displacement ``u`` (cached by node positions)."""
        x = self.positions(u)
        xn = x[self.nodes]
        if (
            self._cache is not None
            and self._cache_k == self.k_V_kPa
            and np.array_equal(xn, self._cache_x)
        ):
            return self._cache
        t0 = time.perf_counter()
        parts = [self._pairs_one(x, ps) for ps in self.passes]
        out = ContactPairs(
            np.concatenate([p[0] for p in parts]),
            np.concatenate([p[1] for p in parts]).reshape(-1, 3),
            np.concatenate([p[2] for p in parts]),
            np.concatenate([p[3] for p in parts]),
            np.concatenate([p[4] for p in parts]),
            sum(p[5] for p in parts),
        )
        self._cache, self._cache_x, self._cache_k = out, xn.copy(), self.k_V_kPa
        self.detect_time_s += time.perf_counter() - t0
        self.evaluations += 1
        return out

    # -- energy, forces, tangent ------------------------------------------------------------------

    def _local(
        self, u: np.ndarray, hessian: bool
    ) -> tuple[ContactPairs, np.ndarray, np.ndarray, np.ndarray | None]:
        pr = self.pairs(u)
        x = self.positions(u)
        nodes = np.concatenate([pr.slave[:, None], pr.master], axis=1)  # (na, 4)
        dofs = (3 * nodes[:, :, None] + np.arange(3)).reshape(-1, 12)
        if len(pr.slave) == 0:
            return pr, dofs, np.zeros((0, 12)), np.zeros((0, 12, 12)) if hessian else None
        g, grad, H = gap_derivatives(
            x[pr.slave], x[pr.master[:, 0]], x[pr.master[:, 1]], x[pr.master[:, 2]], hessian
        )
        return pr, dofs, grad, H

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        pr = self.pairs(u)
        return float(0.5 * np.sum(pr.stiffness * np.minimum(pr.gap_mm, 0.0) ** 2))

    def force_vector(self, u: np.ndarray) -> np.ndarray:
        """Contact contribution to the residual, dPi_c/du (flat, mN)."""
        pr, dofs, grad, _ = self._local(u, hessian=False)
        t0 = time.perf_counter()
        w = (pr.stiffness * np.minimum(pr.gap_mm, 0.0))[:, None] * grad
        out = np.bincount(dofs.ravel(), weights=w.ravel(), minlength=self.n_dofs)
        self.assembly_time_s += time.perf_counter() - t0
        return out

    def tangent_coo(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact tangent d2Pi_c/du2 as COO triplets (rows, cols, values; duplicates add)."""
        pr, dofs, grad, H = self._local(u, hessian=True)
        t0 = time.perf_counter()
        assert H is not None
        c = pr.stiffness[:, None, None]
        gneg = np.minimum(pr.gap_mm, 0.0)[:, None, None]
        K = c * (grad[:, :, None] * grad[:, None, :] + gneg * H)
        rows = np.repeat(dofs, 12, axis=1).ravel()
        cols = np.tile(dofs, (1, 12)).ravel()
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
        """Penetration and force of the state ``u`` at the current ``k_V_kPa``."""
        pr = self.pairs(u)
        depth = np.maximum(-pr.gap_mm, 0.0)
        pen = depth > 0.0
        if not pen.any():
            return ContactSummary(0, 0.0, 0.0, 0.0, pr.n_deep)
        return ContactSummary(
            int(len(np.unique(pr.slave[pen]))),
            float(depth.max()),
            float(np.max(depth / pr.size_mm)),
            float(np.sum(pr.stiffness * depth)),
            pr.n_deep,
        )

    def reset_timers(self) -> None:
        self.detect_time_s = self.assembly_time_s = 0.0
        self.evaluations = 0

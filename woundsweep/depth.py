"""Material-depth penalty contact (stages 4-6; paper: "material depth contact model", its [12]).

Units: lengths mm, k_V kPa (1 GPa = 1e6 kPa), forces mN, energy mN mm. Selected with the sweep
setting ``stages.contact_model: depth`` (the default is the surface model, `woundsweep.contact`;
docs/design.md compares the two).

The body is split into two sides (``cell_side``, one flag per tetrahedron; the wound model
uses the wound's mirror plane, x < x_c). A contact surface facet belongs to the side of the
cell it bounds. Contact is two-pass: the contact points of one side's surface (the slave) are
tested against the tetrahedra of the other side (the master body), and vice versa.

- Material depth. phi_s(X) is the distance, in the REFERENCE configuration, from a point of
  side s to the contact surface of side s (its wound flank). It is computed exactly at the
  nodes (nearest facets by a KD-tree, exact point-triangle distances) and interpolated
  linearly (P1) in each tetrahedron. The master region of side s is its cells with a node
  within ``layers`` (3) facet sizes of its contact surface (at most max_depth_mm). Measuring
  the depth to the skin surface as well (so that a lip sliding onto the other lip's top
  enters at depth 0) was tried: it tilts the force near the rim toward the skin surface, and
  no 45-degree job of a sample of 6 passed with it (docs/design.md).
- Penetration. A slave point q (the six contact points per facet of `woundsweep.contact`) at
  deformed position x_q penetrates when it lies inside a deformed master tetrahedron T
  (barycentric coordinates lam(x_q) >= 0); its depth is phi(x_q) = sum_i lam_i phi_i, the
  material depth of the master point that it occupies. Inside/outside is decided by the
  deformed body itself, not by a facet's extended plane, so a point that slides past an edge
  of the master surface over a convex fold is never taken for penetrating (the false
  penetrations of the surface model, docs/design.md). phi = 0 on the contact surface and is
  continuous, so a point's force vanishes continuously as it leaves the body there (a point
  that enters a master cell through another boundary, such as the skin surface next to the
  rim, starts with a small depth: a jump).
  Touching counts (phi > -touch_rel h): such a point carries no force but its stiffness.
- Force. Energy Pi_c = sum_q (c_q / 2) phi_q^2 with c_q = w k_V A_q / h_q (w = 1/2 for the two
  passes, A_q the reference area the point carries, h_q its facet size): pressure k_V phi / h
  per reference area, as in `woundsweep.contact` (for a homogeneous stretch l normal to the
  surface the deformed overlap is d = l phi, so p = k_V d / (h l^2)). Its exact gradient
  c phi grad_x phi has the direction of T's depth gradient, which jumps between cells, so the
  residual jumps too. With ``smooth_normal`` (default) the direction is
  n(x_q) = sum_i lam_i n_i instead, n_i the volume-weighted mean of grad_x phi over the master
  cells around node i (deformed): the residual is continuous. The reaction on master node j is
  -lam_j times the force on the point (d lam / d y_j = -lam_j d lam / d x): forces balance.
- Linearisation. The tangent is the exact derivative of each point's force with respect to
  x_q and T's four nodes (central differences, step 1e-6 h, of the closed-form force; x_q
  spread over its facet's nodes by the shape functions). The nodal normals depend on all the
  nodes around them; their change is not in the tangent but is handled like the surface
  model's pairing: `freeze` keeps the normals of the increment's start, and at convergence
  `refresh` recomputes them and reports whether the forces moved by more than the tolerance
  (Newton then continues). With ``smooth_normal`` the tangent is not symmetric (MUMPS LU
  does not need it to be).

Point location is vectorised (no Python loop over points or cells): a KD-tree of the deformed
master cells' centroids gives each point its ``candidates`` nearest cells (within the largest
centroid-vertex distance), whose barycentric coordinates are computed at once (3 x 3 inverses
by cofactors). Dof layout: node i has dofs 3 i .. 3 i + 2.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from .contact import (
    TWO_PASS_WEIGHT,
    ContactSummary,
    _contact_points,
    _surface,
    orient_outward,
    owning_cells,
    point_triangle_distance,
)

__all__ = ["DepthContact", "DepthState", "material_depth"]


def material_depth(X: np.ndarray, nodes: np.ndarray, facets: np.ndarray, k: int = 16) -> np.ndarray:
    """Exact distance (mm) from the points ``X[nodes]`` to the triangles ``X[facets]``.

    The ``k`` facets with the nearest centroids are measured exactly; nodes of the facets
    themselves get 0.
    """
    p = X[nodes]
    k = min(k, len(facets))
    _, cand = cKDTree(X[facets].mean(axis=1)).query(p, k=k)
    cand = np.asarray(cand).reshape(len(p), k)
    t = X[facets[cand]]  # (n, k, 3, 3)
    d = point_triangle_distance(p[:, None, :], t[..., 0, :], t[..., 1, :], t[..., 2, :])[0]
    out = d.min(axis=1)
    out[np.isin(nodes, facets)] = 0.0
    return out


class DepthState(NamedTuple):
    """Penetrating contact points of both passes at one state."""

    carrier: np.ndarray  # (na, 3) nodes of the slave facet that holds the point
    bary: np.ndarray  # (na, 3) the point's shape function values on that facet
    cell: np.ndarray  # (na, 4) nodes of the master cell that contains it
    cell_phi: np.ndarray  # (na, 4) material depth at those nodes (mm)
    cell_normal: np.ndarray  # (na, 4, 3) smoothed depth gradient at those nodes (or zeros)
    depth: np.ndarray  # (na,) material depth phi of the point (mm)
    grad: np.ndarray  # (na, 3) grad_x phi in the master cell (deformed, 1/1)
    stiffness: np.ndarray  # (na,) c = w k_V A_q / h_q, mN/mm
    size_mm: np.ndarray  # (na,) h_q
    n_deep: int  # points deeper than the region cap (depth_cap_mm)


def _inv3(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverses and determinants of 3 x 3 matrices (n, 3, 3) by cofactors (numpy's batched
    inv calls LAPACK once per matrix: 30 times slower here)."""
    a, b, c = M[:, :, 0], M[:, :, 1], M[:, :, 2]  # columns
    r0, r1, r2 = np.cross(b, c), np.cross(c, a), np.cross(a, b)  # rows of det * M^-1
    det = np.einsum("ni,ni->n", a, r0)
    return np.stack([r0, r1, r2], axis=1) / det[:, None, None], det


def _cell_force(
    x: np.ndarray,
    y: np.ndarray,
    phi: np.ndarray,
    nodal: np.ndarray | None,
    c: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """Contact force blocks (n, 5, 3) on (x_q, y_0..y_3) of points x (n, 3) in cells y (n, 4, 3)
    with nodal depths phi (n, 4) and nodal normals (n, 4, 3) (None: the cell's depth gradient);
    also lam (n, 4), phi(x) (n,), grad_x phi (n, 3), force direction (n, 3)."""
    Minv = _inv3(np.transpose(y[:, 1:] - y[:, :1], (0, 2, 1)))[0]
    l123 = np.einsum("nij,nj->ni", Minv, x - y[:, 0])
    lam = np.concatenate([1.0 - l123.sum(axis=1, keepdims=True), l123], axis=1)
    grads = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)  # (n, 4, 3)
    g = np.einsum("ni,nij->nj", phi, grads)
    d = np.einsum("ni,ni->n", lam, phi)
    n = g if nodal is None else np.einsum("ni,nij->nj", lam, nodal)
    r = (c * d)[:, None] * n
    coef = np.concatenate([np.ones((len(x), 1)), -lam], axis=1)  # d lam / d y_j = -lam_j d lam / dx
    return coef[:, :, None] * r[:, None, :], lam, d, g, n


class _Region(NamedTuple):
    cells: np.ndarray  # (nt, 4) master cells of one side
    phi: np.ndarray  # (nt, 4) material depth at their nodes


class DepthContact:
    """Two-pass material-depth penalty between the two sides of a body (module docstring).

    ``X`` (n, 3) reference node coordinates, ``cells`` (m, 4) tetrahedra, ``cell_side`` (m,)
    bool (True: side 1), ``surface`` (k, 3) facets that can touch the other side (any
    orientation). ``k_V_kPa`` (attribute) is the penalty; 0 switches contact off.
    """

    def __init__(
        self,
        X: np.ndarray,
        cells: np.ndarray,
        cell_side: np.ndarray,
        surface: np.ndarray,
        *,
        max_depth_mm: float,
        candidates: int = 16,
        smooth_normal: bool = True,
        touch_rel: float = 1e-9,
        layers: float = 3.0,
    ) -> None:
        self.X = np.asarray(X, dtype=float)
        self.n_dofs = 3 * len(self.X)
        cells = np.asarray(cells, dtype=np.int64)
        side = np.asarray(cell_side, dtype=bool)
        surface = orient_outward(self.X, cells, surface)
        facet_side = side[owning_cells(cells, surface, len(self.X))]
        self.facets = (surface[~facet_side], surface[facet_side])
        self.points = tuple(_contact_points(self.X, f) for f in self.facets)
        self.surfaces = tuple(_surface(self.X, f) for f in self.facets)  # (side 0, side 1)
        # The master region: cells within ``layers`` surface element sizes of the surface (and
        # max_depth_mm); overlaps are a small fraction of an element, so deeper cells would
        # only cost point location time.
        size = max(float(np.max(p.size_mm)) for p in self.points)
        cap = min(float(max_depth_mm), layers * size)
        self.depth_cap_mm = cap
        regions = []
        for s in (False, True):
            own = cells[side == s]
            depth = material_depth(self.X, own.ravel(), self.facets[int(s)]).reshape(-1, 4)
            regions.append(_Region(own[depth.min(axis=1) <= cap], depth[depth.min(axis=1) <= cap]))
        self.regions = tuple(regions)
        self.nodes = np.unique(
            np.concatenate([*self.facets, *(r.cells for r in regions)], axis=None)
        )
        self.max_depth_mm = float(max_depth_mm)
        self.candidates = int(candidates)
        self.smooth_normal = bool(smooth_normal)
        self.touch_rel = float(touch_rel)
        self.k_V_kPa = 0.0
        self.frozen = False  # True: the nodal normals of the last `freeze` are used
        self._nodal: list[np.ndarray | None] = [None, None]
        self._cache_x: np.ndarray | None = None
        self._cache: DepthState | None = None
        self._cache_k = -1.0
        self.reset_timers()

    def positions(self, u: np.ndarray) -> np.ndarray:
        """Deformed coordinates (n, 3) of all nodes for flat displacement dofs ``u``."""
        return self.X + np.asarray(u).reshape(-1, 3)

    def _normals(self, x: np.ndarray, side: int) -> np.ndarray:
        """Smoothed depth gradient at every node (n, 3): the volume-weighted mean of grad_x phi
        over the master cells of ``side`` around the node (zero off them)."""
        reg = self.regions[side]
        y = x[reg.cells]
        Minv, det = _inv3(np.transpose(y[:, 1:] - y[:, :1], (0, 2, 1)))
        grads = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)
        gt = np.einsum("ti,tij->tj", reg.phi, grads)
        vol = np.repeat(np.abs(det) / 6.0, 4)
        flat = reg.cells.ravel()
        den = np.bincount(flat, weights=vol, minlength=len(x))
        num = [np.bincount(flat, weights=vol * np.repeat(gt[:, c], 4), minlength=len(x))
               for c in range(3)]  # fmt: skip
        return np.stack(num, axis=1) / np.maximum(den, 1e-300)[:, None]

    def freeze(self, u: np.ndarray) -> None:
        """Keep the nodal normals of ``u`` (``smooth_normal``) until the next `freeze` or
        `unfreeze`: within a load increment the force direction field is then fixed, so the
        tangent is exact; `refresh` updates it (an outer fixed point, as for the surface
        model). Point location and depths stay live."""
        if not self.smooth_normal:
            return
        x = self.positions(u)
        self._nodal = [self._normals(x, 0), self._normals(x, 1)]
        self.frozen = True
        self._cache = None

    def unfreeze(self) -> None:
        """Compute the nodal normals afresh at every state again."""
        self.frozen = False
        self._nodal = [None, None]
        self._cache = None

    def refresh(self, u: np.ndarray, tol: float) -> bool:
        """Update frozen normals at ``u``; True when that changes the contact forces by more
        than ``tol`` (mN, Euclidean norm)."""
        if not self.frozen or self.k_V_kPa <= 0.0:
            return False
        before = self.force_vector(u)
        self.freeze(u)
        after = self.force_vector(u)
        self.refreshes += 1
        return bool(np.linalg.norm(after - before) > tol)

    # -- point location ---------------------------------------------------------------------

    def _pass(self, x: np.ndarray, slave: int) -> tuple[np.ndarray, ...]:
        qp, reg = self.points[slave], self.regions[1 - slave]
        pts = np.einsum("qi,qij->qj", qp.bary, x[qp.carrier])
        y = x[reg.cells]  # (nt, 4, 3)
        M = np.transpose(y[:, 1:] - y[:, :1], (0, 2, 1))  # columns y_i - y_0
        Minv, det = _inv3(M)  # rows: grad lam_1..3
        grads = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)  # (nt, 4, 3)
        cen = y.mean(axis=1)
        reach = float(np.sqrt(np.max(np.sum((y - cen[:, None]) ** 2, axis=2))))
        k = min(self.candidates, len(cen))
        dist, cand = cKDTree(cen).query(pts, k=k, distance_upper_bound=reach * (1 + 1e-9))
        cand = np.asarray(cand).reshape(len(pts), k)
        near = np.isfinite(np.asarray(dist).reshape(len(pts), k))
        cand = np.where(near, cand, 0)
        l123 = np.einsum("nkij,nkj->nki", Minv[cand], pts[:, None, :] - y[cand, 0])
        lam = np.concatenate([1.0 - l123.sum(axis=2, keepdims=True), l123], axis=2)
        lmin = np.where(near, lam.min(axis=2), -np.inf)
        best = np.argmax(lmin, axis=1)
        r = np.arange(len(pts))
        inside = lmin[r, best] >= -self.touch_rel
        cell = cand[r, best][inside]
        lam = lam[r, best][inside]
        phi = np.einsum("ni,ni->n", lam, reg.phi[cell])
        # Touching counts (phi > -touch_rel h), as in `woundsweep.contact`: a point on the
        # master surface carries no force but its stiffness, which holds a touching start.
        keep = phi > -self.touch_rel * qp.size_mm[inside]
        hit = np.flatnonzero(inside)[keep]
        cell, lam, phi = cell[keep], lam[keep], phi[keep]
        g = np.einsum("ni,nij->nj", reg.phi[cell], grads[cell])
        if self.smooth_normal:
            frozen = self._nodal[1 - slave] if self.frozen else None
            nodal = frozen if frozen is not None else self._normals(x, 1 - slave)
            cn = nodal[reg.cells[cell]]
        else:
            cn = np.zeros((len(cell), 4, 3))
        stiff = TWO_PASS_WEIGHT * self.k_V_kPa * qp.area_mm2[hit] / qp.size_mm[hit]
        return (qp.carrier[hit], qp.bary[hit], reg.cells[cell], reg.phi[cell], cn, phi, g, stiff,
                qp.size_mm[hit])  # fmt: skip

    def state(self, u: np.ndarray) -> DepthState:
        """Penetrating points of both passes at ``u``; cached by the contact nodes' positions."""
        x = self.positions(u)
        xn = x[self.nodes]
        if self._cache is not None and self._cache_k == self.k_V_kPa:
            if np.array_equal(xn, self._cache_x):
                return self._cache
        t0 = time.perf_counter()
        parts = [self._pass(x, s) for s in (0, 1)]
        cols = [np.concatenate([p[i] for p in parts]) for i in range(9)]
        n_deep = int(np.sum(cols[5] > self.depth_cap_mm))
        out = DepthState(*cols, n_deep)
        self._cache, self._cache_x, self._cache_k = out, xn.copy(), self.k_V_kPa
        self.detect_time_s += time.perf_counter() - t0
        self.searches += 1
        self.evaluations += 1
        return out

    # -- energy, forces, tangent --------------------------------------------------------------

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        st = self.state(u)
        return float(0.5 * np.sum(st.stiffness * st.depth**2))

    def _dofs(self, st: DepthState) -> np.ndarray:
        nodes = np.concatenate([st.carrier, st.cell], axis=1)  # (na, 7)
        return (3 * nodes[:, :, None] + np.arange(3)).reshape(-1, 21)

    def _blocks(self, st: DepthState, x: np.ndarray, dx: np.ndarray | None = None) -> np.ndarray:
        """Force blocks (na, 5, 3) on (x_q, y_0..y_3); ``dx`` (na, 5, 3) perturbs them."""
        xq = np.einsum("ni,nij->nj", st.bary, x[st.carrier])
        y = x[st.cell]
        if dx is not None:
            xq, y = xq + dx[:, 0], y + dx[:, 1:]
        nodal = st.cell_normal if self.smooth_normal else None
        return _cell_force(xq, y, st.cell_phi, nodal, st.stiffness)[0]

    def _to_nodes(self, st: DepthState) -> np.ndarray:
        """(na, 5, 7): x_q = sum_a N_a x_a over the slave facet; y_j are master nodes."""
        P = np.zeros((len(st.depth), 5, 7))
        P[:, 0, :3] = st.bary
        P[:, 1:, 3:] = np.eye(4)
        return P

    def force_vector(self, u: np.ndarray) -> np.ndarray:
        """Contact contribution to the residual (flat, mN): c phi n on the point, -lam_j times
        that on master node j, the point's share spread over its facet's nodes."""
        st = self.state(u)
        t0 = time.perf_counter()
        f = np.einsum("npa,npi->nai", self._to_nodes(st), self._blocks(st, self.positions(u)))
        out = np.bincount(self._dofs(st).ravel(), weights=f.ravel(), minlength=self.n_dofs)
        self.assembly_time_s += time.perf_counter() - t0
        return out

    def tangent_coo(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact tangent as COO triplets (rows, cols, values; duplicates add): the exact
        derivative of the force blocks of each point's cell (central differences over the 15
        coordinates of x_q and the cell's nodes, step 1e-6 h), the nodal normals held fixed."""
        st = self.state(u)
        t0 = time.perf_counter()
        x = self.positions(u)
        na = len(st.depth)
        J = np.empty((na, 5, 3, 5, 3))
        eps = 1e-6 * st.size_mm
        for p in range(5):
            for i in range(3):
                d = np.zeros((na, 5, 3))
                d[:, p, i] = eps
                J[:, :, :, p, i] = (self._blocks(st, x, d) - self._blocks(st, x, -d)) / (
                    2.0 * eps[:, None, None]
                )
        P = self._to_nodes(st)
        K = np.einsum("npa,npiqj,nqb->naibj", P, J, P).reshape(na, 21, 21)
        dofs = self._dofs(st)
        rows = np.repeat(dofs, 21, axis=1).ravel()
        cols = np.tile(dofs, (1, 21)).ravel()
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
        """Add the contact tangent to an assembled PETSc matrix ``A`` and re-finalise it."""
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

    # -- reporting ----------------------------------------------------------------------------

    def summary(self, u: np.ndarray) -> ContactSummary:
        """Penetrating points, the largest deformed penetration depth phi / |grad_x phi| (mm
        and relative to h_q), and the total contact force sum c phi |n| (mN) at ``u``."""
        st = self.state(u)
        pen = st.depth > 0.0
        if not pen.any():
            return ContactSummary(0, 0.0, 0.0, 0.0, 0)
        st = DepthState(*(a[pen] for a in st[:-1]), st.n_deep)
        depth = st.depth / np.linalg.norm(st.grad, axis=1)
        n = st.grad
        if self.smooth_normal:
            xq = np.einsum("ni,nij->nj", st.bary, self.positions(u)[st.carrier])
            y = self.positions(u)[st.cell]
            n = _cell_force(xq, y, st.cell_phi, st.cell_normal, st.stiffness)[4]
        force = float(np.sum(st.stiffness * st.depth * np.linalg.norm(n, axis=1)))
        return ContactSummary(
            len(depth), float(depth.max()), float(np.max(depth / st.size_mm)), force, st.n_deep
        )

    def reset_timers(self) -> None:
        """Zero the counters: location time, assembly time, evaluations, searches, refreshes."""
        self.detect_time_s = 0.0
        self.assembly_time_s = 0.0
        self.evaluations = 0
        self.searches = 0
        self.refreshes = 0

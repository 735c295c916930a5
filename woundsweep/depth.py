"""Material-depth penalty contact (stages 4-6; paper: "material depth contact model", its [12]).

Units: lengths mm, k_V kPa (1 GPa = 1e6 kPa), forces mN, energy mN mm. Selected with the sweep
setting ``stages.contact_model: depth`` (the default is the surface model, `woundsweep.contact`;
docs/design.md compares the two).

The body is split into two sides (``cell_side``, one flag per tetrahedron; the wound model
uses the wound's mirror plane, x < x_c). A contact surface facet belongs to the side of the
cell it bounds. Contact is two-pass: the contact points of one side's surface (the slave) are
tested against the tetrahedra of the other side (the master body), and vice versa.

- Material depth. phi_s(X) is the distance, in the REFERENCE configuration, from a point of
  side s to the contact surface of side s (its wound flank). The master region of side s is
  its cells with a node within ``layers`` (3) facet sizes of its contact surface (at most
  max_depth_mm). With ``exact_depth`` (the wound model's setting, `WOUND_OPTIONS`) a point's
  depth is the exact distance of the material point it occupies, X_q = sum_i lam_i X_i, to
  the nearest of the ``near_facets`` contact facets closest to its cell (unsigned: a located
  point is inside the body). The distance to a faceted surface is C1 away from the medial
  axis, so the stiffness does not jump between cells (only through F^-T). Without it, phi is
  the P1 interpolant of the exact nodal distances, whose gradient jumps between cells by
  O(h / R) on a surface of curvature radius R: measured on 45-degree cylinders, those jumps
  stop Newton at a fixed penalty however small the increment.
- Penetration. A slave point q (the six contact points per facet of `woundsweep.contact`) at
  deformed position x_q penetrates when it lies inside a deformed master tetrahedron T
  (barycentric coordinates lam(x_q) >= 0). Inside/outside is decided by the deformed body
  itself, not by a facet's extended plane, so a point that slides past an edge of the master
  surface over a convex fold is never taken for penetrating (the false penetrations of the
  surface model, docs/design.md). phi = 0 on the contact surface, so a point's force vanishes
  continuously as it leaves the body there.
- Exits. A point can also enter the master side through its other boundary facets
  (`side_exits`: the skin surface next to the rim, the plane where the sides join beyond the
  wound's ends), already at a depth phi > 0: the force would jump. With ``exit_fade`` = a the
  force is multiplied by s(psi / (a phi)), s the C1 ramp of `exit_weight` and psi the exact
  distance of the material point to the nearest exit facet: 0 on an exit, 1 once psi > a phi,
  so only points within about their own depth of an exit are weakened (a band that shrinks
  with the penetration, i.e. like 1 / k_V).
- Force. Magnitude c_q r(phi) with c_q = w k_V A_q / h_q (w = 1/2 for the two passes, A_q the
  reference area the point carries, h_q its facet size): pressure k_V phi / h per reference
  area, as in `woundsweep.contact` (for a homogeneous stretch l normal to the surface the
  deformed overlap is d = l phi, so p = k_V d / (h l^2)). r(phi) = phi, or with
  ``engage_kPa`` = e a C1 engagement: r = delta t^2 (2 - t), t = phi / delta, below
  delta = e h / k_V and phi above it (the stiffness grows from 0 instead of jumping to c at
  contact; r depends on k_V phi only, so overlaps still scale like 1 / k_V, and above the
  contact pressure e the law is unchanged). Direction: with ``smooth_normal`` (default)
  n(x_q) = sum_i lam_i n_i, n_i the volume-weighted mean of grad_x phi_P1 over the master
  cells around node i (deformed), so the residual is continuous; otherwise the depth
  gradient. The reaction on master node j is -lam_j times the force on the point
  (d lam / d y_j = -lam_j d lam / d x): forces balance. `energy` is (c/2) phi^2 (the potential
  of the depth-gradient variant without ramp and fade).
- Linearisation. The tangent is the exact derivative of each point's force with respect to
  x_q and T's four nodes (central differences of the closed-form force, step 1e-6 h, and at
  most 1 % of delta with the ramp; x_q spread over its facet's nodes by the shape functions).
  The nodal normals depend on the nodes of all the master cells around them. With
  ``linearised`` (the wound model's setting) that dependence is in the tangent too (a sparse
  product, `_normal_tangent`), which is then the exact derivative of the force. Without it,
  `freeze` keeps the normals of a load increment's start and `refresh` recomputes them at
  convergence (Newton then continues if the forces moved): measured on a 45-degree cylinder,
  that outer fixed point contracts by 0.9 to 1.0 per refresh, or not at all. The tangent is
  not symmetric (MUMPS LU does not need it to be).

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
    _face_keys,
    _surface,
    orient_outward,
    owning_cells,
    point_triangle_distance,
)

__all__ = [
    "WOUND_OPTIONS",
    "DepthContact",
    "DepthState",
    "exit_weight",
    "material_depth",
    "side_exits",
]

# The configuration of the wound model (stages.py) and of its known-answer tests: exact depth,
# live normals in the tangent, exits faded over the depth, engagement below 10 MPa (measured
# at 45 degrees, docs/design.md: with 1 kPa an entering point's stiffness rose over 1e-6 h and
# 1 of 7 jobs went through; with 1e4 kPa, over 1 % of h at 1 GPa, 2 to 3 of the 7).
WOUND_OPTIONS: dict[str, Any] = {
    "exact_depth": True,
    "linearised": True,
    "exit_fade": 1.0,
    "engage_kPa": 1e4,
}


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


def _near(X: np.ndarray, cells: np.ndarray, facets: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` facets (indices) with centroids nearest to each cell's centroid (n, k)."""
    k = min(k, len(facets))
    near = cKDTree(X[facets].mean(axis=1)).query(X[cells].mean(axis=1), k=k)[1]
    return np.asarray(near).reshape(len(cells), k)


def _nearest(
    X: np.ndarray, p: np.ndarray, facets: np.ndarray, cand: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest of the candidate facets ``cand`` (n, k) to the points p (n, 3): its nodes
    (n, 3), exact distance (n,) and signed plane distance (n,)."""
    tri = X[facets[cand]]  # (n, k, 3, 3)
    dist, plane, _ = point_triangle_distance(
        p[:, None, :], tri[:, :, 0], tri[:, :, 1], tri[:, :, 2]
    )
    pick = np.argmin(dist, axis=1)
    r = np.arange(len(p))
    return facets[cand[r, pick]], dist[r, pick], plane[r, pick]


def side_exits(cells: np.ndarray, surface: np.ndarray) -> np.ndarray:
    """Boundary facets (k, 3) of the cell set ``cells`` other than ``surface``: where a point
    can enter the side without crossing its contact surface (the skin surface, the plane where
    the sides join beyond the wound's ends, the patch's faces)."""
    faces = cells[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3)
    n = int(max(cells.max(), np.max(surface))) + 1
    keys = _face_keys(faces, n)
    _, first, count = np.unique(keys, return_index=True, return_counts=True)
    bnd = first[count == 1]
    return faces[bnd[~np.isin(keys[bnd], _face_keys(surface, n))]]


class DepthState(NamedTuple):
    """Penetrating contact points of both passes at one state."""

    carrier: np.ndarray  # (na, 3) nodes of the slave facet that holds the point
    bary: np.ndarray  # (na, 3) the point's shape function values on that facet
    cell: np.ndarray  # (na, 4) nodes of the master cell that contains it
    cell_phi: np.ndarray  # (na, 4) material depth at those nodes (mm)
    cell_normal: np.ndarray  # (na, 4, 3) smoothed depth gradient at those nodes (or zeros)
    exit_facet: np.ndarray  # (na, 3) nearest exit facet of the master side (exit_fade)
    depth: np.ndarray  # (na,) material depth phi of the point (mm)
    stiffness: np.ndarray  # (na,) c = w k_V A_q / h_q, mN/mm
    size_mm: np.ndarray  # (na,) h_q
    master: np.ndarray  # (na,) side of the master cell (0 or 1)
    facet: np.ndarray  # (na, 3) nearest master contact facet (exact_depth; else zeros)
    n_deep: int  # points deeper than the region cap (depth_cap_mm)


def _inv3(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverses and determinants of 3 x 3 matrices (n, 3, 3) by cofactors (numpy's batched
    inv calls LAPACK once per matrix: 30 times slower here)."""
    a, b, c = M[:, :, 0], M[:, :, 1], M[:, :, 2]  # columns
    r0, r1, r2 = np.cross(b, c), np.cross(c, a), np.cross(a, b)  # rows of det * M^-1
    det = np.einsum("ni,ni->n", a, r0)
    return np.stack([r0, r1, r2], axis=1) / det[:, None, None], det


def exit_weight(psi: np.ndarray, width: np.ndarray) -> np.ndarray:
    """C1 ramp s(t) = 3 t^2 - 2 t^3, t = clip(psi / width, 0, 1): 0 on an exit, 1 beyond width."""
    t = np.clip(psi / np.maximum(width, 1e-300), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _cell_force(
    x: np.ndarray,
    y: np.ndarray,
    phi: np.ndarray,
    nodal: np.ndarray | None,
    c: np.ndarray,
    *,
    exit_tri: np.ndarray | None = None,
    fade: float = 0.0,
    ref: np.ndarray | None = None,
    tri: np.ndarray | None = None,
    delta: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """Contact force blocks (n, 5, 3) on (x_q, y_0..y_3) of points x (n, 3) in cells y (n, 4, 3).

    The depth is the P1 interpolant of the nodal depths phi (n, 4), or with ``ref`` (n, 4, 3,
    the cell's reference nodes) and ``tri`` (n, 3, 3, a reference facet, outward) the exact
    distance of the occupied material point to that facet. The direction is the nodal
    normals (n, 4, 3) interpolated (None: grad_x of the depth). The magnitude c phi is ramped
    in over ``delta`` (n,) (c delta t^2 (2 - t), t = phi / delta, below it: C1, and c phi above
    it, so the penalty law is unchanged beyond delta) and faded
    by `exit_weight` of the material point's exact distance to the exit facet ``exit_tri``
    (n, 3, 3) over ``fade`` times the depth when given (needs ``ref``).
    Also returns lam (n, 4), the depth (n,), grad_x of the depth (n, 3), the direction (n, 3)
    and the magnitude (n,).
    """
    Minv = _inv3(np.transpose(y[:, 1:] - y[:, :1], (0, 2, 1)))[0]
    l123 = np.einsum("nij,nj->ni", Minv, x - y[:, 0])
    lam = np.concatenate([1.0 - l123.sum(axis=1, keepdims=True), l123], axis=1)
    grads = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)  # (n, 4, 3)
    Xq = None if ref is None else np.einsum("ni,nij->nj", lam, ref)  # the material point
    if tri is None or ref is None:
        g = np.einsum("ni,nij->nj", phi, grads)
        d = np.einsum("ni,ni->n", lam, phi)
    else:
        d = point_triangle_distance(Xq, tri[:, 0], tri[:, 1], tri[:, 2])[0]
        m = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        inward = -m / np.linalg.norm(m, axis=1, keepdims=True)
        # grad_x of X . N for the reference direction N: F^-T N
        g = np.einsum("ni,nij->nj", np.einsum("nij,nj->ni", ref, inward), grads)
    n = g if nodal is None else np.einsum("ni,nij->nj", lam, nodal)
    mag = c * d
    if delta is not None:
        dl = np.maximum(delta, 1e-300)
        t = np.clip(d / dl, 0.0, 1.0)
        mag = c * np.where(d < dl, dl * t * t * (2.0 - t), d)
    if exit_tri is not None and Xq is not None and fade > 0.0:
        psi = point_triangle_distance(Xq, exit_tri[:, 0], exit_tri[:, 1], exit_tri[:, 2])[0]
        mag = mag * exit_weight(psi, fade * np.maximum(d, 0.0))
    r = mag[:, None] * n
    coef = np.concatenate([np.ones((len(x), 1)), -lam], axis=1)  # d lam / d y_j = -lam_j d lam / dx
    return coef[:, :, None] * r[:, None, :], lam, d, g, n, mag


class _Region(NamedTuple):
    cells: np.ndarray  # (nt, 4) master cells of one side
    phi: np.ndarray  # (nt, 4) material depth at their nodes
    near: np.ndarray  # (nt, k) contact facets nearest to the cell (exact_depth)
    near_exit: np.ndarray | None  # (nt, k) exit facets nearest to the cell (exit_fade)


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
        linearised: bool = False,
        exact_depth: bool = False,
        near_facets: int = 8,
        engage_kPa: float = 0.0,
        exit_depth: bool = False,
        touch_rel: float = 1e-9,
        layers: float = 3.0,
        exit_fade: float = 0.0,
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
        self.exits: list[np.ndarray | None] = [None, None]
        for s in (False, True):
            own = cells[side == s]
            depth = material_depth(self.X, own.ravel(), self.facets[int(s)]).reshape(-1, 4)
            near = depth.min(axis=1) <= cap
            own, depth = own[near], depth[near]
            use = exit_fade > 0 or exit_depth
            exits = side_exits(cells[side == s], self.facets[int(s)]) if use else None
            if exits is not None and len(exits) == 0:
                raise ValueError("exits need boundary facets other than the contact surface")
            self.exits[int(s)] = exits
            if exit_depth and exits is not None:
                depth = np.minimum(depth, material_depth(self.X, own.ravel(), exits).reshape(-1, 4))
            regions.append(
                _Region(own, depth, _near(self.X, own, self.facets[int(s)], near_facets),
                        None if exits is None else _near(self.X, own, exits, near_facets))
            )  # fmt: skip
        self.regions = tuple(regions)
        self.exit_fade = float(exit_fade)
        self.engage_kPa = float(engage_kPa)
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
        self.linearised = bool(linearised) and self.smooth_normal
        self.exact_depth = bool(exact_depth)
        self.exit_depth = bool(exit_depth) and self.exact_depth
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

    def _normal_jacobian(self, x: np.ndarray, side: int) -> Any:
        """d n_i / d x_m of `_normals` (sparse, 3 n x 3 n, row 3 i + a, column 3 m + b).

        n_i = N_i / D_i with N_i = sum_K v_K g_K and D_i = sum_K v_K over the cells K around i;
        the per-cell derivatives of v_K g_K (quadratic in the nodes) and v_K are central
        differences over K's 12 coordinates."""
        import scipy.sparse

        reg = self.regions[side]
        y = x[reg.cells]
        nt = len(y)

        def cell_terms(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            Minv, det = _inv3(np.transpose(y[:, 1:] - y[:, :1], (0, 2, 1)))
            grads = np.concatenate([-Minv.sum(axis=1, keepdims=True), Minv], axis=1)
            v = np.abs(det) / 6.0
            return v[:, None] * np.einsum("ti,tij->tj", reg.phi, grads), v

        eps = 1e-6 * float(np.median(np.linalg.norm(y[:, 1] - y[:, 0], axis=1))) if nt else 1.0
        dq = np.empty((nt, 3, 4, 3))
        dv = np.empty((nt, 4, 3))
        for m in range(4):
            for b in range(3):
                d = np.zeros_like(y)
                d[:, m, b] = eps
                (qp, vp), (qm, vm) = cell_terms(y + d), cell_terms(y - d)
                dq[:, :, m, b] = (qp - qm) / (2 * eps)
                dv[:, m, b] = (vp - vm) / (2 * eps)
        q, v = cell_terms(y)
        flat = reg.cells.ravel()
        den = np.maximum(np.bincount(flat, weights=np.repeat(v, 4), minlength=len(x)), 1e-300)
        num = [np.bincount(flat, weights=np.repeat(q[:, c], 4), minlength=len(x)) for c in range(3)]
        n = np.stack(num, axis=1) / den[:, None]  # = _normals(x, side)
        i = reg.cells  # (nt, 4) row nodes
        # value[t, i, a, m, b] = (dq[t, a, m, b] - n_i[a] dv[t, m, b]) / D_i
        val = (dq[:, None] - n[i][:, :, :, None, None] * dv[:, None, None]) / den[i][
            :, :, None, None, None
        ]
        rows = np.broadcast_to((3 * i[:, :, None] + np.arange(3))[:, :, :, None, None], val.shape)
        cols = np.broadcast_to((3 * i[:, :, None] + np.arange(3))[:, None, None], val.shape)
        N = 3 * len(x)
        return scipy.sparse.coo_matrix(
            (val.ravel(), (rows.ravel(), cols.ravel())), shape=(N, N)
        ).tocsr()

    def _normal_tangent(self, st: DepthState, x: np.ndarray) -> Any:
        """The tangent's part from the live nodal normals: sum over points of
        d(c phi w n_q) / d n_i  d n_i / d x, spread over the point's nodes like its force."""
        import scipy.sparse

        na, n = len(st.depth), len(x)
        xq = np.einsum("ni,nij->nj", st.bary, x[st.carrier])
        out = self._eval(st, xq, x[st.cell])
        lam, a = out[1], out[5]
        G = scipy.sparse.vstack([self._normal_jacobian(x, 0), self._normal_jacobian(x, 1)])
        q = np.repeat(np.arange(na), 4)
        cols = (st.master.astype(np.int64)[:, None] * n + st.cell).ravel()
        Aq = scipy.sparse.csr_matrix(((a[:, None] * lam).ravel(), (q, cols)), shape=(na, 2 * n))
        eye = scipy.sparse.identity(3, format="csr")
        Fq = scipy.sparse.kron(Aq, eye, format="csr") @ G  # d f_q / d x, (3 na, 3 n)
        rows = np.concatenate([st.carrier, st.cell], axis=1).ravel()
        w = np.concatenate([st.bary, -lam], axis=1).ravel()
        Sq = scipy.sparse.csr_matrix((w, (rows, np.repeat(np.arange(na), 7))), shape=(n, na))
        return scipy.sparse.kron(Sq, eye, format="csr") @ Fq

    def freeze(self, u: np.ndarray) -> None:
        """Keep the nodal normals of ``u`` (``smooth_normal``) until the next `freeze` or
        `unfreeze`: within a load increment the force direction field is then fixed, so the
        tangent is exact; `refresh` updates it (an outer fixed point, as for the surface
        model). Point location and depths stay live."""
        if not self.smooth_normal or self.linearised:
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
        Minv = _inv3(M)[0]  # rows: grad lam_1..3
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
        facet = np.zeros((len(cell), 3), dtype=np.int64)
        exit_facet = np.zeros((len(cell), 3), dtype=np.int64)
        exits = self.exits[1 - slave]
        if self.exact_depth or exits is not None:
            Xq = np.einsum("ni,nij->nj", lam, self.X[reg.cells[cell]])
        if exits is not None and reg.near_exit is not None:
            exit_facet, exit_dist, _ = _nearest(self.X, Xq, exits, reg.near_exit[cell])
        if self.exact_depth:
            # Unsigned: a located point is inside the master body, so its depth is >= 0 (the
            # plane's sign would flip inside the body next to a reflex edge of the surface).
            facet, phi, _ = _nearest(self.X, Xq, self.facets[1 - slave], reg.near[cell])
            if self.exit_depth and exits is not None:
                closer = exit_dist < phi
                facet = np.where(closer[:, None], exit_facet, facet)
                phi = np.where(closer, exit_dist, phi)
        # Touching counts (phi > -touch_rel h), as in `woundsweep.contact`: a point on the
        # master surface carries no force but its stiffness, which holds a touching start.
        keep = phi > -self.touch_rel * qp.size_mm[inside]
        hit = np.flatnonzero(inside)[keep]
        cell, lam, phi, facet = cell[keep], lam[keep], phi[keep], facet[keep]
        exit_facet = exit_facet[keep]
        if self.smooth_normal:
            frozen = self._nodal[1 - slave] if self.frozen else None
            nodal = frozen if frozen is not None else self._normals(x, 1 - slave)
            cn = nodal[reg.cells[cell]]
        else:
            cn = np.zeros((len(cell), 4, 3))
        stiff = TWO_PASS_WEIGHT * self.k_V_kPa * qp.area_mm2[hit] / qp.size_mm[hit]
        return (qp.carrier[hit], qp.bary[hit], reg.cells[cell], reg.phi[cell], cn,
                exit_facet, phi, stiff, qp.size_mm[hit],
                np.full(len(hit), 1 - slave, dtype=np.int8), facet)  # fmt: skip

    def state(self, u: np.ndarray) -> DepthState:
        """Penetrating points of both passes at ``u``; cached by the contact nodes' positions."""
        x = self.positions(u)
        xn = x[self.nodes]
        if self._cache is not None and self._cache_k == self.k_V_kPa:
            if np.array_equal(xn, self._cache_x):
                return self._cache
        t0 = time.perf_counter()
        parts = [self._pass(x, s) for s in (0, 1)]
        cols = [np.concatenate([p[i] for p in parts]) for i in range(11)]
        n_deep = int(np.sum(cols[6] > self.depth_cap_mm))
        out = DepthState(*cols, n_deep)
        self._cache, self._cache_x, self._cache_k = out, xn.copy(), self.k_V_kPa
        self.detect_time_s += time.perf_counter() - t0
        self.searches += 1
        self.evaluations += 1
        return out

    # -- energy, forces, tangent --------------------------------------------------------------

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u`` (without the exit fade, of which it is not the
        potential)."""
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
        return self._eval(st, xq, y)[0]

    def _eval(self, st: DepthState, xq: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """`_cell_force` of the points of ``st`` at x_q (na, 3) in cells y (na, 4, 3)."""
        nodal = st.cell_normal if self.smooth_normal else None
        fade = self.exit_fade > 0.0
        return _cell_force(
            xq, y, st.cell_phi, nodal, st.stiffness,
            exit_tri=self.X[st.exit_facet] if fade else None, fade=self.exit_fade,
            ref=self.X[st.cell], tri=self.X[st.facet] if self.exact_depth else None,
            delta=self._delta(st),
        )  # fmt: skip

    def _delta(self, st: DepthState) -> np.ndarray | None:
        if self.engage_kPa <= 0.0 or self.k_V_kPa <= 0.0:
            return None
        return self.engage_kPa * st.size_mm / self.k_V_kPa

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
        delta = self._delta(st)
        if delta is not None:  # far inside the ramp's quadratic part and below the depth
            eps = np.minimum(eps, 1e-2 * delta)
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
        if self.linearised and not self.frozen:
            K = K + self._normal_tangent(self.state(u), self.positions(u))
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
        and relative to h_q), and the total contact force sum c phi w |n| (mN) at ``u``."""
        st = self.state(u)
        pen = st.depth > 0.0
        if not pen.any():
            return ContactSummary(0, 0.0, 0.0, 0.0, 0)
        st = DepthState(*(a[pen] for a in st[:-1]), st.n_deep)
        x = self.positions(u)
        out = self._eval(st, np.einsum("ni,nij->nj", st.bary, x[st.carrier]), x[st.cell])
        depth = st.depth / np.linalg.norm(out[3], axis=1)
        force = float(np.sum(np.linalg.norm(out[0][:, 0], axis=1)))  # |c phi w n| per point
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

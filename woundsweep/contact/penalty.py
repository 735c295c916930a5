"""Two-pass penalty contact of the two wound flanks (stages 4-6), in the deformed configuration.

Formulation (docs/model.md, "Contact"):

- Surfaces and points. The wound surface is split into two flanks at the mirror plane, each
  facet oriented out of the body; every facet of one flank (the slave of that pass) carries
  six contact points (`woundsweep.contact.surfaces.RULE_BARY`) with reference area A_q and
  facet size h_q.
- Gap. g = (x_q - x_1) . n to the plane of the point's master facet (x_1, x_2, x_3) of the
  other flank, n its deformed unit normal; g < 0 is penetration, -g the depth.
- Pairing (`woundsweep.contact.search`): the best valid facet among the nearest ones (no
  node shared with the point's own facet, facing it, projection at most ``fade_width``
  beyond its edges). The wound model freezes the pairing per load increment (`freeze`) and
  re-searches it at convergence (`refresh`): Newton goes on while a new pairing moves the
  forces by more than the tolerance. A point whose master goes A -> B -> A over successive
  searches shares both facets with half its area each (``share_cycles``), while the search
  gives it either and the other stays valid.
- Edge fade. A point's energy is multiplied by phi = prod_i s(lam_i), lam the barycentric
  coordinates of its projection and s(lam) = 1 - 3 t^2 + 2 t^3, t = clip(-lam / fade_width,
  0, 1): past an edge where no other facet takes over, the force fades (C1) instead of
  jumping. Penetration is reported only for points with phi = 1.
- Energy. Pi_c = sum over engaged points of phi (w / 2) (k_V / h_q) A_q g^2, w = 1/2 as each
  flank is slave once and master once: the pressure per reference area is k_V (-g) / h_q,
  so k_V has stress units and the penetration at pressure p is p h / k_V.
- Linearisation. Exact residual and tangent for a given pairing (gap and barycentric
  derivatives of `woundsweep.contact.geometry`; the second derivatives of lam by central
  differences of the exact first ones, only for fading points).
- Assembly. Residual contributions by ``np.bincount``; the tangent is added to the PETSc
  matrix as one CSR batch, growing its sparsity pattern where couplings cross the wound.

Evaluation is vectorised over contact points; the last pairing is cached by the flank node
positions, so a Jacobian at the state of the last residual costs no second search.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np

from .geometry import (
    barycentric_derivatives,
    expand_hessian,
    facing_mask,
    fade_weight,
    gap_derivatives,
    projection,
)
from .protocol import ContactPairs, ContactSummary
from .search import closest_facets
from .surfaces import contact_points, surface

__all__ = ["TWO_PASS_WEIGHT", "FlankContact"]

TWO_PASS_WEIGHT = 0.5  # each flank is slave once and master once


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
        a, b = surface(self.X, np.asarray(left)), surface(self.X, np.asarray(right))
        self.surfaces = (a, b)
        self.points = (contact_points(self.X, a.facets), contact_points(self.X, b.facets))
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

    def _detect_one(self, x: np.ndarray, side: int) -> _Candidates:
        """Candidate points of one pass: a valid master facet and g < near_rel h (in front
        but close, touching, or penetrating up to max_depth_mm)."""
        sl, ms, qp = self.surfaces[side], self.surfaces[1 - side], self.points[side]
        sf = qp.carrier
        pts = np.einsum("qi,qij->qj", qp.bary, x[sf])
        p = x[sl.facets]
        normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[qp.facet]
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        cl = closest_facets(
            x, pts, normals, sf, ms, self._shares[side],
            neighbours=self.neighbours, normal_cos=self.normal_cos, fade_width=self.fade_width,
        )  # fmt: skip
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
            lam = projection(xq, pm[:, 0], pm[:, 1], pm[:, 2])[1]
            ps = x[raw.carrier[idx]]
            ns = np.cross(ps[:, 1] - ps[:, 0], ps[:, 2] - ps[:, 0])
            ns /= np.linalg.norm(ns, axis=1, keepdims=True)
            nm = np.cross(pm[:, 1] - pm[:, 0], pm[:, 2] - pm[:, 0])
            facing = facing_mask(ns, nm, np.linalg.norm(nm, axis=1), self.normal_cos)
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
        g, lam = projection(xq, pm[:, 0], pm[:, 1], pm[:, 2])
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
                Hw[fb] = expand_hessian(H12w, pr.bary[fb])
        if not hessian:
            return _Local(pr, dofs, grad, grad_w, None, None)
        assert H12 is not None
        return _Local(pr, dofs, grad, grad_w, expand_hessian(H12, pr.bary, linear_q=True), Hw)

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

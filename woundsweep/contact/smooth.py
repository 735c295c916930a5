"""Two-pass penalty contact of the wound flanks on smooth implicit surfaces (stages 4-6).

Formulation (docs/model.md, "Contact"):

- Points. The contact points of a flank are its nodes (those not shared with the other
  flank, where the flanks meet), each carrying a third of the reference area of its facets,
  A_q, and their size h_q (`woundsweep.contact.surfaces.surface`).
- Gap. g_q = phi(x_q), phi the implicit surface of the other flank's deformed facets
  (`woundsweep.contact.implicit`): the kernel radius of a facet is ``radius_factor`` times its
  reference size. phi is C2 in every node position, across facet edges included, so a point
  sliding over the master has a force and a tangent that turn smoothly; there is no pairing
  to choose, freeze or refresh. g < 0 is penetration.
- Energy. Pi_c = sum_q (w / 2) (k_V / h_q) A_q <-g_q>^2, w = 1/2 as each flank is slave once
  and master once: the pressure per reference area is k_V (-g) / h, so k_V has stress units
  and the penetration at pressure p is p h / k_V.
- Linearisation. Exact: residual c g dg and tangent c (dg dg^T + g d2g) of every point with
  g <= 0, c = w k_V A / h, with the derivatives of the quotient phi = N / D (at g = 0 the
  tangent of the penetrating side: touching flanks are held from the first Newton step).
- Multipliers. With ``mult`` set (mu = c psi per point, <= 0; `woundsweep.contact.multipliers`
  carries them through Newton), the curvature term is mu d2psi and a point with mu < 0 stays
  engaged where its gap has opened: the semi-smooth step of the mixed form.

A point sees the master facets whose centroid lies within their kernel radius (a KD-tree
query at every new state, cheap: the kernel vanishes with two derivatives at its radius, so
the set can change without a jump). Evaluations are cached by the flank node positions.

The coupling pattern (`ContactModel`) is planned by `woundsweep.contact.pattern`.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple, cast

import numpy as np

from .implicit import pair_terms, support_step
from .pattern import PATTERN_GAP, PATTERN_MARGIN, CouplingPlan
from .protocol import ContactSummary, Linearization
from .surfaces import FlankPass, lumped_area, near_pairs, surface, triangle_areas

__all__ = ["TWO_PASS_WEIGHT", "FlankContact"]

TWO_PASS_WEIGHT = 0.5  # each flank is slave once and master once


class _PassState(NamedTuple):
    """Gaps and derivatives of one pass's points at one state (`FlankContact._evaluate_pass`)."""

    gap_all: np.ndarray  # (nq,) gap of every point (+inf where no master is near)
    weight_all: np.ndarray  # (nq,) s^2 w A / h per point
    gap: np.ndarray  # (na,) psi = s g of the engaged points
    weight: np.ndarray  # (na,) w A / h of the engaged points
    dofs: np.ndarray  # (na, L) local dofs (padded with 0)
    grad: np.ndarray  # (na, L) dpsi in local dofs
    hess: np.ndarray | None  # (na, L, L) d2psi
    # A field named like tuple.index (shadows the method, which is never called on it).
    index: np.ndarray  # type: ignore[assignment]  # (na,) engaged points' indices in the pass
    support_all: np.ndarray  # (nq,) every point's support step at this state (not held)
    in_plan: bool  # every pair of the tangent is in the coupling plan (or none is planned)


class _State(NamedTuple):
    """Gaps and derivatives of the engaged points at one state (both passes)."""

    gap_all: np.ndarray  # (nq_total,) gap of every point (+inf where no master is near)
    weight_all: np.ndarray  # (nq_total,) s^2 w A / h per point, mm (c = k_V w A / h)
    size_all: np.ndarray  # (nq_total,)
    full_weight: np.ndarray  # (nq_total,) w A / h: weight_all where the support step is 1
    gap: np.ndarray  # (na,) psi = s g of the engaged points (g <= 0; s the support step)
    weight: np.ndarray  # (na,)
    dofs: np.ndarray  # (na, L) local dofs (padded with 0)
    grad: np.ndarray  # (na, L) dpsi in local dofs (0 in padding)
    hess: np.ndarray | None  # (na, L, L) d2psi
    # A field named like tuple.index (shadows the method, which is never called on it).
    index: np.ndarray  # type: ignore[assignment]  # (na,) indices in the all-points numbering
    support_all: np.ndarray  # (nq_total,) every point's support step at this state (not held)


class FlankContact:
    """Two-pass penalty between two surfaces on their implicit surfaces (module docstring).

    ``X`` (n, 3) reference node coordinates; ``left`` and ``right`` (k, 3) outward-oriented
    facets in node numbering. ``k_V_kPa`` (attribute) is the penalty; 0 switches the contact
    terms off (gaps and penetrations are still measured). ``pattern_gap`` and
    ``pattern_margin``: those of the coupling pattern (`woundsweep.contact.pattern`). ``tied``
    nodes are held by another law (the closure zone's tie) and are masters only, not contact
    points.
    """

    def __init__(
        self,
        X: np.ndarray,
        left: np.ndarray,
        right: np.ndarray,
        *,
        radius_factor: float = 1.5,
        pattern_gap: float = PATTERN_GAP,
        pattern_margin: float = PATTERN_MARGIN,
        tied: np.ndarray | None = None,
    ) -> None:
        self.X = np.asarray(X, dtype=float)
        self.n_dofs = 3 * len(self.X)
        sides = (np.asarray(left, dtype=np.int64), np.asarray(right, dtype=np.int64))
        self.surfaces = surfs = tuple(surface(self.X, f) for f in sides)
        # Nodes held by another law (the zone tie) are masters only, never contact points.
        shared = np.intersect1d(surfs[0].nodes, surfs[1].nodes)
        if tied is not None:
            shared = np.union1d(shared, np.asarray(tied, dtype=np.int64))
        passes = []
        for i in (0, 1):
            sl, ms = surfs[i], surfs[1 - i]
            keep = ~np.isin(sl.nodes, shared)
            m_area = triangle_areas(self.X[ms.facets])
            rho = radius_factor * np.sqrt(4.0 * m_area / np.sqrt(3.0))
            size = sl.size_mm[keep]
            passes.append(
                FlankPass(sl.nodes[keep], lumped_area(self.X, sl.facets, sl.nodes[keep]), size,
                      ms.facets, rho, np.pi * (radius_factor * size) ** 2 / 4.0)
            )  # fmt: skip
        self.passes = tuple(passes)
        self.nodes = np.union1d(surfs[0].nodes, surfs[1].nodes)  # every node whose position matters
        self.radius_factor = float(radius_factor)
        self.k_V_kPa = 0.0
        self._offsets = (0, len(self.passes[0].nodes))
        self.n_points = sum(len(ps.nodes) for ps in self.passes)
        # The multipliers mu = c psi (<= 0) of the semi-smooth step (module docstring); None:
        # the pure penalty, mu = c psi(u). Setting them invalidates the cached evaluations.
        self._mult: np.ndarray | None = None
        self._cache_x: np.ndarray | None = None
        self._cache: dict[bool, _State] = {}
        # The support step of every point frozen at a state (`freeze_support`), or None: s
        # follows the state.
        self._frozen: np.ndarray | None = None
        self.plan = CouplingPlan(
            self.passes, self._offsets, len(self.X), pattern_gap, pattern_margin
        )
        self.reset_timers()

    def positions(self, u: np.ndarray) -> np.ndarray:
        """Deformed coordinates (n, 3) of all nodes for flat displacement dofs ``u``."""
        return self.X + np.asarray(u).reshape(-1, 3)

    # -- evaluation ---------------------------------------------------------------------------

    def _pairs(self, x: np.ndarray, ps: FlankPass) -> tuple[np.ndarray, np.ndarray]:
        """(point, facet) index pairs with the point inside the facet's kernel radius."""
        t0 = time.perf_counter()
        q, f = near_pairs(x, ps, 1.0)
        self.detect_time_s += time.perf_counter() - t0
        self.searches += 1
        return q, f

    def _evaluate_pass(self, x: np.ndarray, i: int, hessian: bool) -> _PassState:
        ps, off = self.passes[i], self._offsets[i]
        q, f = self._pairs(x, ps)
        nq = len(ps.nodes)
        mf = ps.facets[f]
        t = pair_terms(x[ps.nodes[q]], x[mf[:, 0]], x[mf[:, 1]], x[mf[:, 2]], ps.rho_mm[f], False)
        N = np.bincount(q, weights=t.N, minlength=nq)
        D = np.bincount(q, weights=t.D, minlength=nq)
        gap = np.full(nq, np.inf)
        seen = D > 0.0
        gap[seen] = N[seen] / D[seen]
        # g = 0 counts as engaged: the tangent is then that of the penetrating side, so
        # touching surfaces hold each other from the first Newton step on.
        # Where the master surface ends (its kernel support D thins out) the point's force
        # fades with it: the gap enters the energy as psi = s(D / D_full) g, s a C2 step.
        t_sup = np.zeros(nq)
        t_sup[seen] = D[seen] / ps.support_mm2[seen]
        s_w, s_1, s_2 = support_step(t_sup)
        s_live = s_w
        if self._frozen is not None:  # the support of the solve's start: a constant weight
            s_w = self._frozen[off : off + nq]
            s_1 = s_2 = np.zeros(nq)
        engaged = gap <= 0.0
        if self._mult is not None:  # semi-smooth active set: compressive multipliers stay
            engaged |= self._mult[off : off + nq] < 0.0
        act_pt = np.flatnonzero(engaged & (s_w > 0.0) & np.isfinite(gap))
        keep = np.isin(q, act_pt)
        q, f, mf = q[keep], f[keep], mf[keep]
        in_plan = not hessian or self.plan.covers(i, q, f)
        if hessian:  # second derivatives only for the engaged points' pairs
            t = pair_terms(x[ps.nodes[q]], x[mf[:, 0]], x[mf[:, 1]], x[mf[:, 2]], ps.rho_mm[f])
        else:
            # Each field filtered, None where it is None (only d2N and d2D can be).
            t = type(t)(*(None if a is None else a[keep] for a in t))  # type: ignore[arg-type]
        rank = np.full(nq, -1, dtype=np.int64)
        rank[act_pt] = np.arange(len(act_pt))
        qa = rank[q]
        # Local node numbering per engaged point (its own node and its masters' nodes).
        pair_nodes = np.concatenate([ps.nodes[q][:, None], mf], axis=1)  # (P, 4)
        key = qa[:, None] * len(x) + pair_nodes
        own = rank[act_pt] * len(x) + ps.nodes[act_pt]
        uniq, inv = np.unique(np.concatenate([own, key.ravel()]), return_inverse=True)
        pt_of = uniq // len(x)
        first = np.searchsorted(pt_of, np.arange(len(act_pt)))
        slot = np.arange(len(uniq)) - first[pt_of]
        L = int(slot.max()) + 1 if len(uniq) else 1
        loc = slot[inv[len(own) :]].reshape(-1, 4)  # local slot of each pair node
        node_of = np.zeros((len(act_pt), L), dtype=np.int64)
        node_of[pt_of, slot] = uniq % len(x)
        na = len(act_pt)
        g, Dq, Dfull = gap[act_pt], D[act_pt], ps.support_mm2[act_pt]
        sw, s1, s2 = s_w[act_pt], s_1[act_pt], s_2[act_pt]
        ldof = (3 * loc[:, :, None] + np.arange(3)).reshape(-1, 12)
        rows = np.repeat(qa, 12)

        def gather(v: np.ndarray) -> np.ndarray:
            out = np.zeros((na, 3 * L))
            np.add.at(out, (rows, ldof.ravel()), v.ravel())
            return out

        dphi = gather((t.dN - g[qa, None] * t.dD) / Dq[qa, None])  # dg = (dN - g dD) / D
        dt = gather(t.dD) / Dfull[:, None]  # d(D / D_full)
        psi = sw * g
        grad = sw[:, None] * dphi + (s1 * g)[:, None] * dt
        hess = None
        if hessian:
            assert t.d2N is not None and t.d2D is not None  # pair_terms with second derivatives
            r_i = np.repeat(ldof, 12, axis=1).ravel()
            c_i = np.tile(ldof, (1, 12)).ravel()
            p_i = np.repeat(qa, 144)

            def gather2(v: np.ndarray) -> np.ndarray:
                out = np.zeros((na, 3 * L, 3 * L))
                np.add.at(out, (p_i, r_i, c_i), v.ravel())
                return out

            dD = dt * (Dfull / Dq)[:, None]
            d2phi = gather2((t.d2N - g[qa, None, None] * t.d2D) / Dq[qa, None, None])
            outer = dphi[:, :, None] * dD[:, None, :]
            d2phi -= outer + np.transpose(outer, (0, 2, 1))
            d2t = gather2(t.d2D) / Dfull[:, None, None]
            cross = dphi[:, :, None] * dt[:, None, :]
            hess = sw[:, None, None] * d2phi
            hess += s1[:, None, None] * (cross + np.transpose(cross, (0, 2, 1)))
            hess += g[:, None, None] * (
                s2[:, None, None] * dt[:, :, None] * dt[:, None, :] + s1[:, None, None] * d2t
            )
        dofs = (3 * node_of[:, :, None] + np.arange(3)).reshape(na, 3 * L)
        weight = TWO_PASS_WEIGHT * ps.area_mm2 / ps.size_mm
        return _PassState(
            gap_all=gap,
            weight_all=weight * s_w**2,
            gap=psi,
            weight=weight[act_pt],
            dofs=dofs,
            grad=grad,
            hess=hess,
            index=act_pt,
            support_all=s_live,
            in_plan=in_plan,
        )

    def _state(self, u: np.ndarray, hessian: bool) -> _State:
        """Gaps and derivatives at ``u`` (cached by the flank node positions; a state with the
        Hessian serves requests without)."""
        x = self.positions(u)
        xn = x[self.nodes]
        if self._cache_x is None or not np.array_equal(xn, self._cache_x):
            self._cache.clear()
            self._cache_x = xn.copy()
        for key in (True,) if hessian else (False, True):
            if key in self._cache:
                return self._cache[key]
        t0 = time.perf_counter()
        parts = [self._evaluate_pass(x, i, hessian) for i in range(len(self.passes))]
        if not all(p.in_plan for p in parts):  # grown before the tangent is returned
            self.plan.grow(x, np.concatenate([p.gap_all for p in parts]), self._mult)
        L = max(p.dofs.shape[1] for p in parts)

        def pad(a: np.ndarray, square: bool) -> np.ndarray:
            w = L - a.shape[1]
            return np.pad(a, [(0, 0), (0, w)] + ([(0, w)] if square else []))

        st = _State(
            gap_all=np.concatenate([p.gap_all for p in parts]),
            weight_all=np.concatenate([p.weight_all for p in parts]),
            size_all=np.concatenate([ps.size_mm for ps in self.passes]),
            full_weight=np.concatenate(
                [TWO_PASS_WEIGHT * ps.area_mm2 / ps.size_mm for ps in self.passes]
            ),
            gap=np.concatenate([p.gap for p in parts]),
            weight=np.concatenate([p.weight for p in parts]),
            dofs=np.concatenate([pad(p.dofs, False) for p in parts]),
            grad=np.concatenate([pad(p.grad, False) for p in parts]),
            hess=np.concatenate([pad(cast(np.ndarray, p.hess), True) for p in parts])
            if hessian
            else None,
            index=np.concatenate([p.index + off for p, off in zip(parts, self._offsets)]),
            support_all=np.concatenate([p.support_all for p in parts]),
        )
        self._cache[hessian] = st
        self.evaluations += 1
        self.assembly_time_s += time.perf_counter() - t0
        return st

    # -- coupling pattern (`woundsweep.contact.pattern`) ----------------------------------------

    def plan_pattern(self, u: np.ndarray) -> None:
        """Set the coupling pattern to that of a plan at ``u``."""
        gap = self._state(u, hessian=False).gap_all
        self.plan.set(self.positions(u), gap, self._mult)

    def clear_pattern(self) -> None:
        """Drop the coupling pattern (tangents are no longer checked against it)."""
        self.plan.clear()

    def coupling_pattern(self) -> Any:
        """Structure (scipy CSR of ones, n_dofs square) of every tangent entry the planned
        pairs allow; None if no pattern is planned."""
        return self.plan.structure()

    @property
    def pattern_version(self) -> int:
        """Changes with the coupling pattern (planned, grown or cleared)."""
        return self.plan.version

    @property
    def pattern_growths(self) -> int:
        """Growths of the coupling pattern since `reset_timers`."""
        return self.plan.growths

    @property
    def pattern_gap(self) -> float:
        """The plan's gap margin, in element sizes."""
        return self.plan.gap

    @pattern_gap.setter
    def pattern_gap(self, value: float) -> None:
        self.plan.gap = float(value)

    @property
    def pattern_margin(self) -> float:
        """The plan's extra kernel radius of a point's facets."""
        return self.plan.margin

    @pattern_margin.setter
    def pattern_margin(self, value: float) -> None:
        self.plan.margin = float(value)

    # -- energy, forces, tangent ----------------------------------------------------------------

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        st = self._state(u, hessian=False)
        return float(0.5 * self.k_V_kPa * np.sum(st.weight * st.gap**2))

    def force_vector(self, u: np.ndarray) -> np.ndarray:
        """Contact contribution to the residual, dPi_c/du (flat, mN)."""
        st = self._state(u, hessian=False)
        f = (self.k_V_kPa * st.weight * st.gap)[:, None] * st.grad
        return np.bincount(st.dofs.ravel(), weights=f.ravel(), minlength=self.n_dofs)

    def tangent_csr(self, u: np.ndarray) -> Any:
        """Contact tangent d2Pi_c/du2 as a scipy CSR matrix (n_dofs square)."""
        import scipy.sparse

        st = self._state(u, hessian=True)
        assert st.hess is not None
        t0 = time.perf_counter()
        c = self.k_V_kPa * st.weight[:, None, None]
        mu = c[:, 0, 0] * st.gap if self._mult is None else self._mult[st.index]
        K = c * (st.grad[:, :, None] * st.grad[:, None, :]) + mu[:, None, None] * st.hess
        L = st.dofs.shape[1]
        rows = np.repeat(st.dofs, L, axis=1).ravel()
        cols = np.tile(st.dofs, (1, L)).ravel()
        vals = K.ravel()
        # Exact zeros left out: the padding slots (dof 0) would couple dof 0 with every
        # engaged point, entries no tangent has.
        nz = vals != 0.0
        shape = (self.n_dofs,) * 2
        M = scipy.sparse.coo_matrix((vals[nz], (rows[nz], cols[nz])), shape=shape).tocsr()
        M.sum_duplicates()
        self.assembly_time_s += time.perf_counter() - t0
        return M

    @property
    def mult(self) -> np.ndarray | None:
        """Multipliers (n_points,) in the points' order (both passes), or None."""
        return self._mult

    @mult.setter
    def mult(self, value: np.ndarray | None) -> None:
        self._mult = value
        self._forget()

    def _forget(self) -> None:
        """Drop the cached evaluations (made with other multipliers or support)."""
        self._cache_x = None
        self._cache.clear()

    def freeze_support(self, u: np.ndarray | None) -> None:
        """Hold every point's support step at its value at ``u`` (None: let it follow the
        state). With s held, a point's energy is c s^2 <g>^2 / 2: the fade at the master's
        edge then weights the point but does not push it along the surface."""
        held = None if u is None else self._state(u, hessian=False).support_all.copy()
        self._frozen = held
        self._forget()

    def support_change(self, u: np.ndarray) -> float:
        """Largest change of an engaged point's support step between the held one and that
        at ``u`` (0 if none is held)."""
        if self._frozen is None:
            return 0.0
        st = self._state(u, hessian=False)
        change = np.abs(st.support_all - self._frozen)[st.gap_all <= 0.0]
        return float(np.max(change, initial=0.0))

    def penalty_multipliers(self, u: np.ndarray) -> np.ndarray:
        """mu = c psi(u) of every point (0 where not engaged): the penalty's own forces."""
        st = self._state(u, hessian=False)
        out = np.zeros(self.n_points)
        out[st.index] = self.k_V_kPa * st.weight * st.gap
        return out

    def linearization(self, u0: np.ndarray, du: np.ndarray) -> Linearization:
        """(c psi(u0), c dpsi . du) of every point (0 where not engaged at u0): the forces
        the Newton model predicts at u0 + gamma du are min(0, a + gamma b)."""
        st = self._state(u0, hessian=False)
        b = np.zeros(self.n_points)
        b[st.index] = self.k_V_kPa * st.weight * np.sum(st.grad * du[st.dofs], axis=1)
        return Linearization(self.penalty_multipliers(u0), b)

    # -- reporting ------------------------------------------------------------------------------

    def gaps(self, u: np.ndarray) -> np.ndarray:
        """The gap (mm) of every contact point at ``u``, both passes (+inf: no master near)."""
        return self._state(u, hessian=False).gap_all.copy()

    def summary(self, u: np.ndarray) -> ContactSummary:
        """Penetration and compressive normal force of the state ``u`` at the current
        ``k_V_kPa``: force sum c s^2 (-g) over every contact point (s the support step),
        penetration over the points the master's surface fully supports (s = 1); the engaged
        points in the fade (0 < s < 1) and their share of the force. s is the one that
        weights the energy (the held one after `freeze_support`)."""
        st = self._state(u, hessian=False)
        depth = np.maximum(-st.gap_all, 0.0)
        depth[~np.isfinite(depth)] = 0.0
        point_force = st.weight_all * depth  # per point, without k_V: the share needs none
        force = float(self.k_V_kPa * np.sum(point_force))
        # weight_all = s^2 full_weight exactly, so these compare s with 0 and 1 exactly.
        fade = (st.weight_all > 0.0) & (st.weight_all < st.full_weight)
        fade &= st.gap_all <= 0.0
        total = float(np.sum(point_force))
        share = float(np.sum(point_force[fade])) / total if total > 0.0 else 0.0
        n_fade = int(fade.sum())
        depth[st.weight_all < st.full_weight] = 0.0
        pen = depth > 0.0
        if not pen.any():
            return ContactSummary(0, 0.0, 0.0, force, n_fade, share)
        return ContactSummary(
            int(pen.sum()),
            float(depth.max()),
            float(np.max(depth / st.size_all)),
            force,
            n_fade,
            share,
        )

    def reset_timers(self) -> None:
        """Zero the counters: search time, assembly time, evaluations, searches, growths of
        the coupling pattern."""
        self.detect_time_s = 0.0  # cumulative: neighbour searches
        self.assembly_time_s = 0.0  # cumulative: gaps, residual and tangent contributions
        self.evaluations = 0
        self.searches = 0
        self.plan.growths = 0

"""Closure of a fusiform excision by interrupted sutures, and a load after closure
(docs/model.md, "Sutures" and "The load after closure").

A suture holds the wound's walls together over its footprint: the closure zone's mirror pairs
within half a bite width of the suture along the wound (at least the column of pairs nearest
to it), from the surface down to the bite depth (the zone's depth, so the mesh is built with
it). `SuturedClosure` runs, on one mesh and one set of materials:

1. `close`: stage 1, pre-tension, and stage 2, the Dirichlet closure of the whole zone
   (`woundsweep.physics.stages`);
2. `suture`: from the stage-2 state, the zone's Dirichlet condition is released everywhere
   but under the sutures (no contact: the walls between them may open), then the footprints
   are tied (`woundsweep.contact.ZoneTie` on their pairs) at that state and their Dirichlet
   condition released, while the flank contact's penalty is ramped from 1 kPa to 1 GPa as in
   stage 4: the sutures and the contact hold the wound. The force of a suture is the tie's
   pull across the wound on the left wall's held points, each counted for its nearest suture
   (blended into the next one's over `BLEND_mm` about halfway, `shares`) (mN). A placement
   is re-solved from the same stage-2 state;
3. `itch`: from the sutured state, the patch's lateral faces are held in plane and moved by the
   load's displacement gradient E (u += E (X - X_c)) in ``steps`` equal increments, each
   measured.

Every state is measured by `woundsweep.physics.suture_measures`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from ..config.fusiform import Lens
from ..config.paper import ClosureZone, StageSettings
from ..config.solver import SolverSettings
from ..config.sutures import ItchLoad, SuturePlan
from ..contact import FlankContact, ZoneTie, split_wound_flanks
from ..core.schema import StageStatus
from ..solver.continuation import LoadState, continuation
from ..solver.newton import NewtonSolver, Policy
from .domain import dof_rows
from .materials import JobMaterials
from .problem import WoundProblem
from .stages import CONTACT_MAX_DECADES, CONTACT_START_kPa, WoundModel
from .suture_measures import SurfacePatch, SutureState, measure_state, surface_patch

__all__ = ["BLEND_mm", "SolveStep", "SuturedClosure"]

# A held wall point's pull counts for its nearest suture, blended linearly into the next one's
# over this length about the point halfway between them (so the split of the load between
# neighbours does not jump with the mesh's nodes, nor with rounding in a symmetric placement).
BLEND_mm = 0.5


class SolveStep(NamedTuple):
    """How one solve went and the state it reached (None if it did not converge)."""

    status: str
    newton_iterations: int
    time_s: float
    state: SutureState | None


class SuturedClosure:
    """A fusiform excision's mesh closed by sutures (module docstring). ``lens``: the
    excision's outline (`GeometrySpec.lens`); ``zone_depth_fraction``: the closure zone's depth
    as a fraction of the wound's, the one the mesh was built with (the bite depth)."""

    def __init__(
        self,
        mesh: Any,
        lens: Lens,
        zone_depth_fraction: float = ClosureZone.depth_fraction,
        solver: SolverSettings | None = None,
        jit: dict[str, Any] | None = None,
    ) -> None:
        self.solver = solver or SolverSettings()
        stages = StageSettings(ClosureZone(1.0, zone_depth_fraction))
        self.model = WoundModel(mesh, self.solver, stages, jit=jit, tie_zone=False)
        if self.model.contact is None or self.model.closure_line is None:
            raise ValueError("the mesh has no wound to suture")
        d = self.model.domain
        flanks = split_wound_flanks(d.X, d.cell_vertices, d.wound_facets(), d.x_c)
        self.flanks = tuple(d.element.sub_triangles(f) for f in flanks)
        self.lens = lens
        self.closed_u: np.ndarray | None = None
        self.sutured_u: np.ndarray | None = None
        self.positions_mm: tuple[float, ...] = ()
        self.dirichlet_force_mN: np.ndarray | None = None
        self._shares: np.ndarray | None = None  # (tie pairs, sutures): `shares`
        self.orientation_deg = 0.0

    @property
    def domain(self) -> Any:
        return self.model.domain

    def close(self, materials: JobMaterials, orientation_deg: float) -> list[SolveStep]:
        """Stages 1 and 2 (pre-tension, Dirichlet closure of the zone)."""
        self.orientation_deg = float(orientation_deg)
        self.model.set_materials(materials)
        out = []
        for k in (1, 2):
            o = self.model.run_stage(k)
            ok = o.solve.status == StageStatus.CONVERGED
            state = self._measure() if ok else None
            out.append(SolveStep(o.solve.status, int(o.solve.iterations), o.time_s, state))
            if not ok:
                return out
        self.closed_u = self.model.u.copy()
        return out

    # -- sutures --------------------------------------------------------------------------

    def footprints(self, ys: Sequence[float], bite_width_mm: float) -> np.ndarray:
        """The zone nodes (both flanks) the sutures hold: those at most half a bite width
        from their nearest suture along the wound, and for each suture at least the column
        of zone nodes nearest to it (ValueError if a suture is nearest to no node)."""
        d = self.domain
        nodes = d.zone_nodes
        dist = np.abs(d.X[nodes, 1][:, None] - np.asarray(ys, dtype=float)[None, :])
        nearest = np.argmin(dist, axis=1)
        own = dist[np.arange(len(nodes)), nearest]
        held = own <= 0.5 * bite_width_mm * (1 + 1e-9)  # halfway at spacing b: held, shared
        for i in range(len(ys)):
            mine = nearest == i
            if not mine.any():
                raise ValueError(f"the suture at y={ys[i]:g} mm has no wall nodes of its own")
            held |= mine & (own <= own[mine].min() * (1 + 1e-9) + 1e-12)
        return nodes[held]

    @staticmethod
    def shares(y: np.ndarray, ys: Sequence[float]) -> np.ndarray:
        """(len(y), n) weights of the sutures at ``ys`` in the pull of wall points at ``y``:
        the nearest suture's, blended linearly into its neighbour's over `BLEND_mm` about
        the point halfway between them, 1/2 each there; each row sums to 1."""
        ys_arr = np.asarray(ys, dtype=float)
        n = len(ys_arr)
        W = np.zeros((len(y), n))
        dist = np.abs(np.asarray(y)[:, None] - ys_arr[None, :])
        order = np.argsort(dist, axis=1)
        i = order[:, 0]
        rows = np.arange(len(y))
        if n == 1:
            W[rows, i] = 1.0
            return W
        j = order[:, 1]
        # |y - y_j| - |y - y_i| is twice the distance from halfway, toward i.
        delta = 0.5 * (dist[rows, j] - dist[rows, i])
        adjacent = np.abs(i - j) == 1
        wi = np.where(adjacent, np.clip(0.5 + delta / BLEND_mm, 0.5, 1.0), 1.0)
        W[rows, i] = wi
        W[rows, j] += 1.0 - wi
        return W

    def _rebuild(self, tie: ZoneTie) -> None:
        """A contact, problem and Newton solver with ``tie`` (the sutures) on the model."""
        m, d = self.model, self.domain
        left, right = self.flanks
        m.tie = tie
        m.contact = FlankContact(d.X, left, right, tied=tie.pairs.ravel())
        m.problem = WoundProblem(d, m.forms, m.contact, tie)
        m.newton = NewtonSolver(m.problem, m.problem.A, self.solver.newton)

    def suture(self, plan: SuturePlan, ys: Sequence[float] | None = None) -> SolveStep:
        """Close the wound by the sutures of ``plan`` (at ``ys``, default the plan's
        positions) from the stage-2 state (module docstring)."""
        if self.closed_u is None:
            raise RuntimeError("close() first")
        t0 = time.perf_counter()
        d = self.domain
        ys = tuple(plan.positions(2 * self.lens.a) if ys is None else ys)
        held = self.footprints(ys, plan.bite_width_mm)
        left = held[d.X[held, 0] < d.x_c]
        right = held[d.X[held, 0] >= d.x_c]
        tie = ZoneTie(d.X, left, right, self.flanks[0], d.x_c)
        self._rebuild(tie)
        self._shares = self.shares(d.X[tie.pairs[:, 0], 1], ys)
        self.positions_mm = ys
        m = self.model
        m.u[:] = self.closed_u
        # 1. The zone released but under the sutures (Dirichlet there; no contact).
        rows = np.concatenate([d.gauge_rows(), dof_rows(held, 0)])
        res = self._release(rows, Policy(m.settings, symmetric=True))
        its = int(res.iterations)
        if res.status != StageStatus.CONVERGED:
            return SolveStep(res.status, its, time.perf_counter() - t0, None)
        r = m.problem.residual_array()
        self.dirichlet_force_mN = r[3 * tie.pairs[:, 0]] @ self._shares
        # 2. The footprints tied there, their Dirichlet condition released into the tie, and
        # the contact ramped in (as stage 4).
        tie.set_reference(m.u)
        c = m.contact
        k_from, k_to = CONTACT_START_kPa, m.contact_penalty_kPa[0]
        rows = d.gauge_rows()
        res = self._release(rows, Policy.contact(m.settings), (k_from, k_to))
        its += int(res.iterations)
        ok = res.status == StageStatus.CONVERGED
        c.k_V_kPa = k_to
        self.sutured_u = m.u.copy() if ok else None
        state = self._measure() if ok else None
        return SolveStep(res.status, its, time.perf_counter() - t0, state)

    def _release(
        self, rows: np.ndarray, policy: Policy, penalty: tuple[float, float] | None = None
    ) -> Any:
        """Continuation from the current state holding ``rows`` where they are and releasing
        the out-of-balance force of every other dof; with ``penalty`` (from, to) the contact's
        k_V ramps geometrically over the path (contact off before, as in stage 4)."""
        m = self.model
        c = m.contact
        c.k_V_kPa = 0.0
        offset = m.problem.residual_array()
        offset[rows] = 0.0
        values = m.u[rows].copy()
        scale = float(np.linalg.norm(m.problem.internal_force()))
        if penalty is None:

            def load(s: float) -> LoadState:
                return LoadState(values, (1.0 - s) * offset)

            return continuation(m.newton, rows, load, scale, 1.0, policy)
        k_from, k_to = penalty

        def ramp(s: float) -> LoadState:
            c.k_V_kPa = k_from ** (1.0 - s) * k_to**s
            return LoadState(values, (1.0 - s) * offset)

        decades = np.log10(k_to / k_from)
        first, largest = 0.5 / decades, CONTACT_MAX_DECADES / decades
        return continuation(m.newton, rows, ramp, scale, first, policy, largest)

    def suture_forces(self) -> np.ndarray:
        """Per suture, the tie's pull across the wound on its left footprint (mN; positive
        holds the walls together)."""
        m = self.model
        if self._shares is None or m.tie is None or not m.tie.active:
            return np.zeros(len(self.positions_mm))
        f = m.tie.force_vector(m.u, m.contact.k_V_kPa)
        return -(f[3 * m.tie.pairs[:, 0]] @ self._shares)

    def surface(self, bite_width_mm: float) -> SurfacePatch:
        """The deformed skin surface around the wound at the current state, with the
        sutures (`surface_patch`)."""
        ys = np.asarray(self.positions_mm, dtype=float)
        return surface_patch(self.model, self.lens, ys, bite_width_mm)

    # -- the load after closure -----------------------------------------------------------

    def itch(self, load: ItchLoad, steps: int = 4) -> list[SolveStep]:
        """Apply ``load`` from the sutured state in ``steps`` equal increments of the
        lateral faces' in-plane displacement; stops at the first that does not converge."""
        if self.sutured_u is None:
            raise RuntimeError("suture() first")
        m, d = self.model, self.domain
        u = m.u
        u[:] = self.sutured_u
        E = np.asarray(load.gradient(self.orientation_deg))
        lateral = np.union1d(d.x_face_nodes, d.y_face_nodes)
        rows = np.unique(
            np.concatenate([d.gauge_rows(), dof_rows(lateral, 0), dof_rows(lateral, 1)])
        ).astype(np.int32)
        node, comp = rows // 3, rows % 3
        disp = (d.X[node, :2] - np.array([d.x_c, d.y_c])) @ E.T  # E (X - X_c) per row's node
        inc = np.where(comp < 2, disp[np.arange(len(rows)), np.minimum(comp, 1)], 0.0)
        start = u[rows].copy()
        policy = Policy.contact(m.settings)
        out: list[SolveStep] = []
        for j in range(1, steps + 1):
            t0 = time.perf_counter()
            a = u[rows].copy()
            b = start + (j / steps) * inc
            offset = m.problem.residual_array()
            offset[rows] = 0.0
            scale = float(np.linalg.norm(m.problem.internal_force()))

            def ramp(s: float, a: Any = a, b: Any = b, off: Any = offset) -> LoadState:
                return LoadState(a + s * (b - a), (1.0 - s) * off)

            res = continuation(m.newton, rows, ramp, scale, 1.0, policy)
            ok = res.status == StageStatus.CONVERGED
            state = self._measure() if ok else None
            out.append(SolveStep(res.status, int(res.iterations), time.perf_counter() - t0, state))
            if not ok:
                break
        return out

    def _measure(self) -> SutureState:
        return measure_state(
            self.model, self.lens, np.asarray(self.positions_mm, float), self.suture_forces()
        )

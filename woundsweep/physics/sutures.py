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
from ..contact import ZoneTie
from ..core.schema import MeshData, StageStatus
from ..solver.dirichlet import Dirichlet
from .domain import WoundDomain, dof_rows
from .loadpath import LoadStep, Solve, run_load_step
from .materials import JobMaterials
from .model import WoundModel
from .stages import contact_ramp, run_stage
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
        mesh: MeshData,
        lens: Lens,
        zone_depth_fraction: float = ClosureZone.depth_fraction,
        solver: SolverSettings | None = None,
        jit: dict[str, Any] | None = None,
    ) -> None:
        stages = StageSettings(ClosureZone(1.0, zone_depth_fraction))
        self.model = WoundModel(mesh, solver, stages, jit=jit, tie_zone=False)
        if self.model.flanks is None or self.model.closure_line is None:
            raise ValueError("the mesh has no wound to suture")
        self.lens = lens
        self.closed_u: np.ndarray | None = None
        self.sutured_u: np.ndarray | None = None
        self.positions_mm: tuple[float, ...] = ()
        self.dirichlet_force_mN: np.ndarray | None = None
        self._shares: np.ndarray | None = None  # (tie pairs, sutures): `shares`
        self.orientation_deg = 0.0

    @property
    def domain(self) -> WoundDomain:
        return self.model.domain

    def close(self, materials: JobMaterials, orientation_deg: float) -> list[SolveStep]:
        """Stages 1 and 2 (pre-tension, Dirichlet closure of the zone)."""
        self.orientation_deg = float(orientation_deg)
        self.model.set_materials(materials)
        out = []
        for k in (1, 2):
            o = run_stage(self.model, k)
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

    def suture(self, plan: SuturePlan, ys: Sequence[float] | None = None) -> SolveStep:
        """Close the wound by the sutures of ``plan`` (at ``ys``, default the plan's
        positions) from the stage-2 state (module docstring)."""
        if self.closed_u is None:
            raise RuntimeError("close() first")
        t0 = time.perf_counter()
        m, d = self.model, self.domain
        ys = tuple(plan.positions(2 * self.lens.a) if ys is None else ys)
        held = self.footprints(ys, plan.bite_width_mm)
        left = held[d.X[held, 0] < d.x_c]
        right = held[d.X[held, 0] >= d.x_c]
        assert m.flanks is not None
        tie = ZoneTie(d.X, left, right, m.flanks[0], d.x_c)
        m.attach_tie(tie)
        self._shares = self.shares(d.X[tie.pairs[:, 0], 1], ys)
        self.positions_mm = ys
        gauge = Dirichlet(d.gauge_rows())
        # 1. The zone released but under the sutures (held there; no contact).
        footprints = Dirichlet(dof_rows(held, 0))
        released = LoadStep("suture-release", (gauge, footprints), self.closed_u, first_step=1.0)
        res = run_load_step(m, released).solve
        its = int(res.iterations)
        if res.status != StageStatus.CONVERGED:
            return SolveStep(res.status, its, time.perf_counter() - t0, None)
        r = m.problem.residual_array()
        self.dirichlet_force_mN = r[3 * tie.pairs[:, 0]] @ self._shares
        # 2. The footprints tied there, their Dirichlet condition released into the tie, and
        # the contact ramped in (as stage 4).
        tied = LoadStep(
            "suture-tie",
            (gauge,),
            penalty=contact_ramp(m.contact_penalty_kPa[0]),
            tie_at_start=True,
            solve=Solve.CONTACT,
        )
        res = run_load_step(m, tied).solve
        its += int(res.iterations)
        ok = res.status == StageStatus.CONVERGED
        self.sutured_u = m.u.copy() if ok else None
        state = self._measure() if ok else None
        return SolveStep(res.status, its, time.perf_counter() - t0, state)

    def suture_forces(self) -> np.ndarray:
        """Per suture, the tie's pull across the wound on its left footprint (mN; positive
        holds the walls together)."""
        m = self.model
        if self._shares is None or m.tie is None or m.contact is None or not m.tie.active:
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
        E = np.asarray(load.gradient(self.orientation_deg))
        lateral = np.union1d(d.x_face_nodes, d.y_face_nodes)
        rows = np.unique(
            np.concatenate([d.gauge_rows(), dof_rows(lateral, 0), dof_rows(lateral, 1)])
        )
        node, comp = rows // 3, rows % 3
        disp = (d.X[node, :2] - np.array([d.x_c, d.y_c])) @ E.T  # E (X - X_c) per row's node
        inc = np.where(comp < 2, disp[np.arange(len(rows)), np.minimum(comp, 1)], 0.0)
        start = self.sutured_u[rows]
        out: list[SolveStep] = []
        for j in range(1, steps + 1):
            t0 = time.perf_counter()
            moved = Dirichlet(rows, start + (j / steps) * inc)
            step = LoadStep(
                f"itch-{j}",
                (moved,),
                self.sutured_u if j == 1 else None,
                solve=Solve.CONTACT,
                first_step=1.0,
            )
            res = run_load_step(m, step).solve
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

"""Closure of a fusiform excision by interrupted sutures, and a load after closure
(docs/model.md, "Sutures" and "The load after closure").

`SuturedClosure` runs, on one mesh and one set of materials:

1. stage 1, pre-tension, and stage 2, the Dirichlet closure of the zone (the whole wound's
   length, its upper walls), as `WoundModel` does (`woundsweep.physics.stages`); the zone is
   left untied, so its nodes are contact points afterwards;
2. `suture`: from the stage-2 state, each suture's member is tied carrying the stage-2
   reactions of the zone nodes nearest it (along y), and the zone's Dirichlet condition is
   released while the flank contact's penalty is ramped from 1 kPa to 1 GPa, as stage 4 does:
   the sutures and the contact hold the wound. A placement can be re-solved from the same
   stage-2 state;
3. `itch`: from a sutured state, the patch's lateral faces are held in plane and moved by
   the load's displacement gradient E (u += E (X - X_c)), in ``steps`` equal increments, each
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
from ..contact import SutureMembers
from ..core.schema import StageStatus
from ..solver.continuation import LoadState, continuation
from ..solver.newton import Policy
from .domain import dof_rows
from .materials import JobMaterials
from .profiles import locate_cells
from .stages import CONTACT_MAX_DECADES, CONTACT_START_kPa, WoundModel
from .suture_measures import SutureState, measure_state

__all__ = ["BITE_SAMPLES", "SolveStep", "SuturedClosure", "anchor", "loop_anchors"]

# A suture is tied when the surface gap under it is at most this fraction of the wound width;
# its rest length is adjusted at most TIE_ITERATIONS times to get there.
TIE_GAP_PER_W = 0.005
TIE_ITERATIONS = 12
# Points along each anchor's path whose interpolation weights make up the anchor; the wall
# points lie this far inside the tissue, at most WALL_FRACTION of the wall's height deep.
BITE_SAMPLES = 4
WALL_INSET_mm = 0.02
WALL_FRACTION = 0.9
# The wound's edges are first held closed (Dirichlet) over this length under each suture.
FOOTPRINT_mm = 1.0


class SolveStep(NamedTuple):
    """How one solve went and the state it reached (None if it did not converge)."""

    status: str
    newton_iterations: int
    time_s: float
    state: SutureState | None


def anchor(domain: Any, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, weights) of the mean of ``points`` (k, 3), each interpolated linearly in the
    cell that holds it (its vertices' barycentric weights). ValueError if a point is in no
    cell."""
    cells = locate_cells(domain, points)
    if np.any(cells < 0):
        p = points[int(np.argmin(cells))]
        raise ValueError(f"a suture's path leaves the tissue at ({p[0]:.3g}, {p[1]:.3g}, {p[2]:.3g}) mm")
    nodes, weights = [], []
    for p, c in zip(points, cells):
        lam = domain.Dm_inv[c] @ (p - domain.X[domain.cell_vertices[c, 0]])
        bary = np.clip(np.concatenate([[1.0 - lam.sum()], lam]), 0.0, None)
        nodes.append(domain.cell_vertices[c])
        weights.append(bary / bary.sum())
    uniq, inv = np.unique(np.concatenate(nodes), return_inverse=True)
    w = np.bincount(inv, weights=np.concatenate(weights))
    return uniq, w / w.sum()


def loop_anchors(
    domain: Any, lens: Lens, y: float, bite_width: float, bite_depth: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The four anchors of a suture at ``y`` (`woundsweep.contact.sutures.ANCHORS`): each bite
    the upper half of the vertical path a bite width outside the edge, from the surface to
    half the bite depth; each wall point the wall just inside the tissue from half the bite
    depth to the bite depth (at most `WALL_FRACTION` of the wall's height there), each the
    mean of `BITE_SAMPLES` points."""
    z_top = domain.z_top
    half = lens.half_width(y)
    wall = -lens.floor_z(lens.x_c + half)  # the wall's height at y
    depth_wall = min(bite_depth, WALL_FRACTION * wall)
    t = (np.arange(BITE_SAMPLES) + 0.5) / BITE_SAMPLES
    z_bite = z_top - 0.5 * bite_depth * t
    z_wall = z_top - depth_wall * (0.5 + 0.5 * t)
    out = []
    for x, z in (
        (lens.x_c - half - bite_width, z_bite),
        (lens.x_c - half - WALL_INSET_mm, z_wall),
        (lens.x_c + half + WALL_INSET_mm, z_wall),
        (lens.x_c + half + bite_width, z_bite),
    ):
        pts = np.column_stack([np.full_like(z, x), np.full_like(z, y), z])
        out.append(anchor(domain, pts))
    return out


class SuturedClosure:
    """A fusiform excision's mesh closed by sutures (module docstring). ``lens``: the
    excision's outline (`GeometrySpec.lens`); ``dermal_thickness_mm`` sets the default bite
    depth; ``zone_depth_fraction`` the Dirichlet-closed zone's depth."""

    def __init__(
        self,
        mesh: Any,
        lens: Lens,
        dermal_thickness_mm: float,
        solver: SolverSettings | None = None,
        zone_depth_fraction: float = ClosureZone.depth_fraction,
        jit: dict[str, Any] | None = None,
    ) -> None:
        stages = StageSettings(ClosureZone(1.0, zone_depth_fraction))
        self.model = WoundModel(mesh, solver, stages, jit=jit, tie_zone=False)
        if self.model.contact is None or self.model.closure_line is None:
            raise ValueError("the mesh has no wound to suture")
        self.lens = lens
        self.dermal_thickness_mm = float(dermal_thickness_mm)
        self.closed_u: np.ndarray | None = None
        self.members: SutureMembers | None = None
        self.positions_mm: tuple[float, ...] = ()
        self.tied_tension_mN: np.ndarray | None = None
        self.plan: SuturePlan | None = None
        self.materials: JobMaterials | None = None
        self.orientation_deg = 0.0

    @property
    def domain(self) -> Any:
        return self.model.domain

    def close(self, materials: JobMaterials, orientation_deg: float) -> list[SolveStep]:
        """Stages 1 and 2 (pre-tension, Dirichlet closure of the zone)."""
        self.materials = materials
        self.orientation_deg = float(orientation_deg)
        self.model.set_materials(materials)
        self.model.problem.members = None
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

    def _members(self, plan: SuturePlan, ys: Sequence[float]) -> SutureMembers:
        d = self.domain
        lens = self.lens
        depth = plan.depth(self.dermal_thickness_mm)
        loops = [loop_anchors(d, lens, y, plan.bite_width_mm, depth) for y in ys]
        k = plan.stiffness_mN_per_mm(self.dermal_thickness_mm)
        members = SutureMembers(len(d.X), loops, k)
        members.y_mm = np.asarray(ys, dtype=float)  # type: ignore[attr-defined]
        return members

    def footprints(self, ys: Sequence[float]) -> list[np.ndarray]:
        """Per suture, the zone nodes (both flanks) within `FOOTPRINT_mm` / 2 of its y, and at
        least the column of zone nodes nearest to it."""
        d = self.domain
        nodes = d.zone_nodes
        y = d.X[nodes, 1]
        out = []
        for yi in ys:
            dist = np.abs(y - yi)
            reach = max(0.5 * FOOTPRINT_mm, float(dist.min()) * (1 + 1e-9))
            out.append(nodes[dist <= reach])
        return out

    def _close_footprints(self, ys: Sequence[float]) -> tuple[str, int, np.ndarray]:
        """From the stage-2 state, release the zone's Dirichlet closure everywhere but under
        the sutures (no contact); return the status, the Newton steps and per suture the
        reaction (mN, along x) on its left flank's footprint."""
        model, d = self.model, self.domain
        feet = self.footprints(ys)
        held = np.unique(np.concatenate(feet))
        rows = np.concatenate([d.gauge_rows(), dof_rows(held, 0)])
        offset = model.problem.residual_array()
        offset[rows] = 0.0
        values = model.u[rows].copy()
        scale = float(np.linalg.norm(model.problem.internal_force()))

        def load(s: float) -> LoadState:
            return LoadState(values, (1.0 - s) * offset)

        res = continuation(model.newton, rows, load, scale, 1.0, Policy(model.settings, symmetric=True))
        r = model.problem.residual_array()
        left = [f[d.X[f, 0] < d.x_c] for f in feet]
        shares = np.array([max(float(r[dof_rows(f, 0)].sum()), 0.0) for f in left])
        return res.status, int(res.iterations), shares

    def suture(self, plan: SuturePlan, ys: Sequence[float] | None = None) -> SolveStep:
        """Tie the sutures of ``plan`` (at ``ys``, default the plan's positions) at the
        stage-2 state and release the Dirichlet closure into them and the contact."""
        if self.closed_u is None:
            raise RuntimeError("close() first")
        t0 = time.perf_counter()
        model, d, c = self.model, self.domain, self.model.contact
        assert c is not None
        ys = tuple(plan.positions(2 * self.lens.a) if ys is None else ys)
        members = self._members(plan, ys)
        self.plan, self.positions_mm, self.members = plan, ys, members
        u = model.u
        u[:] = self.closed_u
        model.problem.members = None
        c.k_V_kPa = 0.0
        status, its0, shares = self._close_footprints(ys)
        if status != StageStatus.CONVERGED:
            return SolveStep(status, its0, time.perf_counter() - t0, None)
        # A loop pulls each flank across the wound twice (over the top and through the
        # walls): half the footprint's reaction is its tension.
        tension = 0.5 * shares
        members.tie(u, d.X, tension)
        self.tied_tension_mN = tension
        model.problem.members = members
        model.problem.closure_load = None
        c.clear_pattern()  # the next tangent plans the contact's pattern with the members'
        c.mult = None
        rows = d.gauge_rows()
        c.k_V_kPa = 0.0
        offset = model.problem.residual_array()  # the zone's reactions and the members' pull
        offset[rows] = 0.0
        values = u[rows].copy()
        scale = float(np.linalg.norm(model.problem.internal_force()))
        k_from, k_to = CONTACT_START_kPa, model.contact_penalty_kPa[0]

        def load(s: float) -> LoadState:
            c.k_V_kPa = k_from ** (1.0 - s) * k_to**s
            return LoadState(values, (1.0 - s) * offset)

        decades = np.log10(k_to / k_from)
        policy = Policy.contact(model.settings)
        res = continuation(
            model.newton, rows, load, scale, 0.5 / decades, policy, CONTACT_MAX_DECADES / decades
        )
        c.k_V_kPa = k_to
        iterations = its0 + int(res.iterations)
        if res.status == StageStatus.CONVERGED:
            status, its = self._tighten(rows)
            iterations += its
        else:
            status = res.status
        ok = status == StageStatus.CONVERGED
        state = self._measure() if ok else None
        self.sutured_u = u.copy() if ok else None
        return SolveStep(status, iterations, time.perf_counter() - t0, state)

    def suture_gaps(self) -> np.ndarray:
        """The surface gap (mm) at each suture's y at the current state."""
        d, line = self.domain, self.model.closure_line
        x = d.X[:, 0] + self.model.u.reshape(-1, 3)[:, 0]
        pairs = line.surface
        y = d.X[pairs[:, 0], 1]
        order = np.argsort(y)
        gap = (x[pairs[:, 1]] - x[pairs[:, 0]])[order]
        return np.interp(np.asarray(self.positions_mm), y[order], gap)

    def _tighten(self, rows: np.ndarray) -> tuple[str, int]:
        """Tie each suture until the edges meet under it: shorten its rest length by the
        surface gap there (a secant step after the first), re-solving from the current
        state, until every gap is within `TIE_GAP_PER_W` of the width (at most
        `TIE_ITERATIONS` times). Returns the last solve's status and the Newton steps."""
        members, model = self.members, self.model
        assert members is not None and members.rest is not None
        tol = TIE_GAP_PER_W * model.closure_line.width_mm
        slope = np.ones(len(members))  # gap closed per mm of rest length taken in
        prev_gap = prev_rest = None
        its = 0
        policy = Policy.contact(model.settings)
        for _ in range(TIE_ITERATIONS):
            gap = self.suture_gaps()
            if np.all(np.abs(gap) <= tol):
                return StageStatus.CONVERGED, its
            rest = members.rest.copy()
            if prev_gap is not None:
                taken = prev_rest - rest
                closed = prev_gap - gap
                ok = np.abs(taken) > 1e-12
                slope[ok] = np.clip(closed[ok] / taken[ok], 0.2, 5.0)
            new = rest - gap / slope
            prev_gap, prev_rest = gap, rest
            offset = model.problem.residual_array()
            offset[rows] = 0.0
            values = model.u[rows].copy()
            scale = float(np.linalg.norm(model.problem.internal_force()))

            def load(s: float, a: np.ndarray = rest, b: np.ndarray = new) -> LoadState:
                members.rest = a + s * (b - a)
                return LoadState(values, (1.0 - s) * offset)

            res = continuation(model.newton, rows, load, scale, 1.0, policy)
            its += int(res.iterations)
            if res.status != StageStatus.CONVERGED:
                return res.status, its
        gap = self.suture_gaps()
        return (StageStatus.CONVERGED if np.all(np.abs(gap) <= tol) else "not-tied"), its

    # -- the load after closure -----------------------------------------------------------

    def itch(self, load: ItchLoad, steps: int = 4) -> list[SolveStep]:
        """Apply ``load`` from the sutured state in ``steps`` equal increments of the
        lateral faces' in-plane displacement; stops at the first that does not converge."""
        if getattr(self, "sutured_u", None) is None:
            raise RuntimeError("suture() first")
        model, d = self.model, self.domain
        u = model.u
        u[:] = self.sutured_u
        E = np.asarray(load.gradient(self.orientation_deg))
        lateral = np.union1d(d.x_face_nodes, d.y_face_nodes)
        rows = np.unique(
            np.concatenate([d.gauge_rows(), dof_rows(lateral, 0), dof_rows(lateral, 1)])
        ).astype(np.int32)
        node, comp = rows // 3, rows % 3
        rel = d.X[node, :2] - np.array([d.x_c, d.y_c])
        disp = rel @ E.T  # E (X - X_c) at each row's node
        inc = np.where(comp < 2, disp[np.arange(len(rows)), np.minimum(comp, 1)], 0.0)
        start = u[rows].copy()
        policy = Policy.contact(model.settings)
        out: list[SolveStep] = []
        for j in range(1, steps + 1):
            t0 = time.perf_counter()
            a = u[rows].copy()
            b = start + (j / steps) * inc
            offset = model.problem.residual_array()
            offset[rows] = 0.0
            scale = float(np.linalg.norm(model.problem.internal_force()))

            def ramp(s: float, a: np.ndarray = a, b: np.ndarray = b, off: Any = offset) -> LoadState:
                return LoadState(a + s * (b - a), (1.0 - s) * off)

            res = continuation(model.newton, rows, ramp, scale, 1.0, policy)
            ok = res.status == StageStatus.CONVERGED
            state = self._measure() if ok else None
            out.append(SolveStep(res.status, int(res.iterations), time.perf_counter() - t0, state))
            if not ok:
                break
        return out

    def _measure(self) -> SutureState:
        return measure_state(self.model, self.lens, self.members)

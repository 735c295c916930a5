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
from ..contact import Cables, ZoneTie
from ..core.schema import MeshData, StageStatus
from ..solver.dirichlet import Dirichlet
from .domain import WoundDomain, dof_rows
from .loadpath import LoadStep, Solve, run_load_step
from .materials import JobMaterials
from .model import WoundModel
from .stages import contact_ramp, run_stage
from .suture_measures import (
    SurfacePatch,
    SutureState,
    bite_pressure,
    closest_approach,
    measure_state,
    surface_gaps,
    surface_patch,
)
from .thread import NYLON_4_0, ANCHOR_RADIUS_mm, SutureThread, needle_track, suture_loop

__all__ = ["BLEND_mm", "NOT_APPOSED", "TIGHTEN_STEPS", "SolveStep", "SuturedClosure"]

# A held wall point's pull counts for its nearest suture, blended linearly into the next one's
# over this length about the point halfway between them (so the split of the load between
# neighbours does not jump with the mesh's nodes, nor with rounding in a symmetric placement).
BLEND_mm = 0.5


# The status of a thread closure that converged but stayed wider than asked at a suture.
NOT_APPOSED = "not-apposed"
# At most this many tightenings of the threads toward apposition (`SuturedClosure.thread`).
TIGHTEN_STEPS = 12
# The knots' first pull: this fraction of the largest apposition force (tightened threads pull
# their flank with 2 T, about 1.3-1.6 times the apposition force).
FIRST_PULL_PER_APPOSITION = 0.7
# The knots are pulled until the walls' widest closest approach under a suture is within
# AIM_TOLERANCE of the target from AIM times it: one gap, not anywhere below the target, so
# that the pull is determined.
AIM = 0.8
AIM_TOLERANCE = 0.05
# A trial that does not converge is retried this many times, halfway back to the last that did.
BACKOFFS = 2


def _next_pull(history: list[tuple[float, float]], aim: float) -> float:
    """The next knot tension (mN) from the (tension, widest gap) trials so far: the secant
    through the two nearest the aim, kept inside the bracket the trials give (halfway into
    it when the secant leaves it), or x1.5 / /1.5 while no trial lies on one side."""
    below = [t for t, g in history if g <= aim]  # pulled enough
    above = [t for t, g in history if g > aim]
    lo, hi = (max(above) if above else None), (min(below) if below else None)
    t1, g1 = history[-1]
    if lo is None:
        return t1 / 1.5
    if hi is None:
        return t1 * 1.5
    pts = sorted(history, key=lambda h: abs(h[1] - aim))[:2]
    (ta, ga), (tb, gb) = pts
    guess = ta + (aim - ga) * (tb - ta) / (gb - ga) if gb != ga else 0.5 * (lo + hi)
    return guess if lo < guess < hi else 0.5 * (lo + hi)


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
        self.zone_depth_fraction = float(zone_depth_fraction)
        self.closed_r: np.ndarray | None = None  # the stage-2 residual: its reactions
        self.cables: Cables | None = None
        self.tracks_mm: np.ndarray = np.zeros((0, 2, 2, 3))  # (suture, flank, entry/exit, xyz)
        self.shortening_mm = np.zeros(0)  # per loop: how much shorter than at apposition, mm
        self.knot_tension_mN: float | None = None  # the one pull the knots were tied with
        self.radius_mm = ANCHOR_RADIUS_mm  # the threads' anchor radius (`thread`)

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
        self.closed_r = self.model.problem.residual_array()
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
        self._detach_threads()
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

    # -- threads --------------------------------------------------------------------------

    @property
    def bite_depth_mm(self) -> float:
        """The bite depth: the closure zone's (mm)."""
        return self.zone_depth_fraction * self.lens.d

    def _detach_threads(self) -> None:
        self.cables = None
        self.model.attach_cables(None)

    def thread(
        self,
        plan: SuturePlan,
        ys: Sequence[float] | None = None,
        material: SutureThread = NYLON_4_0,
        radius_mm: float = ANCHOR_RADIUS_mm,
        apposed_gap_mm: float | None = None,
    ) -> SolveStep:
        """Close the wound by threads from the stage-2 state (module docstring): every loop
        tied at its length there, the zone's Dirichlet condition released while the flank
        contact is ramped in; then, with ``apposed_gap_mm``, every knot pulled with one tension
        until the walls meet under every suture (the widest of their closest approaches,
        `approach_at_sutures`, just below that), and held there
        (`_pull_until_apposed`; `TIGHTEN_STEPS` trials at most, the status `NOT_APPOSED` if
        none lands)."""
        if self.closed_u is None:
            raise RuntimeError("close() first")
        if self.model.tie is not None:
            raise RuntimeError("threads on a model whose footprints are tied: a new SuturedClosure")
        t0 = time.perf_counter()
        m, d = self.model, self.domain
        ys = tuple(plan.positions(2 * self.lens.a) if ys is None else ys)
        tracks = np.array(
            [
                needle_track(d, self.lens.half_width(float(y)), float(y), plan.bite_width_mm,
                             self.bite_depth_mm)
                for y in ys
            ]
        )  # fmt: skip
        cables = Cables(d.X, [suture_loop(d, t, radius_mm) for t in tracks], material.EA_mN)
        self.radius_mm = float(radius_mm)
        self.cables, self.tracks_mm, self.positions_mm = cables, tracks, ys
        self._shares = None
        m.attach_cables(cables)
        self.knot_tension_mN = None
        self.shortening_mm = np.zeros(len(ys))
        if apposed_gap_mm is None:
            res = self._from_closed(None)
            status, its = str(res.status), int(res.iterations)
        else:  # every trial starts from the stage-2 state: the tie at apposition is not needed
            status, its = self._pull_until_apposed(ys, apposed_gap_mm)
        ok = status in (StageStatus.CONVERGED, NOT_APPOSED)
        self.sutured_u = m.u.copy() if ok else None
        state = self._measure() if ok else None
        return SolveStep(status, its, time.perf_counter() - t0, state)

    def _from_closed(self, pull_mN: float | None) -> Any:
        """From the stage-2 state: the loops tied at their length there (``pull_mN`` None) or
        pulled with ``pull_mN``, the zone's condition released and the contact ramped in (as
        stage 4); the continuation's result."""
        m, d = self.model, self.domain
        assert self.cables is not None and self.closed_u is not None
        m.u[:] = self.closed_u
        if pull_mN is None:
            self.cables.tie(m.u)
        else:
            self.cables.pull(pull_mN)
        step = LoadStep(
            "thread-tie",
            (Dirichlet(d.gauge_rows()),),
            self.closed_u,
            penalty=contact_ramp(m.contact_penalty_kPa[0]),
            solve=Solve.CONTACT,
        )
        return run_load_step(m, step).solve

    def _pull_until_apposed(self, ys: Sequence[float], target_mm: float) -> tuple[str, int]:
        """Every knot pulled with one tension, the smallest that brings the widest of the
        walls' closest approaches under the sutures to `AIM` x ``target_mm`` (within
        `AIM_TOLERANCE` x it), then held: each loop tied at its length there. (status, Newton
        steps)."""
        assert self.cables is not None and self.closed_u is not None
        apposed = self.cables.lengths(self.closed_u)
        aim, tol = AIM * target_mm, AIM_TOLERANCE * target_mm
        t = FIRST_PULL_PER_APPOSITION * float(np.max(self.apposition_forces(ys)))
        history: list[tuple[float, float]] = []
        its, good = 0, None
        status: str = NOT_APPOSED
        for _ in range(TIGHTEN_STEPS):
            for _ in range(BACKOFFS + 1):
                res = self._from_closed(t)
                its += int(res.iterations)
                if res.status == StageStatus.CONVERGED:
                    break
                t = 0.5 * (t + good) if good is not None else 0.5 * t
            else:
                return res.status, its
            good = t
            g = float(self.approach_at_sutures().max())
            history.append((t, g))
            if abs(g - aim) <= tol:
                status = StageStatus.CONVERGED
                break
            t = _next_pull(history, aim)
        self.knot_tension_mN = good
        self.cables.hold(self.model.u)
        assert self.cables.rest_mm is not None
        self.shortening_mm = apposed - self.cables.rest_mm
        return status, its

    def approach_at_sutures(self) -> np.ndarray:
        """Under each suture, the walls' closest approach within the closure zone (mm,
        `closest_approach`): within the anchor radius of its needle track along the wound."""
        return closest_approach(
            self.model, np.asarray(self.positions_mm, float), self.radius_mm, self.bite_depth_mm
        )

    def bite_pressure(self) -> np.ndarray:
        """Per thread, the pressure under its bites at the current state (kPa,
        `bite_pressure`)."""
        if self.cables is None:
            raise RuntimeError("thread() first")
        return bite_pressure(self.model, self.tracks_mm, self.radius_mm)

    def gaps_at_sutures(self) -> np.ndarray:
        """The surface gap at each suture's y in the current state (mm)."""
        y, gap = surface_gaps(self.model)
        return np.interp(np.asarray(self.positions_mm, float), y, gap)

    def apposition_forces(self, ys: Sequence[float]) -> np.ndarray:
        """Per suture at ``ys``, the stage-2 Dirichlet closure's pull on the left wall over the
        stretch of wound it holds (the wall's nodes counted by `shares`; mN): the force that
        apposes the edges there, which the suture replaces."""
        if self.closed_r is None:
            raise RuntimeError("close() first")
        left = self.domain.zone_left_nodes
        return self.closed_r[3 * left] @ self.shares(self.domain.X[left, 1], ys)

    def thread_pull(self) -> np.ndarray:
        """Per suture, the x-force its thread exerts on the left flank (mN, toward the wound;
        about twice the tension: two strands cross)."""
        if self.cables is None:
            return np.zeros(len(self.positions_mm))
        forces = self.cables.anchor_forces(self.model.u)
        return np.array([-f[: len(f) // 2, 0].sum() for f in forces])

    def suture_forces(self) -> np.ndarray:
        """Per suture, the tie's pull across the wound on its left footprint (mN; positive
        holds the walls together)."""
        m = self.model
        if self.cables is not None:
            return self.cables.tensions(m.u)
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

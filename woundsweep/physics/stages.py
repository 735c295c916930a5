"""The six stages of primary-intention closure (paper: "Modeling primary intention in six
stages"), as recipes over the wound model's domain, forms and problem.

1. Pre-tension: the lateral faces and the deep face stretched by the tension scaling factor.
2. The lateral Dirichlet conditions replaced by the traction of healthy skin; the closure
   zone's wound nodes moved onto the mid-plane (Dirichlet closure).
3. The closure's Dirichlet condition replaced by its consistent nodal reactions, a dead load.
4-6. Contact of the flanks at penalty k_V = 1, 5, 100 GPa, under the same closure load.

docs/model.md states each stage's boundary conditions and loads and why they depart from the
paper where they do. Every change between stages is ramped by load continuation
(`woundsweep.solver.continuation`): Dirichlet values move linearly from their current to
their target values, and the out-of-balance force of the starting state under the new
stage's loads is released linearly (R(u) - (1 - s) R(u_start) = 0 at the free dofs), so s = 0
is exactly the previous state.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse

from ..config.paper import StageSettings
from ..config.solver import NewtonSettings, SolverSettings
from ..contact import GPA_TO_KPA, ContactModel, FlankContact, ZoneTie, split_wound_flanks
from ..core.schema import DERMIS, STAGES, SUBCUTIS, StageStatus, start_stage
from ..solver.continuation import ContinuationResult, LoadState, continuation
from ..solver.newton import NewtonSolver, Policy
from ..solver.symmetry import SymmetryBasis
from .closure import ClosureLine
from .domain import WoundDomain, dof_rows
from .forms import WoundForms
from .materials import HomogeneousState, JobMaterials, homogeneous_state
from .problem import WoundProblem
from .stability import lowest_eigenvalues

__all__ = ["CONTACT_MAX_DECADES", "CONTACT_START_kPa", "StageOutcome", "WoundModel"]

CONTACT_START_kPa = 1.0  # stage 4's penalty ramp starts here: far below the tissue moduli
# Stage 4's penalty grows by at most this many decades per load increment: larger jumps
# (increments double after easy ones) push the flanks apart faster than Newton can follow.
CONTACT_MAX_DECADES = 1.5
# A contact stage's state is accepted when no engaged point's support step differs from the
# one it was solved with by more than SUPPORT_TOL; at most SUPPORT_ROUNDS re-solves get it there.
SUPPORT_TOL, SUPPORT_ROUNDS = 1e-3, 3
# The counts and times of a `ContinuationResult` that add up over consecutive solves.
_SUMMED = ("iterations", "increments", "cuts", "assembly_time_s", "factor_time_s",
           "solve_time_s", "residual_time_s")  # fmt: skip


class StageOutcome(NamedTuple):
    """What a stage produced (arrays in mesh order; `WoundModel` maps them to input order)."""

    stage: int
    solve: ContinuationResult
    time_s: float
    diagnostics: dict[str, float]


class WoundModel:
    """One mesh's domain, forms, problem and Newton solver, and the six stage recipes.

    The forms compile on construction (JIT cache hits after the first time on a machine);
    ``jit_time_s`` records how long that took. Materials can be reassigned between jobs.
    ``tie_zone`` False leaves the closure zone untied in the contact stages (its nodes are
    contact points): the sutured closure (`woundsweep.physics.sutures`) holds it instead.
    """

    def __init__(
        self,
        mesh_data: Any,
        solver: SolverSettings | None = None,
        stages: StageSettings | None = None,
        *,
        jit: dict[str, Any] | None = None,
        tie_zone: bool = True,
    ) -> None:
        solver = solver or SolverSettings()
        # Without stage settings the closure zone is the one the mesh was built with.
        zone = None if stages is None else stages.closure_zone
        penalties = (stages or StageSettings()).contact_penalty_GPa
        if len(penalties) != 3:
            raise ValueError("contact_penalty_GPa needs three values (stages 4, 5, 6)")
        self.contact_penalty_kPa = tuple(float(k) * GPA_TO_KPA for k in penalties)
        self.domain = d = WoundDomain(mesh_data, zone, solver.element_degree)
        self.contact: ContactModel | None = None
        self.tie: ZoneTie | None = None
        self.closure_line: ClosureLine | None = None
        if d.has_wound:
            flanks = split_wound_flanks(d.X, d.cell_vertices, d.wound_facets(), d.x_c)
            left, right = (d.element.sub_triangles(f) for f in flanks)
            pairs = ZoneTie(d.X, d.zone_left_nodes, d.zone_right_nodes, left, d.x_c)
            # Without the tie (sutures hold the wound instead, `physics.sutures`) every flank
            # node is a contact point; the mirror pairs still measure the closure.
            self.tie = pairs if tie_zone else None
            tied = pairs.pairs.ravel() if tie_zone else None
            self.contact = FlankContact(d.X, left, right, tied=tied)
            self.closure_line = ClosureLine(d.X, pairs.pairs, np.unique(left), d.z_top)
        self.forms = WoundForms(d, solver.form_quadrature_degree, jit)
        self.problem = WoundProblem(d, self.forms, self.contact, self.tie)
        self.newton = NewtonSolver(self.problem, self.problem.A, solver.newton)
        # The sutured closure's stitches need not share the patch's symmetry.
        self.use_symmetry = solver.symmetry and tie_zone and d.has_wound
        self.materials: JobMaterials | None = None
        self.homogeneous: dict[int, HomogeneousState] = {}
        self.results: dict[int, StageOutcome] = {}
        self.displacements: dict[int, np.ndarray] = {}
        # The closure's nodal reactions at the end of stage 2 (flat dofs, mN): the closing
        # load of stages 3-6. None before stage 2.
        self.closing_forces: np.ndarray | None = None

    def _symmetry(self, materials: JobMaterials) -> SymmetryBasis | None:
        """The job's symmetry: both mirrors with the Langer line along x or y, else the
        half-turn about the wound's vertical centre line (the mesh, the stages' loads and
        the tie share both)."""
        if not self.use_symmetry:
            return None
        a1 = np.asarray(materials.dermis.a1, dtype=float)
        mirrors = bool(min(abs(a1[0]), abs(a1[1])) < 1e-12)
        return self.domain.symmetry(mirrors)

    @property
    def settings(self) -> NewtonSettings:
        """Newton's settings."""
        return self.newton.settings

    @property
    def jit_time_s(self) -> float:
        """How long compiling (or loading) the forms took, s."""
        return self.forms.jit_time_s

    @property
    def u(self) -> np.ndarray:
        """The current displacement dofs (a writable view)."""
        return self.forms.u.x.array

    def set_materials(self, materials: JobMaterials) -> None:
        """Assign a job's material constants (no recompilation) and reset the state."""
        self.materials = materials
        self.forms.set_materials(materials)
        self.newton.set_symmetry(self._symmetry(materials))
        self.homogeneous = {
            DERMIS: homogeneous_state(materials.dermis, materials.tsf),
            SUBCUTIS: homogeneous_state(materials.subcutis, materials.tsf),
        }
        self.forms.set_loads(np.zeros((3, 3)), np.zeros((3, 3)))
        self.problem.closure_load = None
        self.closing_forces = None
        if self.contact is not None:
            self.contact.k_V_kPa = 0.0
        if self.tie is not None:
            self.tie.release()
        self.u[:] = 0.0
        self.results.clear()
        self.displacements.clear()

    # -- measures of the current state ------------------------------------------------------

    def displacement_input(self) -> np.ndarray:
        """Displacement (n_points, 3) in input point order."""
        return self.u.reshape(-1, 3)[self.domain.input_node]

    def deformed_zone_area(self, side: str) -> float:
        """Deformed area (mm^2) of the closure-zone facets of one flank."""
        return self.domain.deformed_zone_area(side, self.u)

    def contact_forces(self) -> np.ndarray | None:
        """The contact's residual term (flat dofs, mN) at the current state, or None while
        the penalty is off."""
        c = self.contact
        if c is None or c.k_V_kPa <= 0.0:
            return None
        return c.force_vector(self.u)

    def _pin_reaction(self, r: np.ndarray) -> float:
        return float(np.max(np.abs(r[self.domain.pin_rows()])))

    def _lateral_force(self) -> float:
        """x-force (mN) of the healthy-skin traction on the x_max face: the load scale."""
        P, area = self.homogeneous, self.domain.x_max_area
        return float(P[DERMIS].P[0, 0] * area[DERMIS] + P[SUBCUTIS].P[0, 0] * area[SUBCUTIS])

    # -- stages -----------------------------------------------------------------------------

    def run_stage(self, stage: int) -> StageOutcome:
        """Run one stage from the current state (the previous stage's result)."""
        if self.materials is None:
            raise RuntimeError("set_materials() first")
        if stage not in STAGES:
            raise ValueError(f"stage {stage} is not implemented (available: {STAGES})")
        if stage > 1 and stage - 1 not in self.results:
            raise RuntimeError(f"stage {stage} needs stage {stage - 1} first")
        t0 = time.perf_counter()
        recipe = {1: self._stage1, 2: self._stage2, 3: self._stage3}.get(stage)
        res, diag = recipe() if recipe is not None else self._stage_contact(stage)
        out = StageOutcome(stage, res, time.perf_counter() - t0, diag)
        self.results[stage] = out
        self.displacements[stage] = self.u.copy()
        return out

    def _ramp(
        self,
        rows: np.ndarray,
        target: np.ndarray,
        offset: np.ndarray | None,
    ) -> ContinuationResult:
        """Continuation from the current state to ``target`` at ``rows`` with ``offset``
        released (every load is dead: a symmetric tangent)."""
        u = self.u
        start = u[rows].copy()
        free_offset = None
        if offset is not None:
            free_offset = offset.copy()
            free_offset[rows] = 0.0

        def load(s: float) -> LoadState:
            off = None if free_offset is None else (1.0 - s) * free_offset
            return LoadState(start + s * (target - start), off)

        scale = float(np.linalg.norm(self.problem.internal_force()))
        policy = Policy(self.settings, symmetric=True)
        return continuation(self.newton, rows, load, force_scale=scale, policy=policy)

    def _stage1(self) -> tuple[ContinuationResult, dict[str, float]]:
        """Pre-tension (eqs. 12-14): u = (TSF - 1)(x - x_c) on the x faces, likewise in y,
        and in-plane on the deep face (u_z = 0 there)."""
        assert self.materials is not None
        tsf = self.materials.tsf
        d = self.domain
        rows, target = [], []
        for nodes, comp, centre in (
            (d.x_face_nodes, 0, d.x_c),
            (d.y_face_nodes, 1, d.y_c),
            (d.bottom_nodes, 0, d.x_c),
            (d.bottom_nodes, 1, d.y_c),
        ):
            rows.append(dof_rows(nodes, comp))
            target.append((tsf - 1.0) * (d.X[nodes, comp] - centre))
        rows.append(dof_rows(d.bottom_nodes, 2))
        target.append(np.zeros(len(d.bottom_nodes)))
        r = np.concatenate(rows)
        t = np.concatenate(target)
        r, first = np.unique(r, return_index=True)
        t = t[first]
        self.forms.set_loads(0.0, 0.0)
        # Newton starts from the unwounded patch's solution, which meets these conditions
        # exactly: it corrects only the disturbance of the wound.
        self.u[:] = self._pretension_state().ravel()
        return self._ramp(r, t, None), {}

    def _pretension_state(self) -> np.ndarray:
        """Nodal displacements (n, 3) of the unwounded two-layer patch under stage 1's
        conditions: each layer at its homogeneous state F = diag(s, s, lambda3) (traction-free
        top and interface), u_z = 0 on the deep face and continuous across the layers."""
        d = self.domain
        X = d.X
        s = self.homogeneous[DERMIS].stretch  # the TSF, the same in both layers
        sub_nodes = np.unique(d.cell_nodes[d.cell_tags[d.cell_input] == SUBCUTIS])
        z_bottom = float(X[:, 2].min())
        z_int = float(X[sub_nodes, 2].max()) if len(sub_nodes) else z_bottom
        lam_sub = self.homogeneous[SUBCUTIS].lambda3
        lam_der = self.homogeneous[DERMIS].lambda3
        z = X[:, 2]
        u = np.empty_like(X)
        u[:, 0] = (s - 1.0) * (X[:, 0] - d.x_c)
        u[:, 1] = (s - 1.0) * (X[:, 1] - d.y_c)
        u[:, 2] = (lam_sub - 1.0) * (np.minimum(z, z_int) - z_bottom) + (lam_der - 1.0) * (
            np.maximum(z - z_int, 0.0)
        )
        return u

    def _stage2(self) -> tuple[ContinuationResult, dict[str, float]]:
        """Healthy-skin traction on the lateral faces (eqs. 15-16) and Dirichlet closure
        u_x = x_c - x on the closure zone (eq. 18)."""
        d = self.domain
        self.forms.set_loads(self.homogeneous[DERMIS].P, self.homogeneous[SUBCUTIS].P)
        offset = self.problem.residual_array()
        gauge = d.gauge_rows()
        u = self.u
        zone_rows = dof_rows(d.zone_nodes, 0)
        rows = np.concatenate([gauge, zone_rows])
        target = np.concatenate([u[gauge], d.x_c - d.X[d.zone_nodes, 0]])
        res = self._ramp(rows, target, offset)
        r = self.problem.residual_array()
        # The reactions of the Dirichlet closure: u_x is held, so they act along x only.
        self.closing_forces = np.zeros_like(r)
        self.closing_forces[zone_rows] = r[zone_rows]
        f_left = float(r[dof_rows(d.zone_left_nodes, 0)].sum())
        f_right = float(r[dof_rows(d.zone_right_nodes, 0)].sum())
        diag = {
            "closure_force_left_mN": f_left,
            "closure_force_right_mN": f_right,
            "pin_reaction_max_mN": self._pin_reaction(r),
            "lateral_force_mN": self._lateral_force(),
        }
        return res, diag

    def _stage3(self) -> tuple[ContinuationResult, dict[str, float]]:
        """Closure by a load (eqs. 17, 19): the Dirichlet closure's consistent nodal reactions
        of stage 2, applied as dead nodal forces (docs/model.md, "Closure load")."""
        assert self.closing_forces is not None
        self.problem.closure_load = self.closing_forces
        offset = self.problem.residual_array()
        rows = self.domain.gauge_rows()
        res = self._ramp(rows, self.u[rows].copy(), offset)
        r = self.problem.residual_array()
        d = self.domain
        area = self.deformed_zone_area("left") + self.deformed_zone_area("right")
        total = float(np.abs(self.closing_forces[dof_rows(d.zone_nodes, 0)]).sum())
        diag = {
            "closure_traction_kPa": total / area if area > 0 else 0.0,
            "pin_reaction_max_mN": self._pin_reaction(r),
        }
        return res, diag

    def _stage_contact(self, stage: int) -> tuple[ContinuationResult, dict[str, float]]:
        """Stages 4-6: the stage-3 loads plus flank contact at this stage's penalty.

        Stage 4 restarts from the stage-2 state (docs/model.md). The penalty is ramped
        geometrically from the previous stage's (stage 4: from ``CONTACT_START_kPa``) to this
        stage's value, so an overlap left by the closure is pushed out gradually instead of by
        a force of order k_V at once.
        """
        rows = self.domain.gauge_rows()
        u = self.u
        c = self.contact
        if c is None:  # no wound: nothing can touch; the stage re-solves the stage-3 loads
            offset = self.problem.residual_array()
            return self._ramp(rows, u[rows].copy(), offset), {}
        k_from, k_to, load, scale = self._contact_load(stage, rows)
        policy = Policy.contact(self.settings)
        # Stage 4 releases the closure and brings the penalty up from CONTACT_START_kPa at the
        # Dirichlet-closed state (six decades to 1 GPa): half a decade first, at most
        # CONTACT_MAX_DECADES later. Stages 5 and 6 start in contact equilibrium and are
        # solved in one increment (a cut halves it if needed).
        decades = max(np.log10(k_to / k_from), 1e-9)
        first = min(1.0, 0.5 / decades) if stage == 4 else 1.0
        largest = min(1.0, CONTACT_MAX_DECADES / decades) if stage == 4 else 1.0
        try:
            res = continuation(self.newton, rows, load, scale, first, policy, largest)
            res = self._support_rounds(res, rows, load, scale, policy)
        finally:
            c.k_V_kPa = k_to
        diag: dict[str, float] = {}
        if res.status != StageStatus.CONVERGED:
            # Stalled at a stable state, or at a limit point of the path? (stability.py)
            k_last = k_from ** (1.0 - res.load_reached) * k_to**res.load_reached
            diag.update(self._stability(rows, k_last))
            # The forces of the state reached, at the penalty it was reached with.
            c.k_V_kPa = k_last
        try:
            diag.update(self._contact_diagnostics(rows, u, c))
        finally:
            c.k_V_kPa = k_to
        return res, diag

    def _support_rounds(
        self,
        res: ContinuationResult,
        rows: np.ndarray,
        load: Callable[[float], LoadState],
        scale: float,
        policy: Policy,
    ) -> ContinuationResult:
        """Newton holds each point's support step at the solve's start (`FlankContact.
        freeze_support`); a converged state is a result only if the support it reached is the
        one it was solved with, so it is solved again at the stage's end load, support taken
        from it, until it is (at most ``SUPPORT_ROUNDS`` times; else max-iterations)."""
        c = self.contact
        assert c is not None
        rounds = 0
        while res.status == StageStatus.CONVERGED and c.support_change(self.u) > SUPPORT_TOL:
            if rounds == SUPPORT_ROUNDS:
                return res._replace(status=StageStatus.MAX_ITERATIONS)
            again = continuation(self.newton, rows, lambda s: load(1.0), scale, 1.0, policy)
            res = again._replace(**{f: getattr(res, f) + getattr(again, f) for f in _SUMMED})
            rounds += 1
        return res

    def _contact_diagnostics(
        self, rows: np.ndarray, u: np.ndarray, c: ContactModel
    ) -> dict[str, float]:
        """Pin reaction, tie and contact forces and penetration of ``u`` at ``c``'s penalty."""
        diag: dict[str, float] = {}
        r = self.problem.residual_array()
        diag["pin_reaction_max_mN"] = self._pin_reaction(r)
        diag["contact_penalty_kPa"] = c.k_V_kPa
        if self.tie is not None:
            diag["tie_force_mN"] = self.tie.force_mN(u, c.k_V_kPa)
            diag["tie_max_slip_mm"] = float(np.max(np.abs(self.tie.slip(u)), initial=0.0))
        detect, assemble, searches = c.detect_time_s, c.assembly_time_s, c.searches
        summ = c.summary(u)
        diag.update(
            {
                "n_penetrating": summ.n_penetrating,
                "max_penetration_mm": summ.max_penetration_mm,
                "max_penetration_rel": summ.max_penetration_rel,
                "contact_force_mN": summ.contact_force_mN,
                "contact_detect_time_s": detect,
                "contact_assembly_time_s": assemble,
                "contact_searches": searches,
            }
        )
        return diag

    def _contact_load(
        self, stage: int, rows: np.ndarray
    ) -> tuple[float, float, Callable[[float], LoadState], float]:
        """Set up contact stage ``stage`` at the current state: (k_from, k_to, the load of the
        continuation parameter s, the force scale). At s = 0 the state is in equilibrium."""
        c = self.contact
        assert c is not None
        u = self.u
        k_to = self.contact_penalty_kPa[stage - 4]
        k_from = CONTACT_START_kPa if stage == 4 else self.contact_penalty_kPa[stage - 5]
        k_from = min(k_from, k_to)
        if stage == 4:
            u[:] = self.displacements[start_stage(4)]
            self.problem.closure_load = self.closing_forces  # whatever stage 3 did
            if self.tie is not None:  # the closed zone is tied where stage 2 closed it
                self.tie.set_reference(u)
        c.reset_timers()
        # Out-of-balance force released over the stage: stage 4, that of the stage-2 state
        # under the closure load (contact off; zero up to stage 2's convergence); stages 5 and 6 start from an equilibrium
        # with contact at k_from, so only its convergence residual is left to release.
        c.k_V_kPa = 0.0 if stage == 4 else k_from
        offset = self.problem.residual_array()
        offset[rows] = 0.0
        values = u[rows].copy()
        scale = float(np.linalg.norm(self.problem.internal_force()))

        def load(s: float) -> LoadState:
            c.k_V_kPa = k_from ** (1.0 - s) * k_to**s
            return LoadState(values, (1.0 - s) * offset)

        return k_from, k_to, load, scale

    def _stability(self, rows: np.ndarray, k_V_kPa: float) -> dict[str, float]:
        """Lowest eigenvalue nearest zero (mN/mm) of the free-dof tangent at the current state
        with penalty ``k_V_kPa`` (NaN if it cannot be computed). With the dead closure load
        every load is dead, so the tangent is the Hessian of the total potential and its sign
        decides the stability of that equilibrium."""
        c = self.contact
        assert c is not None
        A = self.problem.A
        saved = c.k_V_kPa
        c.k_V_kPa = k_V_kPa
        c.mult = None  # the potential's own Hessian, not a failed solve's semi-smooth tangent
        free = np.ones(A.getSize()[0], dtype=bool)
        free[rows] = False
        try:
            self.problem.jacobian(A)
            ai, aj, av = A.getValuesCSR()
            K = scipy.sparse.csr_matrix((av, aj, ai), shape=A.getSize())
            try:
                eig = float(lowest_eigenvalues(K, free)[0])
            except ArithmeticError:
                eig = float("nan")
        finally:
            c.k_V_kPa = saved
        return {"stability_min_eig_mN_per_mm": eig, "stability_penalty_kPa": k_V_kPa}

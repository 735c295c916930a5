"""The wound model: one mesh's domain, forms, problem and Newton solver, and the state a load
path works on (the displacement, the job's materials, the stages' results and states).

What a stage does is not here: the stages, the sutured closure and the load after closure are
recipes (`woundsweep.physics.loadpath.LoadStep`) that `woundsweep.physics.loadpath.
run_load_step` runs on a model.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..config.paper import StageSettings
from ..config.solver import NewtonSettings, SolverSettings
from ..contact import GPA_TO_KPA, Cables, FlankContact, ZoneTie, split_wound_flanks
from ..core.schema import DERMIS, SUBCUTIS, MeshData
from ..solver.continuation import ContinuationResult
from ..solver.newton import NewtonSolver
from ..solver.symmetry import SymmetryBasis
from .closure import ClosureLine
from .domain import WoundDomain
from .forms import WoundForms
from .materials import HomogeneousState, JobMaterials, homogeneous_state
from .problem import WoundProblem

__all__ = ["StageOutcome", "WoundModel"]


class StageOutcome(NamedTuple):
    """What a stage produced (arrays in mesh order; `WoundModel` maps them to input order)."""

    stage: int
    solve: ContinuationResult
    time_s: float
    diagnostics: dict[str, float]


class WoundModel:
    """One mesh's domain, forms, problem and Newton solver, and the state of a job on it.

    The forms compile on construction (JIT cache hits after the first time on a machine);
    ``jit_time_s`` records how long that took. Materials can be reassigned between jobs.
    ``tie_zone`` False leaves the closure zone untied in the contact stages (its nodes are
    contact points): the sutured closure (`woundsweep.physics.sutures`) attaches its own tie
    (`attach_tie`).
    """

    def __init__(
        self,
        mesh_data: MeshData,
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
        # The closing load of stages 3-6 (`woundsweep.physics.stages`); only the reactions'
        # closure ties the zone in the contact stages.
        self.closure_load = (stages or StageSettings()).closure_load
        symmetric = tie_zone
        tie_zone = tie_zone and self.closure_load == "reactions"
        if len(penalties) != 3:
            raise ValueError("contact_penalty_GPa needs three values (stages 4, 5, 6)")
        self.contact_penalty_kPa = tuple(float(k) * GPA_TO_KPA for k in penalties)
        self.domain = d = WoundDomain(mesh_data, zone, solver.element_degree)
        self.contact: FlankContact | None = None
        self.tie: ZoneTie | None = None
        self.closure_line: ClosureLine | None = None
        self.flanks: tuple[np.ndarray, np.ndarray] | None = None
        if d.has_wound:
            flanks = split_wound_flanks(d.X, d.cell_vertices, d.wound_facets(), d.x_c)
            left, right = (d.element.sub_triangles(f) for f in flanks)
            self.flanks = (left, right)
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
        self.use_symmetry = solver.symmetry and symmetric and d.has_wound
        self.materials: JobMaterials | None = None
        self.homogeneous: dict[int, HomogeneousState] = {}
        self.results: dict[int, StageOutcome] = {}
        self.displacements: dict[int, np.ndarray] = {}
        # The closing load of stages 3-6 (flat dofs, mN) and its amplitude (kPa; None for the
        # reactions, which have no single traction). None before stage 2.
        self.closing_forces: np.ndarray | None = None
        self.closing_traction_kPa: float | None = None

    def attach_tie(self, tie: ZoneTie) -> None:
        """Hold the wound by ``tie`` (the sutures' footprints) instead of the closure zone's
        tie: the flank contact, the problem and the Newton solver are made anew with it (its
        pairs are not contact points)."""
        if self.flanks is None:
            raise ValueError("the mesh has no wound to tie")
        d = self.domain
        left, right = self.flanks
        self.tie = tie
        self.contact = FlankContact(d.X, left, right, tied=tie.pairs.ravel())
        cables = self.problem.cables
        self.problem = WoundProblem(d, self.forms, self.contact, tie)
        self.problem.set_cables(cables)
        self.newton = NewtonSolver(self.problem, self.problem.A, self.settings)

    def attach_cables(self, cables: Cables | None) -> None:
        """Hold the wound by ``cables`` too (the sutures' threads, `woundsweep.contact.cable`;
        None: none): their term joins the problem's residual, tangent and energy once tied."""
        self.problem.set_cables(cables)

    def set_newton_settings(self, settings: NewtonSettings) -> None:
        """Solve with ``settings`` from here on (a Newton solver made anew on the problem)."""
        self.newton = NewtonSolver(self.problem, self.problem.A, settings)
        if self.materials is not None:
            self.newton.set_symmetry(self._symmetry(self.materials))

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
        self.closing_traction_kPa = None
        if self.contact is not None:
            self.contact.k_V_kPa = 0.0
        if self.tie is not None:
            self.tie.release()
        self.u[:] = 0.0
        self.results.clear()
        self.displacements.clear()

    def hold_closure_reactions(self, r: np.ndarray, rows: np.ndarray) -> None:
        """Keep the residual ``r``'s reactions at ``rows`` (the Dirichlet closure's, flat dofs,
        mN) as the closing load of the stages after it; zero elsewhere."""
        forces = np.zeros_like(r)
        forces[rows] = r[rows]
        self.closing_forces = forces

    def hold_closing_traction(self, shape: np.ndarray, amplitude_kPa: float) -> None:
        """Keep ``amplitude_kPa`` times ``shape`` (the nodal forces of a unit traction, flat
        dofs, mN per kPa) as the closing load of the stages after it."""
        self.closing_forces = amplitude_kPa * shape
        self.closing_traction_kPa = float(amplitude_kPa)

    def record(self, outcome: StageOutcome) -> None:
        """Keep a stage's outcome and its end state (a later stage may start from it)."""
        self.results[outcome.stage] = outcome
        self.displacements[outcome.stage] = self.u.copy()

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

    def pin_reaction(self, r: np.ndarray) -> float:
        """The largest reaction (mN) of the gauge pins in the residual ``r``."""
        return float(np.max(np.abs(r[self.domain.pin_rows()])))

    def lateral_force(self) -> float:
        """x-force (mN) of the healthy-skin traction on the x_max face: the load scale."""
        P, area = self.homogeneous, self.domain.x_max_area
        return float(P[DERMIS].P[0, 0] * area[DERMIS] + P[SUBCUTIS].P[0, 0] * area[SUBCUTIS])

    def pretension_state(self) -> np.ndarray:
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

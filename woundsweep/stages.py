"""The wound model's forms, boundary sets and stages (paper: "Modeling primary intention in six
stages").

Physics (units mm, kPa, mN):

1. Pre-tension (eqs. 12-14): u_x = (TSF - 1)(x - x_c) on the x faces, u_y = (TSF - 1)(y - y_c)
   on the y faces (normal components only; the tangential ones are traction-free), and on the
   deep face u = ((TSF - 1)(x - x_c), (TSF - 1)(y - y_c), 0). The paper writes ``u_x = TSF * a``;
   the tension scaling factor is a stretch, so the displacement is (TSF - 1) times the
   coordinate. We stretch about the wound's mid-plane x_c and the patch centre y_c, which
   differs from stretching about the origin only by a rigid translation (same stresses) and
   keeps the wound's mirror plane fixed, so both flanks close symmetrically in stage 2.
2. Lateral Dirichlet -> traction of healthy skin (eqs. 15-16, Assumption 4). Each layer's
   traction is T = P N with P the first Piola-Kirchhoff stress of the homogeneous
   pre-stretched state F = diag(TSF, TSF, lambda3) of that layer's material (lambda3 makes
   the top traction-free; `materials.homogeneous_state`), N the reference outward normal, so
   shear components appear at oblique orientations. The layer of a lateral facet is the tag
   of the cell it bounds (derived facet ids LATERAL_DERMIS / LATERAL_SUBCUTIS). The deep face
   keeps u_z = 0; rigid in-plane motion is removed by three point constraints on the deep face
   (u_x, u_y at the node nearest (x_c, y_c); u_x at the node nearest (x_c, y_c + L_y/2)) held
   at their stage-1 values; their reactions are recorded and vanish for balanced loads.
   Primary intention (eq. 18): u_x = x_c - x on the wound-surface nodes of the closure zone
   (|y - y_c| <= y_fraction * L_y and z >= -depth_fraction * d), so both flanks meet on x = x_c.
3. Closure by traction (eq. 19, Assumption 3): the zone's Dirichlet condition is replaced by a
   traction along x toward the mid-plane, of uniform magnitude tau per DEFORMED area, i.e.
   transformed with Nanson's formula (eq. 17): f dA = tau sign |J F^-T N| dA. tau is the total
   stage-2 reaction force of the closure condition on both flanks divided by the deformed
   zone area at the end of stage 2, so the stage-3 closing force equals the stage-2 one while
   its distribution becomes uniform. The remaining gap is reported as ``closure_gap_mm``.
4-6. Contact (paper: "material depth contact model"): the loads of stage 3 stay, with the
   closure traction frozen as a dead load: tau times the Nanson factor of the stage-2 state
   (the state stage 4 starts from, at which tau was sized), so the closing force on each
   flank is the stage-2 one at every state and the stage has a potential energy (stored
   energy + penalty energy - work of the dead loads). Newton then accepts updates that lower
   that energy and leaves unstable equilibria (`woundsweep.newton`); with the follower load
   the tangent was non-symmetric and Newton stalled on about half of the 45-degree jobs
   (docs/design.md, "Contact models", session 10). The penalty contact of the wound flanks (`woundsweep.contact`, two-pass surface-to-surface,
   pressure k_V * depth / h) is switched on with k_V = 1, 5, 100 GPa (sweep key
   ``stages.contact_penalty_GPa``). Stage 4 solves the stage-3 loads with contact starting
   from the stage-2 state, not the stage-3 one: without contact, stage 3's uniform traction
   can drive the flanks through each other by several elements (demo job 0: 3 h deep), where
   no penalty method can tell which facets should touch, while the Dirichlet-closed stage-2
   flanks touch on the mid-plane. The stage ramps the closure from Dirichlet to traction and
   the penalty geometrically from ``CONTACT_START_kPa`` to k_V together; stages 5 and 6 start
   from the previous stage and ramp the penalty from its value. The contact term enters the
   residual and its exact tangent the Jacobian (`FlankContact`; with the sweep setting
   ``stages.contact_model: depth`` the material-depth model `woundsweep.depth.DepthContact`,
   which locates the contact points in the deformed cells of the other side). The force scale of the
   convergence test is the internal force without contact, so large penalty forces of an
   intermediate state cannot loosen the tolerance.

Every change between stages is ramped (load continuation, `newton.continuation`): Dirichlet
values move linearly from their current to their target values, and the out-of-balance force
of the starting state under the new stage's loads is released linearly
(R(u) - (1 - s) R(u_start) = 0 at the free dofs), so s = 0 is exactly the previous state.

All material parameters, tractions and the closure magnitude are ``fem.Constant``s, so the
forms compile once per machine and quadrature degree.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import dolfinx.fem
import numpy as np
import scipy.sparse
import ufl
from petsc4py import PETSc

from . import compat
from .contact import GPA_TO_KPA, FlankContact, owning_cells, split_wound_flanks
from .depth import WOUND_OPTIONS, DepthContact
from .materials import (
    FLYNN_SKIN_TYPES,
    Fung,
    HomogeneousState,
    Material,
    MooneyRivlin,
    homogeneous_state,
    von_mises,
)
from .newton import (
    CONVERGED,
    ContinuationResult,
    LoadState,
    NewtonSettings,
    NewtonSolver,
    continuation,
)
from .stability import lowest_eigenvalues

__all__ = [
    "BOTTOM",
    "DERMIS",
    "IMPLEMENTED_STAGES",
    "LATERAL_DERMIS",
    "LATERAL_SUBCUTIS",
    "STAGE_NAMES",
    "SUBCUTIS",
    "TOP",
    "WOUND",
    "X_MAX",
    "X_MIN",
    "Y_MAX",
    "Y_MIN",
    "ZONE_LEFT",
    "ZONE_RIGHT",
    "ClosureZone",
    "JobMaterials",
    "StageOutcome",
    "WoundModel",
]

# Cell and facet tags of the mesh contract (docs/design.md).
DERMIS, SUBCUTIS = 1, 2
X_MIN, X_MAX, Y_MIN, Y_MAX, BOTTOM, TOP, WOUND = 11, 12, 13, 14, 15, 16, 17
# Facet ids derived by the solver for its integrals (internal, not part of the contract).
LATERAL_DERMIS, LATERAL_SUBCUTIS, ZONE_LEFT, ZONE_RIGHT = 101, 102, 103, 104

STAGE_NAMES = {
    1: "pre-tension (Dirichlet lateral)",
    2: "lateral traction + Dirichlet closure",
    3: "lateral traction + closure traction",
    4: "contact k_V = 1 GPa",
    5: "contact k_V = 5 GPa",
    6: "contact k_V = 100 GPa",
}
IMPLEMENTED_STAGES = (1, 2, 3, 4, 5, 6)


@dataclasses.dataclass(frozen=True)
class JobMaterials:
    """The materials of one job: dermis (Fung at the job's orientation), subcutis, TSF."""

    dermis: Fung
    subcutis: MooneyRivlin
    tsf: float

    @classmethod
    def table2(cls, skin_type: str, orientation_deg: float) -> JobMaterials:
        """The paper's Table 2 values for ``skin_type`` (normal / stiff / soft)."""
        return cls(
            Fung.table2(skin_type, orientation_deg),
            MooneyRivlin.subcutis(),
            float(FLYNN_SKIN_TYPES[skin_type]["tsf"]),
        )

    @classmethod
    def from_sweep(
        cls, materials: Mapping[str, Any], skin_type: str, orientation_deg: float
    ) -> JobMaterials:
        """From a sweep's ``materials`` section (keys as in `woundsweep.grid.DEFAULTS`)."""
        entry = materials["skin_types"][skin_type]
        return cls(
            Fung.from_table(entry, orientation_deg),
            MooneyRivlin.from_table(materials["subcutis"]),
            float(entry["tsf"]),
        )


@dataclasses.dataclass(frozen=True)
class ClosureZone:
    """Where primary intention acts: the middle ``y_fraction`` of the wound length (|y - y_c| <=
    y_fraction * L_y, L_y the patch half-length) and the upper ``depth_fraction`` of its depth."""

    y_fraction: float = 1.0 / 3.0
    depth_fraction: float = 0.5

    @classmethod
    def from_sweep(cls, stages: Mapping[str, Any] | None) -> ClosureZone:
        zone = (stages or {}).get("closure_zone", {})
        return cls(
            float(zone.get("y_fraction", cls.y_fraction)),
            float(zone.get("depth_fraction", cls.depth_fraction)),
        )


class StageOutcome(NamedTuple):
    """What a stage produced (arrays in mesh order; `WoundModel` maps them to input order)."""

    stage: int
    solve: ContinuationResult
    time_s: float
    diagnostics: dict[str, float]


def _constant(mesh: Any, value: Any) -> dolfinx.fem.Constant:
    return dolfinx.fem.Constant(mesh, PETSc.ScalarType(0) + np.asarray(value, dtype=float))


def _symbolic(mesh: Any, material: Material) -> tuple[Material, dict[str, Any]]:
    """A copy of ``material`` whose fields are fem.Constants; returns it and the constants."""
    consts = {
        f.name: _constant(mesh, getattr(material, f.name)) for f in dataclasses.fields(material)
    }
    return dataclasses.replace(material, **consts), consts


def _assign(consts: Mapping[str, Any], material: Material) -> None:
    for name, c in consts.items():
        c.value = np.asarray(getattr(material, name), dtype=float)


CONTACT_MODELS = ("depth", "surface")  # woundsweep.depth.DepthContact, contact.FlankContact
# The closure traction in stages 4-6 (module docstring): on the stage-2 area, or on the
# current one (each load increment's state, updated at convergence until it holds).
CLOSURE_LOADS = ("dead", "follower")


class WoundModel:
    """Forms, boundary sets and stage logic for one mesh; materials can be reassigned.

    ``mesh_data`` has the `MeshData` fields ``points``, ``cells``, ``cell_tags``, ``facets``,
    ``facet_tags`` (docs/design.md). The forms compile on construction (JIT cache hits after
    the first time on a machine); ``jit_time_s`` records how long that took.
    """

    CONTACT_START_kPa = 100.0  # stage 4's penalty ramp starts here: a soft-tissue modulus

    def __init__(
        self,
        mesh_data: Any,
        *,
        quadrature_degree: int = 1,
        zone: ClosureZone | None = None,
        settings: NewtonSettings | None = None,
        jit: dict[str, Any] | None = None,
        contact_penalty_GPa: tuple[float, float, float] = (1.0, 5.0, 100.0),
        contact_model: str = "surface",
        closure_load: str = "dead",
    ) -> None:
        if contact_model not in CONTACT_MODELS:
            raise ValueError(
                f"contact_model must be one of {CONTACT_MODELS}, not {contact_model!r}"
            )
        if closure_load not in CLOSURE_LOADS:
            raise ValueError(f"closure_load must be one of {CLOSURE_LOADS}, not {closure_load!r}")
        self.closure_follows = closure_load == "follower"
        self.zone_spec = zone or ClosureZone()
        if len(contact_penalty_GPa) != 3:
            raise ValueError("contact_penalty_GPa needs three values (stages 4, 5, 6)")
        self.contact_penalty_kPa = tuple(float(k) * GPA_TO_KPA for k in contact_penalty_GPa)
        self.settings = settings or NewtonSettings()
        pts = np.asarray(mesh_data.points, dtype=float)
        cells = np.asarray(mesh_data.cells, dtype=np.int64)
        ctags = np.asarray(mesh_data.cell_tags, dtype=np.int32)
        facets = np.asarray(mesh_data.facets, dtype=np.int64)
        ftags = np.asarray(mesh_data.facet_tags, dtype=np.int32)
        self.points, self.cells, self.cell_tags = pts, cells, ctags
        self.mesh, self.cell_mt, self.facet_mt = compat.mesh_from_arrays(
            pts, cells, ctags, facets, ftags
        )
        mesh = self.mesh
        self.V = compat.vector_space(mesh)
        self.u = dolfinx.fem.Function(self.V)
        self._u_vec = compat.petsc_vec(self.u)
        self.node_input = compat.node_input_index(self.V)
        self.cell_input = compat.cell_input_index(mesh)
        n_nodes = len(self.node_input)
        self.input_node = np.full(len(pts), -1, dtype=np.int64)
        self.input_node[self.node_input] = np.arange(n_nodes)
        if np.any(self.input_node < 0):
            raise ValueError("the mesh has points that belong to no cell")
        self.X = pts[self.node_input]  # reference coordinates of the nodes
        self.cell_nodes = compat.cell_dofs(self.V)  # (m, 4) node indices, mesh cell order
        self._prepare_kinematics()
        self._classify(facets, ftags)
        self.contact: FlankContact | DepthContact | None = None
        if self.has_wound and contact_model == "depth":
            side = self.X[self.cell_nodes].mean(axis=1)[:, 0] >= self.x_c
            self.contact = DepthContact(
                self.X, self.cell_nodes, side, self.input_node[facets[ftags == WOUND]],
                max_depth_mm=self.wound_depth, **WOUND_OPTIONS,
            )  # fmt: skip
        elif self.has_wound:
            left, right = split_wound_flanks(
                self.X, self.cell_nodes, self.input_node[facets[ftags == WOUND]], self.x_c
            )
            # Deeper "penetrations" are not overlaps of facing flanks but the far side of the
            # wound; the wound's depth bounds any overlap that closure can produce.
            self.contact = FlankContact(self.X, left, right, max_depth_mm=self.wound_depth)
        self._build_forms(quadrature_degree, jit)
        self.materials: JobMaterials | None = None
        self.homogeneous: dict[int, HomogeneousState] = {}
        self.A = compat.create_matrix(self.a_form)
        self.newton = NewtonSolver(self, self.A, self.settings)
        self.results: dict[int, StageOutcome] = {}
        self.displacements: dict[int, np.ndarray] = {}
        self.tau_kPa = 0.0
        self.closure_force_mN: tuple[float, float] = (0.0, 0.0)

    # -- geometry ---------------------------------------------------------------------------

    def _prepare_kinematics(self) -> None:
        Xc = self.X[self.cell_nodes]  # (m, 4, 3)
        Dm = np.transpose(Xc[:, 1:, :] - Xc[:, :1, :], (0, 2, 1))  # columns = edges
        det = np.linalg.det(Dm)
        self.ref_det = det
        self.volumes = np.abs(det) / 6.0
        self.Dm_inv = np.linalg.inv(Dm)
        self.midpoints = Xc.mean(axis=1)
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        self.bbox = (lo, hi)
        self.ell = float(np.linalg.norm(hi - lo))

    def _grad(self, w: np.ndarray) -> np.ndarray:
        """Cellwise gradient (m, 3, 3) of a P1 vector field given as flat dofs."""
        W = w.reshape(-1, 3)[self.cell_nodes]
        Dw = np.transpose(W[:, 1:, :] - W[:, :1, :], (0, 2, 1))
        return Dw @ self.Dm_inv

    def _classify(self, facets: np.ndarray, ftags: np.ndarray) -> None:
        """Node sets for the boundary conditions and derived facet tags for the integrals."""
        n_pts = len(self.points)

        def nodes_of(mask: np.ndarray) -> np.ndarray:
            return np.unique(self.input_node[np.unique(facets[mask])])

        self.x_face_nodes = nodes_of(np.isin(ftags, (X_MIN, X_MAX)))
        self.y_face_nodes = nodes_of(np.isin(ftags, (Y_MIN, Y_MAX)))
        self.bottom_nodes = nodes_of(ftags == BOTTOM)
        if len(self.bottom_nodes) == 0 or len(self.x_face_nodes) == 0:
            raise ValueError("the mesh has no tagged deep face or x faces")
        lo, hi = self.bbox
        self.x_c = 0.5 * (lo[0] + hi[0])
        self.y_c = 0.5 * (lo[1] + hi[1])
        self.half_length_y = 0.5 * (hi[1] - lo[1])
        self.z_top = float(hi[2])
        tol = 1e-9 * self.ell

        wound_mask = ftags == WOUND
        self.has_wound = bool(wound_mask.any())
        zone_left = zone_right = np.zeros(0, dtype=np.int64)
        self.zone_nodes = np.zeros(0, dtype=np.int64)
        if self.has_wound:
            wound_pts = np.unique(facets[wound_mask])
            wx = self.points[wound_pts, 0]
            # The wound's mirror plane; the patch centre for the symmetric paper geometries.
            self.x_c = 0.5 * (wx.min() + wx.max())
            self.wound_depth = float(self.z_top - self.points[wound_pts, 2].min())
            y_lim = self.zone_spec.y_fraction * self.half_length_y + tol
            z_lim = self.z_top - self.zone_spec.depth_fraction * self.wound_depth - tol
            p = self.points
            in_zone = np.zeros(n_pts, dtype=bool)
            in_zone[wound_pts] = (np.abs(p[wound_pts, 1] - self.y_c) <= y_lim) & (
                p[wound_pts, 2] >= z_lim
            )
            self.zone_nodes = np.unique(self.input_node[np.flatnonzero(in_zone)])
            wf = np.flatnonzero(wound_mask)
            zf = wf[np.all(in_zone[facets[wf]], axis=1)]
            left = self.points[facets[zf]].mean(axis=1)[:, 0] < self.x_c
            zone_left, zone_right = zf[left], zf[~left]
        else:
            self.wound_depth = 0.0
        self.zone_left_facets = facets[zone_left]
        self.zone_right_facets = facets[zone_right]
        self.zone_left_nodes = self.zone_nodes[self.X[self.zone_nodes, 0] < self.x_c]
        self.zone_right_nodes = self.zone_nodes[self.X[self.zone_nodes, 0] >= self.x_c]

        lateral = np.flatnonzero(np.isin(ftags, (X_MIN, X_MAX, Y_MIN, Y_MAX)))
        owner = owning_cells(self.cells, facets[lateral], n_pts)
        layer = np.where(self.cell_tags[owner] == DERMIS, LATERAL_DERMIS, LATERAL_SUBCUTIS)
        p = self.points[facets[lateral]]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        on_xmax = ftags[lateral] == X_MAX
        self.x_max_area = {
            DERMIS: float(area[on_xmax & (layer == LATERAL_DERMIS)].sum()),
            SUBCUTIS: float(area[on_xmax & (layer == LATERAL_SUBCUTIS)].sum()),
        }
        sel = np.concatenate([lateral, zone_left, zone_right])
        vals = np.concatenate(
            [layer, np.full(len(zone_left), ZONE_LEFT), np.full(len(zone_right), ZONE_RIGHT)]
        )
        self.solver_facet_mt = compat.facet_meshtags(self.mesh, facets[sel], vals)

        # Minimal in-plane gauge for stages 2+: nodes of the deep face near its centre line.
        zb = self.X[self.bottom_nodes]

        def nearest(target: tuple[float, float]) -> int:
            d = (zb[:, 0] - target[0]) ** 2 + (zb[:, 1] - target[1]) ** 2
            return int(self.bottom_nodes[np.argmin(d)])

        self.pin_a = nearest((self.x_c, self.y_c))
        self.pin_b = nearest((self.x_c, self.y_c + 0.5 * self.half_length_y))

    # -- forms --------------------------------------------------------------------------------

    def _build_forms(self, degree: int, jit: dict[str, Any] | None) -> None:
        mesh = self.mesh
        u, V = self.u, self.V
        v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
        d = len(u)
        F = ufl.variable(ufl.Identity(d) + ufl.grad(u))
        dermis_sym, self._dermis_c = _symbolic(mesh, Fung.normal())
        sub_sym, self._sub_c = _symbolic(mesh, MooneyRivlin.subcutis())
        self.T_dermis = _constant(mesh, np.zeros((3, 3)))
        self.T_subcutis = _constant(mesh, np.zeros((3, 3)))
        self.tau = _constant(mesh, 0.0)
        md = {"quadrature_degree": int(degree)}
        dx = ufl.Measure("dx", domain=mesh, subdomain_data=self.cell_mt, metadata=md)
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=self.solver_facet_mt, metadata=md)
        N = ufl.FacetNormal(mesh)
        psi_d, psi_s = dermis_sym.strain_energy(F), sub_sym.strain_energy(F)
        P_d = ufl.diff(psi_d, F)
        P_s = ufl.diff(psi_s, F)
        # Nanson (eq. 17): deformed area element per reference area, |J F^-T N|, of the
        # closure's area state follow * u + (1 - follow) * u_area: the current state in
        # stage 3 (a follower load), a fixed one in stages 4-6 (a dead load; module docstring).
        self.follow = _constant(mesh, 1.0)
        self.u_area = dolfinx.fem.Function(V)
        Fa = ufl.Identity(d) + ufl.grad(self.follow * u + (1.0 - self.follow) * self.u_area)
        Ja_N = ufl.det(Fa) * ufl.inv(Fa).T * N
        nanson = ufl.sqrt(ufl.dot(Ja_N, Ja_N))
        R = (
            ufl.inner(P_d, ufl.grad(v)) * dx(DERMIS)
            + ufl.inner(P_s, ufl.grad(v)) * dx(SUBCUTIS)
            - ufl.dot(ufl.dot(self.T_dermis, N), v) * ds(LATERAL_DERMIS)
            - ufl.dot(ufl.dot(self.T_subcutis, N), v) * ds(LATERAL_SUBCUTIS)
            - self.tau * nanson * v[0] * ds(ZONE_LEFT)
            + self.tau * nanson * v[0] * ds(ZONE_RIGHT)
        )
        a = ufl.derivative(R, u, du)
        # The potential whose derivative is R while the closure is a dead load (follow = 0).
        Pi = (
            psi_d * dx(DERMIS)
            + psi_s * dx(SUBCUTIS)
            - ufl.dot(ufl.dot(self.T_dermis, N), u) * ds(LATERAL_DERMIS)
            - ufl.dot(ufl.dot(self.T_subcutis, N), u) * ds(LATERAL_SUBCUTIS)
            - self.tau * nanson * u[0] * ds(ZONE_LEFT)
            + self.tau * nanson * u[0] * ds(ZONE_RIGHT)
        )
        q = ufl.TestFunction(compat.dg0_space(mesh))
        vm = von_mises(P_d, F) * q * dx(DERMIS) + von_mises(P_s, F) * q * dx(SUBCUTIS)
        jit_opts = compat.jit_options() if jit is None else jit
        t0 = time.perf_counter()
        self.R_form = compat.compile_form(R, jit_opts)
        self.a_form = compat.compile_form(a, jit_opts)
        self.vm_form = compat.compile_form(vm, jit_opts)
        self.Pi_form = compat.compile_form(Pi, jit_opts)
        self.jit_time_s = time.perf_counter() - t0
        self.Q = compat.dg0_space(mesh)
        self._vm_vec = compat.create_vector(self.vm_form)
        self._dg0_cell = compat.cell_dofs(self.Q)[:, 0]

    # -- NonlinearProblem protocol (newton.py) -----------------------------------------------

    def solution(self) -> np.ndarray:
        return self.u.x.array

    def _contact_on(self) -> bool:
        return self.contact is not None and self.contact.k_V_kPa > 0.0

    def residual(self, b: PETSc.Vec) -> None:
        compat.assemble_vector(b, self.R_form)
        if self._contact_on():
            self.contact.add_residual(b, self.u.x.array)  # type: ignore[union-attr]

    def energy(self) -> float | None:
        """Total potential (mN mm) at the current state, or None while a load follows the
        deformation (the stage-3 closure traction), when there is none."""
        if float(self.follow.value) != 0.0:
            return None
        e = compat.assemble_scalar(self.Pi_form)
        if self._contact_on():
            e += self.contact.energy(self.u.x.array)  # type: ignore[union-attr]
        return e

    def refresh(self, tol: float) -> bool:
        """Newton's hook at a converged state: re-search a frozen contact pairing (contact.py)
        and move the closure traction's area state to the current one (module docstring);
        True if either moved the forces by more than ``tol`` (mN), so Newton goes on."""
        u = self.u.x.array
        moved = self._contact_on() and self.contact.refresh(u, tol)  # type: ignore[union-attr]
        if self.closure_follows and float(self.follow.value) == 0.0 and not moved:
            r_old = self._residual_array()
            self.u_area.x.array[:] = u
            moved = bool(np.linalg.norm(self._residual_array() - r_old) > tol)
        return moved

    def jacobian(self, A: PETSc.Mat) -> None:
        compat.assemble_matrix(A, self.a_form)
        if self._contact_on():
            self.contact.add_jacobian(A, self.u.x.array)  # type: ignore[union-attr]

    def min_det(self, u: np.ndarray) -> float:
        G = self._grad(u)
        G[:, 0, 0] += 1.0
        G[:, 1, 1] += 1.0
        G[:, 2, 2] += 1.0
        return float(np.linalg.det(G).min())

    def max_strain(self, du: np.ndarray) -> float:
        return float(np.sqrt(np.max(np.sum(self._grad(du) ** 2, axis=(1, 2)), initial=0.0)))

    def length_scale(self) -> float:
        return self.ell

    # -- job parameters -----------------------------------------------------------------------

    def set_materials(self, materials: JobMaterials) -> None:
        """Assign a job's material constants (no recompilation) and reset the state."""
        self.materials = materials
        _assign(self._dermis_c, materials.dermis)
        _assign(self._sub_c, materials.subcutis)
        self.homogeneous = {
            DERMIS: homogeneous_state(materials.dermis, materials.tsf),
            SUBCUTIS: homogeneous_state(materials.subcutis, materials.tsf),
        }
        self.T_dermis.value = np.zeros((3, 3))
        self.T_subcutis.value = np.zeros((3, 3))
        self.tau.value = 0.0
        self.follow.value = 1.0
        self.tau_kPa = 0.0
        self.closure_force_mN = (0.0, 0.0)
        if self.contact is not None:
            self.contact.k_V_kPa = 0.0
        self.u.x.array[:] = 0.0
        self.results.clear()
        self.displacements.clear()

    # -- helpers ------------------------------------------------------------------------------

    @staticmethod
    def _rows(nodes: np.ndarray, comp: int) -> np.ndarray:
        return (3 * np.asarray(nodes, dtype=np.int64) + comp).astype(np.int32)

    def _residual_array(self) -> np.ndarray:
        b = self._u_vec.duplicate()
        self.residual(b)
        return b.getArray(readonly=True).copy()

    def _gauge_rows(self) -> np.ndarray:
        return np.concatenate(
            [
                self._rows(self.bottom_nodes, 2),
                self._rows([self.pin_a], 0),
                self._rows([self.pin_a], 1),
                self._rows([self.pin_b], 0),
            ]
        )

    def _pin_rows(self) -> np.ndarray:
        return np.concatenate(
            [self._rows([self.pin_a], 0), self._rows([self.pin_a], 1), self._rows([self.pin_b], 0)]
        )

    def deformed_zone_area(self, side: str) -> float:
        """Deformed area (mm^2) of the closure-zone facets of one flank (exact for P1)."""
        tri = self.zone_left_facets if side == "left" else self.zone_right_facets
        if len(tri) == 0:
            return 0.0
        x = self.points + self.displacement_input()
        p = x[tri]
        return float(
            0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
        )

    def closure_gap(self) -> float:
        """Widest x-opening between the flanks in the closure zone (mm, deformed; NaN if no zone).

        max over left-flank zone nodes of (x_c - x) plus max over right-flank zone nodes of
        (x - x_c), x the deformed position: 0 when closed, negative when the flanks overlap.
        """
        if len(self.zone_left_nodes) == 0 or len(self.zone_right_nodes) == 0:
            return float("nan")
        ux = self.u.x.array.reshape(-1, 3)[:, 0]
        xl = self.X[self.zone_left_nodes, 0] + ux[self.zone_left_nodes]
        xr = self.X[self.zone_right_nodes, 0] + ux[self.zone_right_nodes]
        return float(np.max(self.x_c - xl) + np.max(xr - self.x_c))

    def displacement_input(self) -> np.ndarray:
        """Displacement (n_points, 3) in input point order."""
        return self.u.x.array.reshape(-1, 3)[self.input_node]

    def von_mises_cells(self) -> np.ndarray:
        """Cellwise von Mises stress (kPa) in mesh cell order (F is constant per P1 cell)."""
        compat.assemble_vector(self._vm_vec, self.vm_form)
        integ = self._vm_vec.getArray(readonly=True)[self._dg0_cell]
        return integ / self.volumes

    def cell_min_det(self) -> float:
        return self.min_det(self.u.x.array)

    # -- stages -------------------------------------------------------------------------------

    def run_stage(self, stage: int) -> StageOutcome:
        """Run one stage from the current state (the previous stage's result)."""
        if self.materials is None:
            raise RuntimeError("set_materials() first")
        if stage not in IMPLEMENTED_STAGES:
            raise ValueError(f"stage {stage} is not implemented (available: {IMPLEMENTED_STAGES})")
        if stage > 1 and stage - 1 not in self.results:
            raise RuntimeError(f"stage {stage} needs stage {stage - 1} first")
        t0 = time.perf_counter()
        if stage <= 3:
            res, diag = {1: self._stage1, 2: self._stage2, 3: self._stage3}[stage]()
        else:
            res, diag = self._stage_contact(stage)
        out = StageOutcome(stage, res, time.perf_counter() - t0, diag)
        self.results[stage] = out
        self.displacements[stage] = self.u.x.array.copy()
        return out

    def _ramp(
        self, rows: np.ndarray, target: np.ndarray, offset: np.ndarray | None
    ) -> ContinuationResult:
        u = self.u.x.array
        start = u[rows].copy()
        free_offset = None
        if offset is not None:
            free_offset = offset.copy()
            free_offset[rows] = 0.0

        def load(s: float) -> LoadState:
            off = None if free_offset is None else (1.0 - s) * free_offset
            return LoadState(start + s * (target - start), off)

        scale = float(np.linalg.norm(self._internal_force()))
        return continuation(self.newton, rows, load, force_scale=scale)

    def _internal_force(self) -> np.ndarray:
        """Nodal internal forces at the current state (external loads and contact switched off)."""
        saved = (self.T_dermis.value.copy(), self.T_subcutis.value.copy(), float(self.tau.value))
        k_V = self.contact.k_V_kPa if self.contact is not None else 0.0
        self.T_dermis.value[:] = 0.0
        self.T_subcutis.value[:] = 0.0
        self.tau.value = 0.0
        if self.contact is not None:
            self.contact.k_V_kPa = 0.0
        r = self._residual_array()
        self.T_dermis.value[:] = saved[0]
        self.T_subcutis.value[:] = saved[1]
        self.tau.value = saved[2]
        if self.contact is not None:
            self.contact.k_V_kPa = k_V
        return r

    def _stage1(self) -> tuple[ContinuationResult, dict[str, float]]:
        tsf = self.materials.tsf  # type: ignore[union-attr]
        X = self.X
        rows, target = [], []
        for nodes, comp, centre in (
            (self.x_face_nodes, 0, self.x_c),
            (self.y_face_nodes, 1, self.y_c),
            (self.bottom_nodes, 0, self.x_c),
            (self.bottom_nodes, 1, self.y_c),
        ):
            rows.append(self._rows(nodes, comp))
            target.append((tsf - 1.0) * (X[nodes, comp] - centre))
        rows.append(self._rows(self.bottom_nodes, 2))
        target.append(np.zeros(len(self.bottom_nodes)))
        r = np.concatenate(rows)
        t = np.concatenate(target)
        r, first = np.unique(r, return_index=True)
        t = t[first]
        self.T_dermis.value[:] = 0.0
        self.T_subcutis.value[:] = 0.0
        self.tau.value = 0.0
        res = self._ramp(r, t, None)
        return res, {"closure_gap_mm": self.closure_gap()}

    def _stage2(self) -> tuple[ContinuationResult, dict[str, float]]:
        self.T_dermis.value[:] = self.homogeneous[DERMIS].P
        self.T_subcutis.value[:] = self.homogeneous[SUBCUTIS].P
        self.tau.value = 0.0
        offset = self._residual_array()
        gauge = self._gauge_rows()
        u = self.u.x.array
        zone_rows = self._rows(self.zone_nodes, 0)
        rows = np.concatenate([gauge, zone_rows])
        target = np.concatenate([u[gauge], self.x_c - self.X[self.zone_nodes, 0]])
        res = self._ramp(rows, target, offset)
        r = self._residual_array()
        f_left = float(r[self._rows(self.zone_left_nodes, 0)].sum())
        f_right = float(r[self._rows(self.zone_right_nodes, 0)].sum())
        self.closure_force_mN = (f_left, f_right)
        diag = {
            "closure_gap_mm": self.closure_gap(),
            "closure_force_left_mN": f_left,
            "closure_force_right_mN": f_right,
            "pin_reaction_max_mN": float(np.max(np.abs(r[self._pin_rows()]))),
            "lateral_force_mN": self._lateral_force(),
        }
        return res, diag

    def _stage3(self) -> tuple[ContinuationResult, dict[str, float]]:
        f_left, f_right = self.closure_force_mN
        area = self.deformed_zone_area("left") + self.deformed_zone_area("right")
        # Left flank is pulled toward +x (f_left > 0), right toward -x (f_right < 0).
        self.tau_kPa = (f_left - f_right) / area if area > 0 else 0.0
        self.tau.value = self.tau_kPa
        self.follow.value = 1.0
        offset = self._residual_array()
        rows = self._gauge_rows()
        u = self.u.x.array
        res = self._ramp(rows, u[rows].copy(), offset)
        r = self._residual_array()
        diag = {
            "closure_gap_mm": self.closure_gap(),
            "closure_traction_kPa": self.tau_kPa,
            "pin_reaction_max_mN": float(np.max(np.abs(r[self._pin_rows()]))),
        }
        return res, diag

    def _stage_contact(self, stage: int) -> tuple[ContinuationResult, dict[str, float]]:
        """Stages 4-6: the stage-3 loads plus flank contact at this stage's penalty.

        Stage 4 restarts from the stage-2 state (module docstring). The penalty is ramped
        geometrically from the previous stage's (stage 4: from ``CONTACT_START_kPa``) to this
        stage's value, so an overlap left by the closure is pushed out gradually instead of by
        a force of order k_V at once.
        """
        rows = self._gauge_rows()
        u = self.u.x.array
        diag: dict[str, float] = {}
        c = self.contact
        if c is None:  # no wound: nothing can touch; the stage re-solves the stage-3 loads
            return self._ramp(rows, u[rows].copy(), self._residual_array()), {}
        k_from, k_to, load, scale = self._contact_load(stage, rows)
        # The residual of a penetrating start holds penalty forces far above the physical
        # ones; they must not set the convergence tolerance.
        self.newton.scale_from_residual = False
        settings = self.newton.settings
        self.newton.settings = dataclasses.replace(
            settings,
            rtol=max(settings.rtol, settings.contact_rtol),
            stol=max(settings.stol, settings.contact_stol),
            residual_growth=(
                settings.contact_residual_growth
                if isinstance(c, FlankContact)
                else settings.residual_growth
            ),
            energy_merit=isinstance(c, FlankContact),
        )
        try:
            decades = np.log10(k_to / k_from)
            res = continuation(
                self.newton, rows, load, scale, first_step=min(1.0, 0.5 / max(decades, 1e-9))
            )
        finally:
            self.newton.scale_from_residual = True
            self.newton.settings = settings
            c.k_V_kPa = k_to
            c.unfreeze()
        if res.status != CONVERGED:
            # Stalled at a stable state, or at a limit point of the path? (stability.py)
            k_last = k_from ** (1.0 - res.load_reached) * k_to**res.load_reached
            diag.update(self._stability(rows, k_last))
        r = self._residual_array()
        diag["closure_gap_mm"] = self.closure_gap()
        diag["pin_reaction_max_mN"] = float(np.max(np.abs(r[self._pin_rows()])))
        diag["contact_penalty_kPa"] = c.k_V_kPa
        detect, assemble, searches = c.detect_time_s, c.assembly_time_s, c.searches
        summ = c.summary(u)
        diag.update(
            {
                "n_penetrating": summ.n_penetrating,
                "max_penetration_mm": summ.max_penetration_mm,
                "max_penetration_rel": summ.max_penetration_rel,
                "contact_force_mN": summ.contact_force_mN,
                "contact_deep_points": summ.n_deep,
                "contact_detect_time_s": detect,
                "contact_assembly_time_s": assemble,
                "contact_searches": searches,
            }
        )
        return res, diag

    def _contact_load(
        self, stage: int, rows: np.ndarray
    ) -> tuple[float, float, Callable[[float], LoadState], float]:
        """Set up contact stage ``stage`` at the current state: (k_from, k_to, the load of the
        continuation parameter s, the force scale). At s = 0 the state is in equilibrium."""
        c = self.contact
        assert c is not None
        u = self.u.x.array
        k_to = self.contact_penalty_kPa[stage - 4]
        k_from = self.CONTACT_START_kPa if stage == 4 else self.contact_penalty_kPa[stage - 5]
        k_from = min(k_from, k_to)
        if stage == 4:
            u[:] = self.displacements[2]
            # The closure traction becomes a dead load on the stage-2 area (module docstring).
            self.u_area.x.array[:] = self.displacements[2]
            self.follow.value = 0.0
        c.reset_timers()
        # Out-of-balance force released over the stage: stage 4, that of the stage-2 state
        # under the stage-3 loads (contact off); stages 5 and 6 start from an equilibrium
        # with contact at k_from, so only its convergence residual is left to release.
        c.k_V_kPa = 0.0 if stage == 4 else k_from
        if stage > 4:
            c.freeze(u)
        offset = self._residual_array()
        offset[rows] = 0.0
        values = u[rows].copy()
        scale = float(np.linalg.norm(self._internal_force()))

        def load(s: float) -> LoadState:
            c.k_V_kPa = k_from ** (1.0 - s) * k_to**s
            c.freeze(u)  # the pairing of the last converged state; Newton refreshes it
            if self.closure_follows:
                self.u_area.x.array[:] = u  # likewise the closure traction's area
            return LoadState(values, (1.0 - s) * offset)

        return k_from, k_to, load, scale

    def _stability(self, rows: np.ndarray, k_V_kPa: float) -> dict[str, float]:
        """Lowest eigenvalue nearest zero (mN/mm) of the free-dof tangent at the current state
        with penalty ``k_V_kPa`` (NaN if it cannot be computed). With the dead closure load
        every load is dead, so the tangent is the Hessian of the total potential and its sign
        decides the stability of that equilibrium (with ``closure_load="follower"`` it is the
        Hessian with the traction's area state held, its load stiffness left out)."""
        c = self.contact
        assert c is not None
        u = self.u.x.array
        saved = c.k_V_kPa
        c.k_V_kPa = k_V_kPa
        c.freeze(u)
        free = np.ones(self.A.getSize()[0], dtype=bool)
        free[rows] = False
        try:
            self.jacobian(self.A)
            ai, aj, av = self.A.getValuesCSR()
            K = scipy.sparse.csr_matrix((av, aj, ai), shape=self.A.getSize())
            try:
                eig = float(lowest_eigenvalues(K, free)[0])
            except ArithmeticError:
                eig = float("nan")
        finally:
            c.k_V_kPa = saved
            c.unfreeze()
        return {"stability_min_eig_mN_per_mm": eig, "stability_penalty_kPa": k_V_kPa}

    def _lateral_force(self) -> float:
        """x-force (mN) of the healthy-skin traction on the x_max face: the load scale."""
        P = self.homogeneous
        return float(
            P[DERMIS].P[0, 0] * self.x_max_area[DERMIS]
            + P[SUBCUTIS].P[0, 0] * self.x_max_area[SUBCUTIS]
        )

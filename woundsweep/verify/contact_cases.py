"""Contact with known answers, through the production assembly (`WoundProblem` with a
`FlankContact`, Newton's contact policy), on two disjoint bodies.

- Flat patch: two unit blocks of the normal dermis (Langer line along x) touching on x = 0,
  the left held at x = -1, symmetry planes y = 0 and z = 0, a dead pressure p = 10 kPa on the
  right's x = +1 face. Frictionless contact of matching faces carries p uniformly: the contact
  force is p A, the overlap at the nodes off the faces' edges p h / k_V (h the node's contact
  size), so it scales with 1 / k_V. The penalty is raised in half decades from 1 MPa to
  100 GPa, each solve from the last: the total potential at equilibrium must not decrease
  along the ramp (d Pi* / d k_V = E_c / k_V >= 0 at a minimum).
- Curved master: a shrink fit. A tube c < r < a + delta inside a tube a < r < b (a quarter
  of each, plane strain: u_z = 0 on both ends), the overlap delta pushed out by the contact
  as the penalty ramps from 1 kPa to 100 GPa; the interface pressure against Lame's
  small-strain answer for two tubes of the linearised material (Mooney-Rivlin with C20 = 0:
  shear modulus 2 C10, bulk modulus K), measured as the contact force on the inner tube over
  its projected area a H.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any, NamedTuple

import numpy as np

from ..config.solver import NewtonSettings, SolverSettings
from ..contact import GPA_TO_KPA, FlankContact, orient_outward
from ..core.schema import BOTTOM, DERMIS, SUBCUTIS, TOP, X_MAX, X_MIN, Y_MIN, StageStatus
from ..physics.domain import WoundDomain, dof_rows
from ..physics.forms import WoundForms
from ..physics.materials import Fung, JobMaterials, MooneyRivlin
from ..physics.problem import WoundProblem
from ..solver.continuation import LoadState, continuation
from ..solver.dirichlet import Dirichlet
from ..solver.newton import NewtonSolver, Policy
from .bvp import VerificationError
from .meshes import MeshData, boundary_facets, grid_tets, join, slab

__all__ = ["FlatPatch", "ShrinkFit", "flat_patch", "lame_pressure", "shrink_fit"]

PRESSURE_KPA = 10.0
N_BOX = 3
RAMP_KPA = tuple(10.0 ** (3.0 + 0.5 * j) for j in range(11))  # 1 MPa .. 100 GPa
CHECKED_GPA = (1.0, 5.0, 100.0)


class _Bodies:
    """Two disjoint bodies on the production forms and problem, touching on ``walls``
    (two lists of boundary triangles in input numbering, one per body)."""

    def __init__(self, mesh: MeshData, walls: tuple[np.ndarray, np.ndarray], degree: int,
                 materials: JobMaterials, rtol: float = 1e-9) -> None:  # fmt: skip
        self.domain = d = WoundDomain(mesh, None, degree)
        settings = SolverSettings(element_degree=degree)
        self.forms = WoundForms(d, settings.form_quadrature_degree)
        self.forms.set_materials(materials)
        sides = [
            d.element.sub_triangles(orient_outward(d.X, d.cell_vertices, d.input_node[w]))
            for w in walls
        ]
        self.contact = FlankContact(d.X, sides[0], sides[1])
        self.problem = WoundProblem(d, self.forms, self.contact)
        self.newton = NewtonSolver(self.problem, self.problem.A, NewtonSettings(rtol=rtol))
        self.policy = Policy.contact(self.newton.settings)

    @property
    def u(self) -> np.ndarray:
        return self.forms.u.x.array

    def rows(self, comp: int, where: np.ndarray) -> np.ndarray:
        return dof_rows(np.flatnonzero(where), comp)

    def solve_at(self, held: Dirichlet, k_kPa: float, scale: float) -> None:
        self.contact.k_V_kPa = k_kPa
        res = self.newton.solve(held, None, scale, self.policy)
        if res.status != StageStatus.CONVERGED:
            raise VerificationError(f"contact at k_V = {k_kPa:.3g} kPa: {res.status}")


def _walls(mesh: MeshData, first_of_second: int, on_wall: Any) -> tuple[np.ndarray, np.ndarray]:
    f = boundary_facets(mesh.cells)
    hit = on_wall(mesh.points[f].mean(axis=1))
    second = np.all(f >= first_of_second, axis=1)
    return f[hit & ~second], f[hit & second]


class FlatPatch(NamedTuple):
    """The flat patch at the checked penalties and the energy along the ramp."""

    force_error: float  # max over CHECKED_GPA of |contact force - p A| / (p A)
    overlap_error: float  # max |overlap k_V / (p h) - 1| at the nodes off the faces' edges
    penetration_slope: float  # d log(max overlap) / d log k_V over CHECKED_GPA
    energy_drop: float  # largest decrease of Pi* between ramp steps, over |Pi*|
    energies: list[float]
    penalties_kPa: list[float]
    time_s: float


@functools.cache
def flat_patch(degree: int = 1) -> FlatPatch:
    """Solve the flat patch (module docstring)."""
    t0 = time.perf_counter()
    s = np.linspace(0.0, 1.0, N_BOX + 1)
    left = slab(s - 1.0, s, s, lambda m: np.full(len(m), DERMIS))
    right = slab(s, s, s, lambda m: np.full(len(m), DERMIS))

    def retag(c: np.ndarray, tags: np.ndarray) -> np.ndarray:
        out = np.where(np.abs(c[:, 0]) < 1e-9, 0, tags)
        out[np.abs(c[:, 0] + 1.0) < 1e-9] = X_MIN
        out[np.abs(c[:, 0] - 1.0) < 1e-9] = X_MAX
        return out

    mesh = join([left, right], retag)
    walls = _walls(mesh, len(left.points), lambda c: np.abs(c[:, 0]) < 1e-9)
    dermis = dataclasses.replace(Fung.normal(0.0), a1=np.array([1.0, 0.0, 0.0]))
    b = _Bodies(mesh, walls, degree, JobMaterials(dermis, MooneyRivlin.subcutis(), 1.0))
    X = b.domain.X
    held = Dirichlet(np.concatenate([
        b.rows(0, np.abs(X[:, 0] + 1.0) < 1e-9), b.rows(1, np.abs(X[:, 1]) < 1e-9),
        b.rows(2, np.abs(X[:, 2]) < 1e-9)]))  # fmt: skip
    held = Dirichlet(np.sort(held.rows), np.zeros(len(held.rows)))
    # The pressure as the lateral traction P N of P = diag(-p, 0, 0), kept as a dead nodal load.
    b.forms.set_loads(np.diag([-PRESSURE_KPA, 0.0, 0.0]), np.zeros((3, 3)))
    load = -b.problem.residual_array()
    b.forms.set_loads(np.zeros((3, 3)), np.zeros((3, 3)))
    b.problem.closure_load = load
    scale = float(np.linalg.norm(load))
    b.contact.k_V_kPa = RAMP_KPA[0]
    res = continuation(b.newton, lambda s_: LoadState(held, -(1.0 - s_) * load), scale, 1.0,
                       b.policy)  # fmt: skip
    if res.status != StageStatus.CONVERGED:
        raise VerificationError(f"flat patch, loading: {res.status}")
    penalties = sorted({*RAMP_KPA, *(k * GPA_TO_KPA for k in CHECKED_GPA)})
    energies, force_err, overlap_err, pen = [], 0.0, 0.0, {}
    nodes = np.concatenate([ps.nodes for ps in b.contact.passes])
    size = np.concatenate([ps.size_mm for ps in b.contact.passes])
    yz = X[nodes, 1:]
    inside = np.all((yz > 1e-9) & (yz < 1.0 - 1e-9), axis=1)
    for k in penalties:
        b.solve_at(held, k, scale)
        energy = b.problem.energy()
        energies.append(float(energy if energy is not None else math.nan))
        if any(math.isclose(k, g * GPA_TO_KPA) for g in CHECKED_GPA):
            summ = b.contact.summary(b.u)
            force_err = max(force_err, abs(summ.contact_force_mN - PRESSURE_KPA) / PRESSURE_KPA)
            depth = -b.contact.gaps(b.u)
            ratio = depth[inside] * k / (PRESSURE_KPA * size[inside])
            overlap_err = max(overlap_err, float(np.abs(ratio - 1.0).max()))
            pen[k] = summ.max_penetration_mm
    ks = sorted(pen)
    slope = float(np.polyfit(np.log(ks), np.log([pen[k] for k in ks]), 1)[0])
    e = np.asarray(energies)
    drop = float(max(0.0, -np.diff(e).min()) / np.abs(e).max())
    return FlatPatch(force_err, overlap_err, slope, drop, energies, penalties,
                     time.perf_counter() - t0)  # fmt: skip


# -- the shrink fit -------------------------------------------------------------------------

INNER, RADIUS, OUTER = 0.5, 1.0, 2.0  # c, a, b (mm)
OVERLAP = 0.01  # delta (mm)
HEIGHT = 0.25  # H (mm)
C10, K_FIT = 50.0, 200.0  # kPa: shear modulus 100, Poisson's ratio 0.29


def lame_pressure(mu: float = 2 * C10, K: float = K_FIT) -> float:
    """The interface pressure (kPa) of the shrink fit in plane-strain linear elasticity:
    u = A r + B / r in each tube, sigma_rr = 2 (lambda + mu) A - 2 mu B / r^2, free inner
    and outer surfaces, sigma_rr = -p at the interface, u_outer(a) - u_inner(a) = delta."""
    lam = K - 2.0 * mu / 3.0

    def u_at_a(r_in: float, r_out: float, p_in: float, p_out: float) -> float:
        M = np.array([[2 * (lam + mu), -2 * mu / r_in**2], [2 * (lam + mu), -2 * mu / r_out**2]])
        A, B = np.linalg.solve(M, [-p_in, -p_out])
        return float(A * RADIUS + B / RADIUS)

    du_outer = u_at_a(RADIUS, OUTER, 1.0, 0.0)  # per unit pressure
    du_inner = u_at_a(INNER, RADIUS, 0.0, 1.0)
    return OVERLAP / (du_outer - du_inner)


def _tube(r0: float, r1: float, n_r: int, n_t: int) -> MeshData:
    """A quarter tube r0 < r < r1, 0 < theta < pi/2, 0 < z < HEIGHT (subcutis)."""
    pts, cells = grid_tets(np.linspace(r0, r1, n_r + 1), np.linspace(0.0, math.pi / 2, n_t + 1),
                           np.linspace(0.0, HEIGHT, 2))  # fmt: skip
    r, t = pts[:, 0], pts[:, 1]
    xyz = np.c_[r * np.cos(t), r * np.sin(t), pts[:, 2]]
    xyz[np.abs(t - math.pi / 2) < 1e-12, 0] = 0.0
    f = boundary_facets(cells)
    return MeshData(xyz, cells, np.full(len(cells), SUBCUTIS, dtype=np.int32), f,
                    np.zeros(len(f), dtype=np.int32), {})  # fmt: skip


class ShrinkFit(NamedTuple):
    pressure_kPa: float
    expected_kPa: float
    energy_drop: float
    dofs: int
    time_s: float


@functools.cache
def shrink_fit(degree: int = 2, n_theta: int = 16, n_r: int = 4) -> ShrinkFit:
    """Solve the shrink fit (module docstring)."""
    t0 = time.perf_counter()
    inner = _tube(INNER, RADIUS + OVERLAP, n_r, n_theta)
    outer = _tube(RADIUS, OUTER, n_r, n_theta)

    def retag(c: np.ndarray, tags: np.ndarray) -> np.ndarray:
        out = np.zeros(len(c), dtype=np.int32)
        out[np.abs(c[:, 0]) < 1e-9] = X_MIN
        out[np.abs(c[:, 1]) < 1e-9] = Y_MIN
        out[np.abs(c[:, 2]) < 1e-9] = BOTTOM
        out[np.abs(c[:, 2] - HEIGHT) < 1e-9] = TOP
        return out

    mesh = join([inner, outer], retag)
    n_in = len(inner.points)
    r = np.hypot(mesh.points[:, 0], mesh.points[:, 1])
    f = boundary_facets(mesh.cells)
    rf = r[f]
    first = np.all(f < n_in, axis=1)
    walls = (f[first & np.all(np.abs(rf - RADIUS - OVERLAP) < 1e-9, axis=1)],
             f[~first & np.all(np.abs(rf - RADIUS) < 1e-9, axis=1)])  # fmt: skip
    sub = MooneyRivlin(C10, 0.0, K_FIT)
    b = _Bodies(mesh, walls, degree, JobMaterials(Fung.normal(0.0), sub, 1.0), rtol=1e-6)
    X = b.domain.X
    held = np.concatenate([
        b.rows(0, np.abs(X[:, 0]) < 1e-9), b.rows(1, np.abs(X[:, 1]) < 1e-9),
        b.rows(2, (np.abs(X[:, 2]) < 1e-9) | (np.abs(X[:, 2] - HEIGHT) < 1e-9))])  # fmt: skip
    bc = Dirichlet(np.unique(held), np.zeros(len(np.unique(held))))
    scale = lame_pressure() * RADIUS * HEIGHT  # mN: the force scale of the fit
    energies = []
    for j in range(17):  # 1 kPa .. 100 GPa in half decades
        b.solve_at(bc, 10.0 ** (0.5 * j), scale)
        energies.append(float(b.problem.energy() or 0.0))
    f_c = b.contact.force_vector(b.u).reshape(-1, 3)
    in_inner = np.zeros(len(X), dtype=bool)
    in_inner[b.domain.input_node[:n_in]] = True
    # P2's edge nodes belong to the body of their cell
    cells_inner = b.domain.cell_input < len(inner.cells)
    in_inner[np.unique(b.domain.cell_nodes[cells_inner])] = True
    force_x = float(-f_c[in_inner, 0].sum())
    e = np.asarray(energies)
    drop = float(max(0.0, -np.diff(e).min()) / np.abs(e).max())
    return ShrinkFit(abs(force_x) / (RADIUS * HEIGHT), lame_pressure(), drop, len(b.u),
                     time.perf_counter() - t0)  # fmt: skip

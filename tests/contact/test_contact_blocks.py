"""Known-answer contact problem: a block pressed against its mirror image.

Two unit blocks with disjoint nodes touch on the plane x = 0: L = [-1, 0] x [0, 1]^2 and
R = [0, 1] x [0, 1]^2 (n^3 grid boxes of six tets each, so the two triangulations of x = 0
coincide). L is held at x = -1 (u_x = 0); y = 0 and z = 0 are symmetry planes of both blocks
(u_y = 0, u_z = 0); R carries a dead-load pressure p on x = +1 (reference traction -p e_x) and
is held in x only by the contact. Frictionless contact of matching surfaces transmits the
pressure uniformly, so both blocks are in the same homogeneous uniaxial state
F = diag(lx, lt, lt), P_xx = -p, P_yy = P_zz = 0 (P1 represents it exactly), and

- the total contact force is the applied load p A (A = 1 mm^2): global equilibrium of R;
- the overlap d is uniform with p = k_V d / h (woundsweep.contact: pressure per reference
  area k_V (-g) / h, half of it carried by each pass; the lumped nodal areas are the
  consistent loads of a uniform pressure on P1 facets), h the size of a contact facet, so
  d = p h / k_V shrinks like 1 / k_V across the stages' k_V = 1, 5, 100 GPa.

Material: the paper's normal dermis (Fung, stiff axis along x); p = 10 kPa compresses both
blocks by about 24 %. The penalties are applied one after the other from the previous state,
as in stages 4-6. A second, non-matching case (R has (n + 1)^2 grid boxes across x = 0) checks
the load balance and the 1 / k_V scaling where the overlap is not uniform.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any, NamedTuple

import numpy as np
import pytest
from box_mesh import boundary_facets, box_tets

from woundsweep.contact import (
    GPA_TO_KPA,
    ContactMultipliers,
    ContactSummary,
    FlankContact,
    orient_outward,
)
from woundsweep.physics.assembly import add_csr, add_vector
from woundsweep.physics.materials import Fung, first_piola

pytestmark = pytest.mark.fem

N_BOX = 3  # grid boxes per block edge
PRESSURE_KPA = 10.0
AREA_MM2 = 1.0
K_V_GPA = (1.0, 5.0, 100.0)
LOAD = 1  # facet tag of R's x = +1 face (local to this test)


def uniaxial_state(material: Fung, p: float) -> tuple[float, float]:
    """Stretches (l_x, l_t) of the homogeneous state P_xx = -p, P_yy = P_zz = 0 (a1 = e_x, so
    y and z are equivalent)."""
    from scipy.optimize import fsolve

    def eq(v: np.ndarray) -> list[float]:
        P = first_piola(material, np.diag([v[0], v[1], v[1]]))
        return [P[0, 0] + p, P[1, 1]]

    sol, info, ok, msg = fsolve(eq, [0.9, 1.05], xtol=1e-14, full_output=True)
    assert ok == 1, msg
    return float(sol[0]), float(sol[1])


class Blocks:
    """The two-block problem; implements `woundsweep.solver.NonlinearProblem`."""

    def __init__(self, n: int, material: Fung, p: float, n_right: int | None = None) -> None:
        import dolfinx.fem
        import ufl

        from woundsweep.physics import compat

        m = n if n_right is None else n_right  # R's grid across the contact plane
        pL, cL = box_tets((n, n, n), (-1.0, 0.0, 0.0), (0.0, 1.0, 1.0))
        pR, cR = box_tets((n, m, m), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
        pts = np.vstack([pL, pR])  # the nodes on x = 0 are duplicated: disjoint bodies
        cells = np.vstack([cL, cR + len(pL)])
        ctags = np.r_[np.ones(len(cL)), np.full(len(cR), 2)].astype(np.int32)
        bf = boundary_facets(cells)
        cx = pts[bf].mean(axis=1)[:, 0]
        load = bf[np.abs(cx - 1.0) < 1e-9]
        left_wall = bf[(np.abs(cx) < 1e-9) & np.all(bf < len(pL), axis=1)]
        right_wall = bf[(np.abs(cx) < 1e-9) & np.all(bf >= len(pL), axis=1)]
        assert len(left_wall) == 2 * n * n and len(load) == len(right_wall) == 2 * m * m

        self.mesh, self.cell_mt, self.facet_mt = compat.mesh_from_arrays(
            pts, cells, ctags, load, np.full(len(load), LOAD)
        )
        self.V = compat.vector_space(self.mesh, 1)
        self.u = dolfinx.fem.Function(self.V)
        node_input = compat.node_input_index(self.V)
        input_node = np.full(len(pts), -1, dtype=np.int64)
        input_node[node_input] = np.arange(len(node_input))
        assert np.all(input_node >= 0)
        self.X = pts[node_input]  # reference coordinates of the (dof) nodes
        self.cell_nodes = compat.cell_dofs(self.V)
        Xc = self.X[self.cell_nodes]
        self.Dm_inv = np.linalg.inv(np.transpose(Xc[:, 1:] - Xc[:, :1], (0, 2, 1)))
        self.ell = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))

        # Dirichlet rows: u_x = 0 on L's x = -1 face, symmetry u_y = 0 / u_z = 0 (both blocks).
        X = self.X
        tol = 1e-9
        self.rows = np.unique(np.concatenate([
            3 * np.flatnonzero(np.abs(X[:, 0] + 1.0) < tol),
            3 * np.flatnonzero(np.abs(X[:, 1]) < tol) + 1,
            3 * np.flatnonzero(np.abs(X[:, 2]) < tol) + 2,
        ])).astype(np.int32)  # fmt: skip
        self.in_right = np.zeros(len(X), dtype=bool)
        self.in_right[input_node[len(pL) :]] = True

        # Forms: hyperelastic residual and its derivative; the dead load as a nodal vector.
        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        F = ufl.variable(ufl.Identity(3) + ufl.grad(self.u))
        md = {"quadrature_degree": 1}  # P1: F is constant per cell, the load linear per facet
        dx = ufl.Measure("dx", domain=self.mesh, metadata=md)
        ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=self.facet_mt, metadata=md)
        R = ufl.inner(ufl.diff(material.strain_energy(F), F), ufl.grad(v)) * dx
        self.R_form = compat.compile_form(R)
        self.a_form = compat.compile_form(ufl.derivative(R, self.u, du))
        f_form = compat.compile_form(ufl.dot(ufl.as_vector((-p, 0.0, 0.0)), v) * ds(LOAD))
        fvec = compat.create_vector(f_form)
        compat.assemble_vector(fvec, f_form)
        self.f_ext = fvec.getArray(readonly=True).copy()
        self.A = compat.create_matrix(self.a_form)

        # Contact: the two x = 0 faces in node numbering, oriented out of their blocks.
        left = orient_outward(X, self.cell_nodes, input_node[left_wall])
        right = orient_outward(X, self.cell_nodes, input_node[right_wall])
        self.contact = FlankContact(X, left, right)
        self.multipliers = ContactMultipliers(self.contact, self.solution)

    # -- NonlinearProblem ---------------------------------------------------------------------

    def solution(self) -> np.ndarray:
        return self.u.x.array

    def residual(self, b: Any) -> None:
        from woundsweep.physics import compat

        compat.assemble_vector(b, self.R_form)
        if self.contact.k_V_kPa > 0:
            add_vector(b, self.contact.force_vector(self.u.x.array))

    def jacobian(self, A: Any) -> None:
        from woundsweep.physics import compat

        compat.assemble_matrix(A, self.a_form)
        if self.contact.k_V_kPa > 0:
            K = self.contact.tangent_csr(self.u.x.array)
            if K.nnz:
                add_csr(A, K)

    def _grad(self, w: np.ndarray) -> np.ndarray:
        W = w.reshape(-1, 3)[self.cell_nodes]
        return np.transpose(W[:, 1:] - W[:, :1], (0, 2, 1)) @ self.Dm_inv

    def min_det(self, u: np.ndarray) -> float:
        return float(np.linalg.det(self._grad(u) + np.eye(3)).min())

    def max_strain(self, du: np.ndarray) -> float:
        return float(np.sqrt(np.max(np.sum(self._grad(du) ** 2, axis=(1, 2)), initial=0.0)))

    def length_scale(self) -> float:
        return self.ell


class Run(NamedTuple):
    status: str
    iterations: int
    summary: ContactSummary
    u: np.ndarray
    reaction_x_mN: float  # sum of the residual over the u_x = 0 rows of L's x = -1 face
    mult_mismatch: float  # max |mu - c psi| / max |c psi|: the carried multipliers at the end
    time_s: float


@functools.cache
def solve_blocks(n_right: int) -> dict[str, Any]:
    """Solve the load at k_V = 1 GPa (load continuation from the touching state), then 5 and
    100 GPa from the previous state. R has ``n_right``^2 grid boxes across x = 0."""
    import ufl

    from woundsweep.solver import Dirichlet, LoadState, NewtonSettings, NewtonSolver
    from woundsweep.solver.continuation import continuation
    from woundsweep.solver.newton import Policy

    material = dataclasses.replace(Fung.normal(0.0), a1=ufl.as_vector((1.0, 0.0, 0.0)))
    t0 = time.perf_counter()
    prob = Blocks(N_BOX, material, PRESSURE_KPA, n_right=n_right)
    t_build = time.perf_counter() - t0
    u = prob.u.x.array
    # The start: the faces touch (g = 0 at every contact point).
    prob.contact.k_V_kPa = K_V_GPA[0] * GPA_TO_KPA
    start = prob.contact.gaps(u)
    newton = NewtonSolver(prob, prob.A, NewtonSettings())
    policy = Policy.contact(newton.settings)  # as the wound's contact stages solve
    held = Dirichlet(prob.rows, np.zeros(len(prob.rows)))
    scale = float(np.linalg.norm(prob.f_ext))
    wall_x = prob.rows[(prob.rows % 3 == 0) & (np.abs(prob.X[prob.rows // 3, 0] + 1) < 1e-9)]
    b = prob.A.createVecs()[1]
    runs: dict[float, Run] = {}
    for k in K_V_GPA:
        prob.contact.k_V_kPa = k * GPA_TO_KPA
        t0 = time.perf_counter()
        if k == K_V_GPA[0]:
            res = continuation(newton, lambda s: LoadState(held, s * prob.f_ext),
                               force_scale=scale, policy=policy)  # fmt: skip
            status, its = res.status, res.iterations
        else:
            r = newton.solve(held, prob.f_ext, force_scale=scale, policy=policy)
            status, its = r.status, r.iterations
        dt = time.perf_counter() - t0
        prob.residual(b)
        reaction = float(b.getArray(readonly=True)[wall_x].sum())
        own = prob.contact.penalty_multipliers(u)
        mismatch = float(np.abs(prob.contact.mult - own).max() / np.abs(own).max())
        runs[k] = Run(status, its, prob.contact.summary(u), u.copy(), reaction, mismatch, dt)
    name = "matching" if n_right == N_BOX else "non-matching"
    print(f"\n{name}: build (mesh, JIT, contact setup) {t_build:.1f} s")
    for k, run in runs.items():
        s = run.summary
        print(f"k_V = {k:5.0f} GPa: {run.status}, {run.iterations} Newton steps, "
              f"{run.time_s:.2f} s; force {s.contact_force_mN:.9f} mN, reaction "
              f"{run.reaction_x_mN:.9f} mN, max penetration {s.max_penetration_mm:.4e} mm "
              f"({s.n_penetrating} points)")  # fmt: skip
    return {"prob": prob, "start": start, "runs": runs, "n_right": n_right}


@pytest.fixture(scope="module", autouse=True)
def _release_solutions():
    yield
    solve_blocks.cache_clear()


@pytest.fixture(scope="module", params=[N_BOX, N_BOX + 1], ids=["matching", "non-matching"])
def solved(request) -> dict[str, Any]:
    return solve_blocks(request.param)


@pytest.fixture(scope="module")
def matching() -> dict[str, Any]:
    return solve_blocks(N_BOX)


def test_touching_start_has_zero_gap_at_every_contact_point(solved) -> None:
    """Every node of both faces is a contact point and sees the other face at gap 0."""
    start = solved["start"]
    assert len(start) == (N_BOX + 1) ** 2 + (solved["n_right"] + 1) ** 2
    np.testing.assert_allclose(start, 0.0, atol=1e-14)


@pytest.mark.parametrize("k_gpa", K_V_GPA)
def test_contact_force_balances_the_load(solved, k_gpa: float) -> None:
    run = solved["runs"][k_gpa]
    assert run.status == "converged"
    load = PRESSURE_KPA * AREA_MM2
    s = run.summary
    assert abs(s.contact_force_mN - load) / load < 0.01
    assert s.max_penetration_mm > 0
    # The load goes on through L to its support: the reaction there is the load, too.
    assert abs(abs(run.reaction_x_mN) - load) / load < 0.01
    # Solved by the semi-smooth step: at convergence its multipliers are the penalty's forces.
    assert run.mult_mismatch < 1e-6


def test_penetration_shrinks_like_one_over_k_V(solved) -> None:
    pen = {k: run.summary.max_penetration_mm for k, run in solved["runs"].items()}
    for k in K_V_GPA[1:]:
        ratio = pen[K_V_GPA[0]] / pen[k]
        assert ratio == pytest.approx(k / K_V_GPA[0], rel=0.2), (k, ratio)


@pytest.mark.parametrize("k_gpa", K_V_GPA)
def test_matching_faces_penetration_is_p_h_over_k_V(matching, k_gpa: float) -> None:
    """Matching faces: overlap d = p h / k_V, h the equilateral side of a contact facet's
    area, at the nodes off the faces' edges (within 1 %); the implicit surface spreads a
    point's reaction over the master facets in its kernel, which on the faces' edges and
    corners, where the kernel is cut off, moves the nodal pressure by up to 30 %."""
    prob = matching["prob"]
    run = matching["runs"][k_gpa]
    c = prob.contact
    c.k_V_kPa = k_gpa * GPA_TO_KPA
    depth = -c.gaps(run.u)
    h = float(np.sqrt(4.0 * (0.5 / N_BOX**2) / np.sqrt(3.0)))
    expected = PRESSURE_KPA * h / (k_gpa * GPA_TO_KPA)
    nodes = np.concatenate([ps.nodes for ps in c.passes])
    yz = prob.X[nodes, 1:]
    inside = np.all((yz > 1e-9) & (yz < 1.0 - 1e-9), axis=1)
    assert inside.sum() == 2 * (N_BOX - 1) ** 2
    np.testing.assert_allclose(depth[inside], expected, rtol=0.01)
    np.testing.assert_allclose(depth, expected, rtol=0.3)
    assert run.summary.n_penetrating == 2 * (N_BOX + 1) ** 2  # every node of both faces


def test_matching_faces_solution_is_the_homogeneous_uniaxial_state(matching) -> None:
    """u = ((l_x - 1)(X + 1), (l_t - 1) Y, (l_t - 1) Z) in L; R the same, shifted by -d in x
    (its face x = 0 sits d behind L's), which P1 represents exactly: up to the overlap's
    variation over the face (the test above), i.e. within the overlap d itself."""
    prob = matching["prob"]
    lx, lt = uniaxial_state(Fung.normal(0.0), PRESSURE_KPA)
    X = prob.X
    for k, run in matching["runs"].items():
        exact = np.c_[(lx - 1.0) * (X[:, 0] + 1.0), (lt - 1.0) * X[:, 1], (lt - 1.0) * X[:, 2]]
        d = PRESSURE_KPA * float(np.sqrt(4.0 * (0.5 / N_BOX**2) / np.sqrt(3.0))) / (k * GPA_TO_KPA)
        exact[prob.in_right, 0] -= d
        err = np.abs(run.u.reshape(-1, 3) - exact).max()
        assert err < d, (k, err, d)

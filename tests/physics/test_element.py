"""The displacement element (`woundsweep.physics.element`): P2 node bookkeeping, kinematics,
the exact homogeneous state, and a wounded P2 job through all six stages."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from skin_patch import SKIN_TYPES, box_patch, homogeneous_field, rel_l2

pytestmark = pytest.mark.fem


@pytest.fixture(scope="module")
def p2_box():
    from woundsweep.config.solver import SolverSettings
    from woundsweep.physics.model import WoundModel

    return WoundModel(box_patch(n_xy=4), SolverSettings(element_degree=2))


@pytest.fixture(scope="module")
def wedge_mesh():
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh

    # t_d = 1, subcutis factor 1, L = 2, w = 0.6, apex depth 0.6 mm, m = 0.3; the P1 mesh,
    # which the P2 tests use too (eight times the cells of the P2 mesh)
    return build_mesh(GeometrySpec.wedge(1.0, 1.0, 2.0, 0.6, 0.6, 0.3, element_degree=1))


def test_p2_nodes_are_vertices_and_edge_midpoints(p2_box) -> None:
    d = p2_box.domain
    assert d.degree == 2 and d.cell_nodes.shape[1] == 10
    n_vertices = len(d.points)
    edges = {tuple(sorted((a, b))) for c in d.cells for i, a in enumerate(c) for b in c[i + 1 :]}
    assert len(d.X) == n_vertices + len(edges)
    # Vertex nodes carry their input point, edge nodes none.
    assert np.count_nonzero(d.node_input >= 0) == n_vertices
    np.testing.assert_array_equal(d.X[d.input_node], d.points)


def test_p2_gradient_at_the_quadrature_points_is_exact_for_a_quadratic_field(p2_box) -> None:
    d = p2_box.domain
    x, y, z = d.X.T
    u = np.c_[x * x - 0.5 * y * z, x * y + 0.3 * z, z * z - 2.0 * x * z].ravel()
    from woundsweep.physics.element import POINTS

    G = d.grad(u).reshape(len(d.cell_nodes), len(POINTS), 3, 3)
    V = np.einsum("kv,mvc->mkc", POINTS, d.X[d.cell_vertices])  # the rule's points
    vx, vy, vz = V[..., 0], V[..., 1], V[..., 2]
    want = np.stack(
        [
            np.stack([2 * vx, -0.5 * vz, -0.5 * vy], axis=-1),
            np.stack([vy, vx, 0.3 + 0 * vx], axis=-1),
            np.stack([-2.0 * vz, 0 * vx, 2 * vz - 2.0 * vx], axis=-1),
        ],
        axis=-2,
    )
    np.testing.assert_allclose(G, want, atol=1e-10)
    # det F at a uniform stretch is the product of the stretches at every point.
    s = np.array([1.1, 0.9, 1.05])
    assert d.min_det(((s - 1.0) * d.X).ravel()) == pytest.approx(np.prod(s), rel=1e-12)


@pytest.mark.parametrize("skin", SKIN_TYPES)
def test_p2_stages_1_and_2_reproduce_the_homogeneous_state(p2_box, skin: str) -> None:
    """Both pre-tension conditions give the per-layer homogeneous state at every P2 node."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import run_stage

    m = p2_box
    m.set_materials(JobMaterials.table2(skin, 0.0))
    hom = homogeneous_field(m.domain.X, skin, 0.0)
    for stage in (1, 2):
        assert run_stage(m, stage).solve.status == "converged"
        assert rel_l2(m.u.reshape(-1, 3), hom) < 1e-6
        # The stress is uniform in each layer: every cell's 14 samples equal its cell mean.
        samples, cells = m.forms.von_mises_samples(), m.forms.von_mises_cells()
        assert samples.values.shape == (len(cells), 14)
        np.testing.assert_allclose(samples.values, cells[:, None] * np.ones((1, 14)), rtol=1e-6)


def test_p2_stress_samples_match_the_materials_at_their_points(p2_box) -> None:
    """Von Mises of a quadratic field at the stress rule's points, against the numpy material
    laws at the same physical points; the summary's maximum sits at the largest sample."""
    from woundsweep.core.schema import DERMIS
    from woundsweep.physics.job import stress_summary
    from woundsweep.physics.materials import JobMaterials, first_piola, von_mises

    m, d = p2_box, p2_box.domain
    mats = JobMaterials.table2("normal", 30.0)
    m.set_materials(mats)
    x, y, z = d.X.T
    m.u[:] = 0.05 * np.c_[x * x - 0.5 * y * z, x * y + 0.3 * z, z * z - 2.0 * x * z].ravel()
    samples = m.forms.von_mises_samples()
    assert samples.weights.sum() == pytest.approx(1.0) and np.all(samples.weights > 0)
    corners = d.X[d.cell_vertices]
    bary = np.c_[1.0 - samples.points.sum(axis=1), samples.points]
    where = np.einsum("kv,mvc->mkc", bary, corners)
    dermis = set(d.cell_mt.indices[d.cell_mt.values == DERMIS].tolist())
    rng = np.random.default_rng(3)
    for c in rng.choice(len(corners), 12, replace=False):
        material = mats.dermis if c in dermis else mats.subcutis
        for k, (px, py, pz) in enumerate(where[c]):
            G = 0.05 * np.array(
                [[2 * px, -0.5 * pz, -0.5 * py], [py, px, 0.3], [-2 * pz, 0, 2 * pz - 2 * px]]
            )
            F = np.eye(3) + G
            want = von_mises(first_piola(material, F), F)
            assert samples.values[c, k] == pytest.approx(want, rel=1e-9)
            assert samples.det_F[c, k] == pytest.approx(np.linalg.det(F), rel=1e-12)
    s = stress_summary(
        m.forms.von_mises_cells(), d.volumes, d.cell_vertices, d.midpoints, samples, corners
    )
    c, k = np.unravel_index(np.argmax(samples.values), samples.values.shape)
    assert s["max_von_mises_kPa"] == samples.values[c, k]
    loc = [s[f"max_location_{a}_mm"] for a in "xyz"]
    np.testing.assert_allclose(loc, where[c, k], atol=1e-12)
    m.u[:] = 0.0


def test_p2_zone_triangles_cover_the_zone_with_the_parents_orientation(wedge_mesh) -> None:
    from woundsweep.contact.geometry import split_wound_flanks
    from woundsweep.physics.domain import WoundDomain

    p1, p2 = WoundDomain(wedge_mesh, degree=1), WoundDomain(wedge_mesh, degree=2)
    zero1, zero2 = np.zeros(p1.n_dofs), np.zeros(p2.n_dofs)
    for side in ("left", "right"):
        # A flat facet's four triangles through its midpoints have its area.
        a1, a2 = p1.deformed_zone_area(side, zero1), p2.deformed_zone_area(side, zero2)
        assert a2 == pytest.approx(a1, rel=1e-12)
    assert len(p2.zone_left_facets) == 4 * len(p1.zone_left_facets)
    # Every P2 zone node is a zone vertex or the midpoint of a zone edge.
    assert len(p2.zone_nodes) > len(p1.zone_nodes)
    np.testing.assert_array_equal(p2.X[p2.input_node[wedge_mesh.facets[0]]], p1.X[
        p1.input_node[wedge_mesh.facets[0]]])  # fmt: skip
    left, _ = split_wound_flanks(p2.X, p2.cell_vertices, p2.wound_facets(), p2.x_c)
    sub = p2.element.sub_triangles(left)

    def normals(X, tri):
        p = X[tri]
        return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])

    parent = np.repeat(normals(p2.X, left), 4, axis=0)
    child = normals(p2.X, sub)
    assert np.all(np.einsum("ij,ij->i", parent, child) > 0)


def test_p2_wedge_through_all_six_stages(wedge_mesh) -> None:
    from woundsweep.config.solver import SolverSettings
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel

    m = WoundModel(wedge_mesh, SolverSettings(element_degree=2))
    records = run_stages(m, JobMaterials.table2("normal", 0.0), 6)
    assert [r.result.status for r in records] == ["converged"] * 6
    r2 = records[1]
    assert abs(r2.result.closure_gap_max_mm) < 1e-8 and r2.result.closed == 1
    d2 = r2.diagnostics
    f_left, f_right = d2["closure_force_left_mN"], d2["closure_force_right_mN"]
    assert f_left > 0 and abs(f_left + f_right) < 1e-6 * f_left  # mirror-symmetric mesh
    for r in records:
        assert r.result.min_J > 0 and r.result.p99_von_mises_kPa > 0
        assert r.result.dofs == m.domain.n_dofs and r.result.element_degree == 2


def test_closed_form_stress_assembles_the_energy_s_derivatives(p2_box) -> None:
    """The forms' residual and tangent (P = F S, S in closed form) against UFL's derivatives
    of the strain energies (P = dW/dF), assembled at a state with both layers strained: equal
    to rounding."""
    import ufl

    from woundsweep.core.schema import DERMIS, SUBCUTIS
    from woundsweep.physics import compat
    from woundsweep.physics.materials import JobMaterials

    m, d = p2_box, p2_box.domain
    mats = JobMaterials.table2("stiff", 30.0)
    m.set_materials(mats)
    x, y, z = d.X.T
    m.u[:] = 0.08 * np.c_[x + 0.3 * y * z, 0.5 * y - 0.2 * x * x, -0.3 * z + 0.1 * x * y].ravel()
    u = m.forms.u
    v, du = ufl.TestFunction(d.V), ufl.TrialFunction(d.V)
    F = ufl.variable(ufl.Identity(3) + ufl.grad(u))
    dermis = dataclasses.replace(mats.dermis, a1=ufl.as_vector([float(c) for c in mats.dermis.a1]))
    md = {"quadrature_degree": 2}
    dx = ufl.Measure("dx", domain=d.mesh, subdomain_data=d.cell_mt, metadata=md)
    R = sum(
        ufl.inner(ufl.diff(W.strain_energy(F), F), ufl.grad(v)) * dx(tag)
        for tag, W in ((DERMIS, dermis), (SUBCUTIS, mats.subcutis))
    )
    jit = compat.jit_options()
    R_ref, a_ref = compat.compile_form(R, jit), compat.compile_form(ufl.derivative(R, u, du), jit)
    vectors, matrices = [], []
    for R_form, a_form in ((R_ref, a_ref), (m.forms.R_form, m.forms.a_form)):
        b = compat.create_vector(R_form)
        compat.assemble_vector(b, R_form)
        A = compat.create_matrix(a_form)
        compat.assemble_matrix(A, a_form)
        vectors.append(b.getArray().copy())
        matrices.append(A)
    assert np.linalg.norm(vectors[0]) > 1.0  # a strained state
    np.testing.assert_allclose(
        vectors[1], vectors[0], rtol=0, atol=1e-12 * np.abs(vectors[0]).max()
    )
    diff = matrices[0].copy()
    diff.axpy(-1.0, matrices[1])
    assert diff.norm() <= 1e-12 * matrices[0].norm()

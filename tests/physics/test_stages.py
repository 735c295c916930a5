"""Stages 1-3 on coarse meshes: equivalence of the lateral conditions, symmetry, closure.

Unwounded patches are structured tetrahedral boxes built here, tagged from midpoints; wounded
ones come from woundsweep.mesh (coarsest size factor).
"""

from __future__ import annotations

import numpy as np
import pytest
from skin_patch import HALF, SKIN_TYPES, T_D, T_TOTAL, box_patch, homogeneous_field, rel_l2

from woundsweep.config.solver import SolverSettings

pytestmark = pytest.mark.fem

P1 = SolverSettings(element_degree=1)  # the meshes here are P1's, and so are the expected values


@pytest.fixture(scope="module", params=[1, 2], ids=["P1", "P2"])
def box_model(request):
    """The unwounded box at P1 and at P2: both represent the homogeneous states exactly."""
    from woundsweep.physics.model import WoundModel

    return WoundModel(box_patch(), SolverSettings(element_degree=request.param))


@pytest.mark.parametrize("skin", SKIN_TYPES)
@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_unwounded_stage2_reproduces_stage1(box_model, skin: str, angle: float) -> None:
    """Lateral traction of healthy skin (stage 2) gives the Dirichlet pre-tension (stage 1)."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import run_stage

    m = box_model
    m.set_materials(JobMaterials.table2(skin, angle))
    assert run_stage(m, 1).solve.status == "converged"
    u1 = m.displacement_input()
    out2 = run_stage(m, 2)
    assert out2.solve.status == "converged"
    u2 = m.displacement_input()
    assert rel_l2(u2, u1) < 0.01
    # Both are the analytic per-layer homogeneous state (P1 and P2 represent it exactly).
    hom = homogeneous_field(m.domain.points, skin, angle)
    assert rel_l2(u1, hom) < 1e-6 and rel_l2(u2, hom) < 1e-6
    # The gauge points carry no load.
    assert out2.diagnostics["pin_reaction_max_mN"] < 1e-8 * out2.diagnostics["lateral_force_mN"]


@pytest.mark.parametrize("skin", SKIN_TYPES)
def test_stage1_starts_from_the_unwounded_solution(box_model, skin: str) -> None:
    """Stage 1's Newton start is the per-layer homogeneous state, which solves the unwounded
    patch exactly: one Newton step (the full-step convergence check) is all it takes."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import run_stage

    m = box_model
    m.set_materials(JobMaterials.table2(skin, 0.0))
    start = m.pretension_state()[m.domain.input_node]
    assert rel_l2(start, homogeneous_field(m.domain.points, skin, 0.0)) < 1e-12
    out = run_stage(m, 1)
    assert out.solve.status == "converged" and out.solve.iterations == 1


@pytest.mark.parametrize("skin", SKIN_TYPES)
def test_unwounded_oblique_orientation_is_healthy_skin(box_model, skin: str) -> None:
    """At 45 degrees healthy skin carries an in-plane shear (P_xy != 0). Stage 1 prescribes
    the healthy state's whole in-plane displacement on the lateral faces, so a patch without
    a wound is homogeneous after it (to 1e-8), and stage 2's traction keeps it there."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import run_stage

    m = box_model
    m.set_materials(JobMaterials.table2(skin, 45.0))
    assert abs(m.homogeneous[1].P[0, 1]) > 0.1 * abs(m.homogeneous[1].P[0, 0])
    assert run_stage(m, 1).solve.status == "converged"
    u1 = m.displacement_input()
    hom = homogeneous_field(m.domain.points, skin, 45.0)
    assert np.max(np.abs(u1 - hom)) <= 1e-8 * HALF
    assert run_stage(m, 2).solve.status == "converged"
    assert rel_l2(m.displacement_input(), hom) < 1e-6


def test_lateral_facets_split_by_layer(box_model) -> None:
    """The derived lateral facet ids hold exactly each layer's share of the four side faces."""
    import ufl

    from woundsweep.physics import compat
    from woundsweep.physics.domain import LATERAL_DERMIS, LATERAL_SUBCUTIS

    m = box_model
    ds = ufl.Measure("ds", domain=m.domain.mesh, subdomain_data=m.domain.solver_facet_mt)
    one = dolfinx_constant(m.domain.mesh, 1.0)
    perimeter = 8 * HALF
    for tag, thickness in ((LATERAL_DERMIS, T_D), (LATERAL_SUBCUTIS, T_TOTAL - T_D)):
        form = compat.compile_form(one * ds(tag, metadata={"quadrature_degree": 1}))
        area = assemble_scalar(form)
        assert area == pytest.approx(perimeter * thickness, rel=1e-12)


def dolfinx_constant(mesh, value: float):
    import dolfinx.fem

    return dolfinx.fem.Constant(mesh, float(value))


def assemble_scalar(form) -> float:
    import dolfinx.fem

    return float(dolfinx.fem.assemble_scalar(form))


@pytest.mark.parametrize("angle", [0.0, 45.0])
def test_rotating_the_orientation_by_90_degrees_rotates_the_solution(angle: float) -> None:
    """Patch P at orientation t and the same patch turned by +90 degrees at t + 90 are the same
    physical problem: equal von Mises per cell, and stage-1 displacements rotated by 90."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    a = WoundModel(box_patch(rotate=False), P1)
    b = WoundModel(box_patch(rotate=True), P1)
    a.set_materials(JobMaterials.table2("stiff", angle))
    b.set_materials(JobMaterials.table2("stiff", angle + 90.0))
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for stage in (1, 2):
        assert run_stage(a, stage).solve.status == "converged"
        assert run_stage(b, stage).solve.status == "converged"
        vm_a = a.forms.von_mises_cells()[np.argsort(a.domain.cell_input)]
        vm_b = b.forms.von_mises_cells()[np.argsort(b.domain.cell_input)]
        np.testing.assert_allclose(vm_b, vm_a, rtol=1e-7, atol=1e-9 * vm_a.max())
        if stage == 1:
            ua, ub = a.displacement_input(), b.displacement_input()
            np.testing.assert_allclose(ub, ua @ R.T, atol=1e-9)


def test_stage3_closing_load_reproduces_the_dirichlet_closure(cylinder_mesh) -> None:
    """Known answer: the consistent nodal reactions of the stage-2 closure, applied as the
    stage-3 load with the Dirichlet condition released (contact off), hold the symmetric
    wound in the Dirichlet-closed state: the same displacement to Newton's tolerance, and a
    zone closed along its whole line."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    m = WoundModel(cylinder_mesh, P1)
    w = 1.2
    assert m.domain.x_c == pytest.approx(w / 2)
    assert len(m.domain.zone_left_nodes) > 3 and len(m.domain.zone_right_nodes) > 3
    # The zone is the middle third of the length and the upper half of its depth.
    zone_X = m.domain.X[m.domain.zone_nodes]
    assert np.all(np.abs(zone_X[:, 1]) <= 4.0 / 3.0 + 1e-9)
    assert np.all(zone_X[:, 2] >= -0.5 * m.domain.wound_depth - 1e-9)
    line = m.closure_line
    assert line is not None and line.width_mm == pytest.approx(w)
    m.set_materials(JobMaterials.table2("normal", 0.0))

    s1 = run_stage(m, 1)
    assert s1.solve.status == "converged"
    gap1 = line.measure(m.u)
    assert gap1.gap_min_mm > w  # the pre-tension widens the opening

    s2 = run_stage(m, 2)
    assert s2.solve.status == "converged"
    x = m.domain.X[:, 0] + m.u.reshape(-1, 3)[:, 0]
    assert np.max(np.abs(x[m.domain.zone_nodes] - w / 2)) < 1e-8
    assert line.measure(m.u).gap_max_mm < 1e-8
    # Wound-surface nodes outside the zone stay open.
    wound_nodes = np.unique(
        m.domain.input_node[np.unique(cylinder_mesh.facets[cylinder_mesh.facet_tags == 17])]
    )
    outside = np.setdiff1d(wound_nodes, m.domain.zone_nodes)
    assert np.max(np.abs(x[outside] - w / 2)) > 0.1 * w
    f_left, f_right = (
        s2.diagnostics["closure_force_left_mN"],
        s2.diagnostics["closure_force_right_mN"],
    )
    assert f_left > 0 > f_right
    assert abs(f_left + f_right) < 1e-6 * f_left  # the mesh is mirror-symmetric
    assert s2.diagnostics["pin_reaction_max_mN"] < 1e-6 * s2.diagnostics["lateral_force_mN"]
    u2 = m.u.copy()

    s3 = run_stage(m, 3)
    assert s3.solve.status == "converged"
    load = m.problem.closure_load
    assert load is not None
    left_rows = 3 * m.domain.zone_left_nodes
    assert float(load[left_rows].sum()) == pytest.approx(f_left, rel=1e-12)
    assert np.count_nonzero(load) <= len(m.domain.zone_nodes)  # x components of the zone only
    diff = float(np.abs(m.u - u2).max()) / float(np.abs(u2).max())
    m3 = line.measure(m.u)
    print(f"\nstage 3 against stage 2: max |du| / max |u| = {diff:.2e}; surface gap "
          f"{m3.gap_max_mm:.2e} mm (stage 1: {gap1.gap_median_mm:.3f} mm, w = {w} mm)")  # fmt: skip
    assert diff < 1e-6
    assert m3.closed and abs(m3.gap_max_mm) < 1e-6 * w and m3.overlap_mm < 1e-6 * w
    # A load of the same total spread otherwise does not hold it: 90 % of the reactions
    # leave the zone open by more than the tolerance (the test can fail).
    m.closing_forces = 0.9 * load
    m.u[:] = u2
    assert run_stage(m, 3).solve.status == "converged"
    assert not line.measure(m.u).closed


def test_stiff_skin_has_higher_maximal_stress_than_soft() -> None:
    """Demo job 0's cylinder at m = 0.5 (with P1 at m = 0.3 its soft stage 2 diverges:
    docs/model.md, "Known limits")."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel

    spec = GeometrySpec.cylindrical(1.0, 1.0, 4.0, 1.2, 0.0, 0.5, element_degree=1)
    m = WoundModel(build_mesh(spec), P1)
    p99 = {}
    for skin in ("stiff", "soft"):
        recs = run_stages(m, JobMaterials.table2(skin, 0.0), 3)
        assert [r.result.status for r in recs] == ["converged"] * 3
        p99[skin] = [r.result.p99_von_mises_kPa for r in recs]
    print(f"\np99 von Mises by stage: stiff {p99['stiff']}, soft {p99['soft']}")
    assert all(s > t for s, t in zip(p99["stiff"], p99["soft"]))


@pytest.fixture(scope="module")
def wounded_model(cylinder_mesh):
    """A wounded P1 model: stage 1's start (the unwounded state) is not its solution."""
    from woundsweep.physics.model import WoundModel

    return WoundModel(cylinder_mesh, P1)


def test_unconverged_stage_stops_later_stages(wounded_model) -> None:
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.solver import NewtonSettings

    m = wounded_model
    saved = m.settings
    try:
        m.set_newton_settings(NewtonSettings(max_iterations=1, max_load_cuts=1))
        recs = run_stages(m, JobMaterials.table2("soft", 45.0), 3)
    finally:
        m.set_newton_settings(saved)
    assert [r.result.status for r in recs] == ["max-iterations", "not-run", "not-run"]
    assert recs[0].displacement_mm is None and recs[0].result.p99_von_mises_kPa is None


def test_newton_statuses_inverted_and_linear_solver_failed(box_model) -> None:
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.solver import Dirichlet, NewtonSettings, NewtonSolver

    m = box_model
    m.set_materials(JobMaterials.table2("normal", 0.0))
    # Push one top node 10 patch thicknesses down in a single step: every relaxation down to
    # gamma_min still inverts its cells.
    newton = NewtonSolver(
        m.problem, m.problem.A, NewtonSettings(gamma_min=0.2, max_strain_step=1e9)
    )
    top = int(np.argmax(m.domain.X[:, 2] - np.abs(m.domain.X[:, 0]) - np.abs(m.domain.X[:, 1])))
    rows = np.array(
        [*(3 * m.domain.bottom_nodes + 0), *(3 * m.domain.bottom_nodes + 1), *(3 * m.domain.bottom_nodes + 2),
         3 * top + 2], dtype=np.int32)  # fmt: skip
    values = np.zeros(len(rows))
    values[-1] = -10 * T_TOTAL
    res = newton.solve(Dirichlet(rows, values))
    assert res.status == "inverted"
    np.testing.assert_array_equal(m.u, 0.0)  # the last accepted state is kept
    # No Dirichlet condition at all: the tangent is singular (rigid motions).
    newton = NewtonSolver(m.problem, m.problem.A, NewtonSettings())
    offset = np.zeros(len(m.u))
    offset[2] = 1.0  # a load, so that a step is needed
    res = newton.solve(Dirichlet.none(), offset)
    assert res.status == "linear-solver-failed"


def test_stage_iteration_budget_ends_a_long_continuation(wounded_model) -> None:
    """A stage that needs more Newton steps than ``max_stage_iterations`` in all its load
    increments stops as ``max-iterations`` before the end of its load."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import run_stage
    from woundsweep.solver import NewtonSettings

    m = wounded_model
    saved = m.settings
    try:
        # Every increment solved to the full tolerance (path_rtol 0), on a wounded patch,
        # where stage 1's start is not its solution.
        m.set_newton_settings(NewtonSettings(load_steps=4, max_stage_iterations=2, path_rtol=0.0))
        m.set_materials(JobMaterials.table2("soft", 45.0))
        out = run_stage(m, 1)
    finally:
        m.set_newton_settings(saved)
    assert out.solve.status == "max-iterations"
    assert 0.0 < out.solve.load_reached < 1.0 and out.solve.iterations > 2

"""Stages 4-6 (flank contact) on closed paper-like wounds: penetration, overlap, 1/k_V, status.

The meshes are demo-sweep geometries (coarsest size factor): a cylindrical wound whose flanks
are driven through each other by stage 3, and a deep wedge whose lower flanks already overlap
in the Dirichlet-closed stage-2 state. The checks that do not use the contact module's own
gap are the mirror-plane ones: at orientation 0 the problem is mirror-symmetric about x = x_c,
so the flanks can only meet on that plane and no flank node may cross it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse

pytestmark = pytest.mark.fem

CONVERGED = "converged"


@pytest.fixture(scope="module")
def wedge_mesh():
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh

    # Demo job 18: a deep, narrow wedge (width 1.2, depth 1.0).
    return build_mesh(GeometrySpec.wedge(1.0, 1.0, 4.0, 1.2, 1.0, 0.3))


def _flank_nodes(m) -> tuple[np.ndarray, np.ndarray]:
    left, right = m.contact.surfaces
    return left.nodes, right.nodes


def _energy_slope(m, u0: np.ndarray, v: np.ndarray, eps: float):
    """(central difference of the potential along v at u0, R(u0)); leaves u perturbed."""
    u = m.u
    u[:] = u0
    R = m.problem.residual_array()
    u[:] = u0 + eps * v
    e_plus = m.problem.energy()
    u[:] = u0 - eps * v
    e_minus = m.problem.energy()
    return (e_plus - e_minus) / (2 * eps), R


def _run(mesh, angle: float, skin: str = "stiff"):
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import WoundModel

    m = WoundModel(mesh)
    m.set_materials(JobMaterials.table2(skin, angle))
    outs = [m.run_stage(k) for k in range(1, 7)]
    return m, outs


@pytest.mark.parametrize("which", ["cylinder", "wedge"])
def test_contact_stages_close_the_wound_without_overlap(which, cylinder_mesh, wedge_mesh) -> None:
    mesh = cylinder_mesh if which == "cylinder" else wedge_mesh
    m, outs = _run(mesh, 0.0)
    assert [o.solve.status for o in outs] == [CONVERGED] * 6
    d3 = outs[2].diagnostics
    d4, d5, d6 = (o.diagnostics for o in outs[3:])
    x = m.domain.X + m.u.reshape(-1, 3)
    left, right = _flank_nodes(m)
    h = float(np.min(m.contact.passes[0].size_mm))
    # Without contact the flanks pass through the mirror plane (stage 3 for the cylinder, the
    # lower wedge already under the stage-2 closure); with it no flank node crosses it by more
    # than 1 % of the smallest element (independent of the contact module's gap).
    x3 = m.domain.X + m.displacements[3].reshape(-1, 3)
    x2 = m.domain.X + m.displacements[2].reshape(-1, 3)
    crossed = max(np.max(x3[left, 0] - m.domain.x_c), np.max(x2[left, 0] - m.domain.x_c))
    print(f"\n{which}: left flank beyond the mirror plane before contact {crossed:.3g} mm, "
          f"after stage 6 {np.max(x[left, 0] - m.domain.x_c):.3g} mm (h_min {h:.3g} mm)")  # fmt: skip
    assert crossed > 0.05 * h
    assert np.max(x[left, 0] - m.domain.x_c) < 0.01 * h
    assert np.max(m.domain.x_c - x[right, 0]) < 0.01 * h
    # The contact module's own measures agree: shallow, no deep overlap, and the wound is
    # actually held shut somewhere (a real compressive force).
    assert d6["max_penetration_rel"] < 0.01
    assert d6["n_penetrating"] > 0 and d6["contact_force_mN"] > 0
    assert np.isfinite(d3["closure_gap_mm"])
    # Penetration ~ pressure * h / k_V: it shrinks with 1/k_V (1, 5, 100 GPa) while the force
    # that holds the flanks apart stays the same.
    p4, p5, p6 = (d["max_penetration_mm"] for d in (d4, d5, d6))
    assert p4 / p5 == pytest.approx(5.0, rel=0.2)
    assert p4 / p6 == pytest.approx(100.0, rel=0.2)
    assert d6["contact_force_mN"] == pytest.approx(d4["contact_force_mN"], rel=0.02)
    # The contact forces are internal: the gauge pins carry nothing.
    assert d6["pin_reaction_max_mN"] < 1e-6 * m._lateral_force()


def test_contact_at_45_degrees(cylinder_mesh) -> None:
    """Oblique fibres: the flanks are no mirror images, contact must still hold them apart."""
    m, outs = _run(cylinder_mesh, 45.0, skin="stiff")
    assert [o.solve.status for o in outs] == [CONVERGED] * 6
    d6 = outs[5].diagnostics
    assert d6["max_penetration_rel"] < 0.01
    assert d6["n_penetrating"] > 0 and d6["contact_force_mN"] > 0
    # Oblique fibres break the mirror symmetry: the two flanks move differently along y.
    uy = m.u.reshape(-1, 3)[:, 1]
    left, right = _flank_nodes(m)
    assert abs(np.mean(uy[left]) - np.mean(uy[right])) > 1e-4


def test_the_zone_tie_is_inert_at_0_degrees(cylinder_mesh) -> None:
    """Mirror symmetry: the tie carries no force, and stages 4-6 are those of the untied
    model."""
    m, outs = _run(cylinder_mesh, 0.0)
    assert m.tie is not None and len(m.tie) > 0
    assert all(o.diagnostics["tie_force_mN"] < 1e-9 * o.diagnostics["contact_force_mN"]
               for o in outs[3:])  # fmt: skip
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import WoundModel

    free = WoundModel(cylinder_mesh)
    free.problem.tie = None
    free.set_materials(JobMaterials.table2("stiff", 0.0))
    outs_free = [free.run_stage(k) for k in range(1, 7)]
    assert [o.solve.status for o in outs_free] == [CONVERGED] * 6
    scale = float(np.abs(m.u).max())
    assert float(np.abs(m.u - free.u).max()) < 1e-9 * scale


def test_the_zone_tie_holds_the_flanks_at_45_degrees(cylinder_mesh) -> None:
    """At 45 degrees the tie carries force, its slip stays at the penalty's scale, and the
    stage's potential (tie included) is that of its residual."""
    m, outs = _run(cylinder_mesh, 45.0)
    assert [o.solve.status for o in outs] == [CONVERGED] * 6
    d6 = outs[5].diagnostics
    assert d6["tie_force_mN"] > 1e-3 * d6["contact_force_mN"]
    h = float(np.min(m.contact.passes[0].size_mm))
    assert d6["tie_max_slip_mm"] < 0.01 * h
    # Slip falls as the penalty rises (stages 4 -> 6: k_V 1 -> 100 GPa).
    assert outs[5].diagnostics["tie_max_slip_mm"] < 0.1 * outs[3].diagnostics["tie_max_slip_mm"]
    u = m.u
    u6 = u.copy()
    rng = np.random.default_rng(4)
    free = np.ones(len(u), dtype=bool)
    free[m.domain.gauge_rows()] = False
    v = np.zeros(len(u))
    v[3 * m.tie.pairs[:, 0] + 1] = 1.0  # slide the zone's left flank along y
    v += 0.1 * np.where(free, rng.standard_normal(len(u)), 0.0)
    fd, R = _energy_slope(m, u6 + 1e-5 * v, v, 1e-7)
    u[:] = u6
    assert fd == pytest.approx(float(R @ v), rel=1e-4)


def test_unconverged_stage_3_does_not_stop_stages_4_to_6(cylinder_mesh) -> None:
    """Stage 4 restarts from stage 2: with stage 3 starved, stages 4-6 run and give the
    results of a run whose stage 3 converged."""
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import WoundModel
    from woundsweep.solver.newton import MAX_ITERATIONS, NewtonSolver

    mats = JobMaterials.table2("stiff", 0.0)
    full = run_stages(WoundModel(cylinder_mesh), mats, 6)
    m = WoundModel(cylinder_mesh)
    real_run_stage, normal = m.run_stage, m.newton

    def starved(stage: int):
        starve = dataclasses.replace(m.settings, max_iterations=1, max_load_cuts=0, path_rtol=0.0)
        m.newton = NewtonSolver(m.problem, m.problem.A, starve) if stage == 3 else normal
        return real_run_stage(stage)

    m.run_stage = starved  # type: ignore[method-assign]
    recs = run_stages(m, mats, 6)
    assert [r.result.status for r in recs] == [CONVERGED] * 2 + [MAX_ITERATIONS] + [CONVERGED] * 3
    assert recs[2].displacement_mm is None
    for a, b in zip(full[3:], recs[3:]):
        assert b.result.p99_von_mises_kPa == pytest.approx(a.result.p99_von_mises_kPa, rel=1e-6)
        assert b.result.contact_force_mN == pytest.approx(a.result.contact_force_mN, rel=1e-6)


def test_unconverged_contact_stage_is_recorded_as_such(cylinder_mesh) -> None:
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import CONTACT_START_kPa, WoundModel
    from woundsweep.solver.newton import MAX_ITERATIONS, NewtonSolver

    m = WoundModel(cylinder_mesh)
    real_run_stage = m.run_stage

    def starved(stage: int):
        # Stages 1-3 as usual; the contact stages get one Newton step, no load cuts and the
        # full tolerance in every increment.
        if stage == 4:
            st = dataclasses.replace(m.settings, max_iterations=1, max_load_cuts=0, path_rtol=0.0)
            m.newton = NewtonSolver(m.problem, m.problem.A, st)
        return real_run_stage(stage)

    m.run_stage = starved  # type: ignore[method-assign]
    recs = run_stages(m, JobMaterials.table2("stiff", 0.0), 6)
    statuses = [r.result.status for r in recs]
    assert statuses == [CONVERGED] * 3 + [MAX_ITERATIONS, "not-run", "not-run"]
    r4 = recs[3]
    assert r4.displacement_mm is None and r4.result.p99_von_mises_kPa is None
    # The contact state it stopped in is still reported (penetration of the last iterate).
    assert r4.result.n_penetrating is not None and r4.result.max_penetration_mm is not None
    # And the stability of the last converged state (here the stage-2 state at the starting
    # penalty): the eigenvalue nearest zero of the symmetric free-dof tangent, recomputed
    # densely from the same assembled tangent.
    k0 = r4.extra["stability_penalty_kPa"]
    assert k0 == pytest.approx(CONTACT_START_kPa)
    np.testing.assert_allclose(m.u, m.displacements[2])
    c = m.contact
    c.k_V_kPa = k0
    m.problem.jacobian(m.problem.A)
    ai, aj, av = m.problem.A.getValuesCSR()
    free = np.ones(len(ai) - 1, dtype=bool)
    free[m.domain.gauge_rows()] = False
    D = scipy.sparse.csr_matrix((av, aj, ai)).toarray()[np.ix_(free, free)]
    # Every load of a contact stage is dead, so the tangent is an energy Hessian: symmetric.
    assert np.abs(D - D.T).max() < 1e-10 * np.abs(D).max()
    w = np.linalg.eigvalsh(0.5 * (D + D.T))
    nearest = np.sort(w[np.argsort(np.abs(w))[:3]])[0]
    assert r4.extra["stability_min_eig_mN_per_mm"] == pytest.approx(nearest, rel=1e-6)
    assert nearest > 0.0  # the closed 0-degree wound is stable


def test_contact_stage_potential_is_that_of_the_residual(cylinder_mesh) -> None:
    """In the contact stages the closure traction is a dead load (stage-2 area), so the stage
    has a potential: its directional derivative is R . v (central differences), and the closure force is the same at any state (tau times the stage-2 area of
    the flank). In stage 3 the traction follows the deformed area: no potential, and the force
    changes with the state."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import WoundModel

    m = WoundModel(cylinder_mesh)
    m.set_materials(JobMaterials.table2("stiff", 0.0))
    for k in (1, 2, 3):
        assert m.run_stage(k).solve.status == CONVERGED
    assert m.problem.energy() is None  # stage 3: a follower load

    def closure_force() -> float:
        # x-force of the closure traction on the left flank: R without tau minus R with it.
        r1 = m.problem.residual_array()
        tau = float(m.forms.tau.value)
        m.forms.tau.value = 0.0
        r0 = m.problem.residual_array()
        m.forms.tau.value = tau
        left = np.flatnonzero(m.domain.X[:, 0] < m.domain.x_c)
        return float(np.sum((r0 - r1)[3 * left]))

    u = m.u
    u3 = u.copy()
    follow3 = closure_force()  # the stage-3 (follower) load at the stage-3 state
    assert follow3 == pytest.approx(m.tau_kPa * m.deformed_zone_area("left"), rel=1e-10)
    m.run_stage(4)
    assert m.problem.energy() is not None
    u4 = u.copy()
    u[:] = m.displacements[2]
    dead = m.tau_kPa * m.deformed_zone_area("left")
    for state in (u3, u4):
        u[:] = state
        assert closure_force() == pytest.approx(dead, rel=1e-10)
    assert abs(follow3 - dead) > 1e-4 * dead  # the stage-3 area differs from stage 2's
    u[:] = u4
    # Away from the equilibrium (where R . v would vanish): a random state near it.
    rng = np.random.default_rng(1)
    free = np.ones(len(u), dtype=bool)
    free[m.domain.gauge_rows()] = False
    w = np.where(free, rng.standard_normal(len(u)), 0.0)
    v = np.where(free, rng.standard_normal(len(u)), 0.0)
    fd, R = _energy_slope(m, u4 + 1e-4 * w, v, 1e-6)
    u[:] = u4
    assert abs(R @ v) > 1e-3 * np.linalg.norm(R) * np.linalg.norm(v) / np.sqrt(len(v))
    assert fd == pytest.approx(float(R @ v), rel=1e-5)


def test_contact_stages_5_and_6_start_in_equilibrium(cylinder_mesh) -> None:
    """At s = 0, stages 5 and 6 solve exactly the converged state of the stage before: the
    out-of-balance force that the stage releases holds only its convergence residual. (It
    once was computed with contact off, so it held the contact forces as well: a jump of
    tens of mN at the first increment, which failed stage 5 of a 45-degree paper job.)"""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import WoundModel

    m = WoundModel(cylinder_mesh)
    m.set_materials(JobMaterials.table2("stiff", 0.0))
    for k in range(1, 5):
        assert m.run_stage(k).solve.status == CONVERGED
    u = m.u
    for stage in (5, 6):
        rows = m.domain.gauge_rows()
        _, _, load, scale = m._contact_load(stage, rows)
        start = load(0.0)
        r = m.problem.residual_array() - start.offset
        r[rows] = 0.0
        contact = m.contact.force_vector(u)
        contact[rows] = 0.0
        assert np.linalg.norm(contact) > 1e-3 * scale  # the contact forces are there ...
        assert np.linalg.norm(r) <= 1e-12 * scale  # ... and balanced at s = 0
        assert m.run_stage(stage).solve.status == CONVERGED


def test_stage_4_starts_from_a_stable_state_on_an_overlapping_wedge() -> None:
    """Paper job 8652's geometry (a 0-degree wedge, width 3, depth 1.5): its Dirichlet-closed
    lower flanks overlap, and at a penalty of 100 kPa the contact's curvature term makes the
    stage-4 starting state a saddle of the potential (Newton cycled there). At the starting
    penalty the free-dof Hessian there is positive definite."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import CONTACT_START_kPa, WoundModel

    m = WoundModel(build_mesh(GeometrySpec.wedge(1.0, 2.0, 6.0, 3.0, 1.5, 0.7)))
    m.set_materials(JobMaterials.table2("stiff", 0.0))
    for stage in (1, 2, 3):
        assert m.run_stage(stage).solve.status == CONVERGED
    rows = m.domain.gauge_rows()
    m._contact_load(4, rows)  # the stage-4 start: the stage-2 state, dead closure load
    np.testing.assert_array_equal(m.u, m.displacements[2])
    eig_start = m._stability(rows, CONTACT_START_kPa)["stability_min_eig_mN_per_mm"]
    eig_100 = m._stability(rows, 100.0)["stability_min_eig_mN_per_mm"]
    assert eig_start > 0.0 > eig_100

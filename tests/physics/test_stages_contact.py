"""Stages 4-6 (flank contact) on closed paper-like wounds: penetration, overlap, 1/k_V, status.

The meshes are demo-sweep geometries (coarsest size factor): a cylindrical wound that the
closure holds shut with nothing else touching, and a deep wedge whose lower flanks overlap in
the Dirichlet-closed stage-2 state, so that the contact must push them apart. The checks that do not use the contact module's own
gap are the mirror-plane ones: at orientation 0 the problem is mirror-symmetric about x = x_c,
so the flanks can only meet on that plane and no flank node may cross it.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
import scipy.sparse

from woundsweep.config.solver import SolverSettings

pytestmark = pytest.mark.fem

CONVERGED = "converged"
P1 = SolverSettings(element_degree=1)  # the meshes here are P1's, and so are the expected values


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


def _run(mesh, angle: float, skin: str = "stiff", solver: SolverSettings = P1):
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    m = WoundModel(mesh, solver)
    m.set_materials(JobMaterials.table2(skin, angle))
    outs = [run_stage(m, k) for k in range(1, 7)]
    return m, outs


@functools.cache
def _p2_mesh(which: str):
    """The fixtures' geometries meshed for P2 (the default element)."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh

    if which == "cylinder":
        return build_mesh(GeometrySpec.cylindrical(1.0, 1.0, 4.0, 1.2, 0.0, 0.3))
    return build_mesh(GeometrySpec.wedge(1.0, 1.0, 4.0, 1.2, 1.0, 0.3))


@pytest.mark.parametrize("degree", [1, 2], ids=["P1", "P2"])
@pytest.mark.parametrize("which", ["cylinder", "wedge"])
def test_contact_stages_close_the_wound_without_overlap(
    which, degree, cylinder_mesh, deep_wedge_mesh
) -> None:
    if degree == 1:
        mesh = cylinder_mesh if which == "cylinder" else deep_wedge_mesh
    else:
        mesh = _p2_mesh(which)
    m, outs = _run(mesh, 0.0, solver=SolverSettings(element_degree=degree))
    assert [o.solve.status for o in outs] == [CONVERGED] * 6
    d4, d5, d6 = (o.diagnostics for o in outs[3:])
    x = m.domain.X + m.u.reshape(-1, 3)
    left, right = _flank_nodes(m)
    h = float(np.median(m.contact.passes[0].size_mm))
    # Under the stage-2 closure the wedge's lower flanks pass through the mirror plane; after
    # the contact stages no flank node crosses it by more than 1 % of the flank's median
    # element (independent of the contact module's gap; the penalty's penetration scales with
    # the local size, and the apex's elements are half the flank's).
    x2 = m.domain.X + m.displacements[2].reshape(-1, 3)
    crossed = np.max(x2[left, 0] - m.domain.x_c)
    print(f"\n{which}: left flank beyond the mirror plane before contact {crossed:.3g} mm, "
          f"after stage 6 {np.max(x[left, 0] - m.domain.x_c):.3g} mm (h {h:.3g} mm)")  # fmt: skip
    assert np.max(x[left, 0] - m.domain.x_c) < 0.01 * h
    assert np.max(m.domain.x_c - x[right, 0]) < 0.01 * h
    # The sutured zone stays closed at the surface through the contact stages.
    for k in (4, 5, 6):
        c = m.closure_line.measure(m.displacements[k])
        assert c.closed and c.gap_max_mm < 0.01 * h and c.overlap_mm < 0.01 * h
    assert d6["pin_reaction_max_mN"] < 1e-6 * m.lateral_force()
    if which == "cylinder":  # nothing but the zone meets: no contact force
        assert crossed < 1e-6 * h and d6["contact_force_mN"] < 1e-6 * m.lateral_force()
        return
    assert crossed > 0.05 * h
    # The contact module's own measures agree: shallow, no deep overlap, and the flanks are
    # actually held apart somewhere (a real compressive force).
    assert d6["max_penetration_rel"] < 0.01
    assert d6["n_penetrating"] > 0 and d6["contact_force_mN"] > 0
    # Penetration ~ pressure * h / k_V: it shrinks with 1/k_V (1, 5, 100 GPa) while the force
    # that holds the flanks apart stays the same.
    p4, p5, p6 = (d["max_penetration_mm"] for d in (d4, d5, d6))
    assert p4 / p5 == pytest.approx(5.0, rel=0.2)
    assert p4 / p6 == pytest.approx(100.0, rel=0.2)
    assert d6["contact_force_mN"] == pytest.approx(d4["contact_force_mN"], rel=0.02)


@pytest.mark.parametrize("degree", [1, 2], ids=["P1", "P2"])
def test_contact_at_45_degrees(deep_wedge_mesh, degree) -> None:
    """Oblique fibres: the flanks are no mirror images, contact must still hold them apart."""
    mesh = deep_wedge_mesh if degree == 1 else _p2_mesh("wedge")
    m, outs = _run(mesh, 45.0, skin="stiff", solver=SolverSettings(element_degree=degree))
    assert [o.solve.status for o in outs] == [CONVERGED] * 6
    d6 = outs[5].diagnostics
    assert d6["max_penetration_rel"] < 0.01
    assert d6["n_penetrating"] > 0 and d6["contact_force_mN"] > 0
    assert m.closure_line.measure(m.u).closed
    # Oblique fibres break the mirror symmetry: the two flanks move differently along y.
    uy = m.u.reshape(-1, 3)[:, 1]
    left, right = _flank_nodes(m)
    assert abs(np.mean(uy[left]) - np.mean(uy[right])) > 1e-4


def test_the_zone_tie_carries_nothing_where_the_closure_load_holds(cylinder_mesh) -> None:
    """A symmetric wound that nothing else touches: the closure load alone holds the zone
    where stage 2 closed it, so the tie carries nothing and stages 4-6 keep the stage-2
    state."""
    m, outs = _run(cylinder_mesh, 0.0)
    assert m.tie is not None and len(m.tie) > 0
    closing = float(m.closing_forces[3 * m.domain.zone_left_nodes].sum())
    h = float(np.min(m.contact.passes[0].size_mm))
    for o in outs[3:]:
        assert o.diagnostics["tie_force_mN"] < 1e-6 * closing
        assert o.diagnostics["tie_max_slip_mm"] < 1e-8 * h
    scale = float(np.abs(m.displacements[2]).max())
    assert float(np.abs(m.u - m.displacements[2]).max()) < 1e-6 * scale


def test_the_zone_tie_holds_the_flanks_at_45_degrees(deep_wedge_mesh) -> None:
    """At 45 degrees the tie carries force, its slip stays at the penalty's scale, and the
    stage's potential (tie included) is that of its residual."""
    m, outs = _run(deep_wedge_mesh, 45.0)
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


def test_unconverged_stage_3_does_not_stop_stages_4_to_6(deep_wedge_mesh, monkeypatch) -> None:
    """Stage 4 restarts from stage 2 under the closure load: with stage 3 starved (half its
    load and one Newton step), stages 4-6 run and give the results of a run whose stage 3
    converged."""
    from woundsweep.physics import stages
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.solver.newton import MAX_ITERATIONS

    mats = JobMaterials.table2("stiff", 0.0)
    full = run_stages(WoundModel(deep_wedge_mesh, P1), mats, 6)
    m = WoundModel(deep_wedge_mesh, P1)
    normal = m.settings
    real_run_stage = stages.run_stage

    def starved(model, stage: int):
        if stage != 3:
            model.set_newton_settings(normal)
            return real_run_stage(model, stage)
        starve = dataclasses.replace(normal, max_iterations=1, max_load_cuts=0, path_rtol=0.0)
        model.set_newton_settings(starve)
        load = model.closing_forces
        model.closing_forces = 0.5 * load
        try:
            return real_run_stage(model, stage)
        finally:
            model.closing_forces = load

    monkeypatch.setattr(stages, "run_stage", starved)
    recs = run_stages(m, mats, 6)
    assert [r.result.status for r in recs] == [CONVERGED] * 2 + [MAX_ITERATIONS] + [CONVERGED] * 3
    assert recs[2].displacement_mm is None
    for a, b in zip(full[3:], recs[3:]):
        assert b.result.p99_von_mises_kPa == pytest.approx(a.result.p99_von_mises_kPa, rel=1e-6)
        assert b.result.contact_force_mN == pytest.approx(a.result.contact_force_mN, rel=1e-6)


def test_unconverged_contact_stage_is_recorded_as_such(deep_wedge_mesh, monkeypatch) -> None:
    from woundsweep.physics import stages
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import CONTACT_START_kPa
    from woundsweep.solver.newton import MAX_ITERATIONS

    m = WoundModel(deep_wedge_mesh, P1)
    real_run_stage = stages.run_stage

    def starved(model, stage: int):
        # Stages 1-3 as usual; the contact stages get one Newton step, no load cuts and the
        # full tolerance in every increment.
        if stage == 4:
            st = dataclasses.replace(m.settings, max_iterations=1, max_load_cuts=0, path_rtol=0.0)
            model.set_newton_settings(st)
        return real_run_stage(model, stage)

    monkeypatch.setattr(stages, "run_stage", starved)
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
    k0 = r4.diagnostics["stability_penalty_kPa"]
    assert k0 == pytest.approx(CONTACT_START_kPa)
    np.testing.assert_allclose(m.u, m.displacements[2])
    c = m.contact
    # The stage's forces are those of that state at its penalty, not at the stage's target.
    assert r4.diagnostics["contact_penalty_kPa"] == pytest.approx(k0)
    at_target = c.summary(m.u).contact_force_mN
    c.k_V_kPa = k0
    assert r4.result.contact_force_mN == pytest.approx(c.summary(m.u).contact_force_mN)
    assert r4.result.contact_force_mN != pytest.approx(at_target)
    m.problem.jacobian(m.problem.A)
    ai, aj, av = m.problem.A.getValuesCSR()
    free = np.ones(len(ai) - 1, dtype=bool)
    free[m.domain.gauge_rows()] = False
    D = scipy.sparse.csr_matrix((av, aj, ai)).toarray()[np.ix_(free, free)]
    # Every load of a contact stage is dead, so the tangent is an energy Hessian: symmetric.
    assert np.abs(D - D.T).max() < 1e-10 * np.abs(D).max()
    w = np.linalg.eigvalsh(0.5 * (D + D.T))
    nearest = np.sort(w[np.argsort(np.abs(w))[:3]])[0]
    assert r4.diagnostics["stability_min_eig_mN_per_mm"] == pytest.approx(nearest, rel=1e-6)
    assert nearest > 0.0  # the closed 0-degree wedge is stable at the starting penalty


def test_contact_stage_potential_is_that_of_the_residual(deep_wedge_mesh) -> None:
    """Every load is dead (the closure load is the stage-2 reactions, fixed), so each stage has
    a potential: its directional derivative is R . v (central differences), in stage 3 and in
    a contact stage with the contact and the tie engaged, away from equilibrium."""
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    m = WoundModel(deep_wedge_mesh, P1)
    m.set_materials(JobMaterials.table2("stiff", 45.0))
    for k in (1, 2, 3):
        assert run_stage(m, k).solve.status == CONVERGED
    u = m.u
    rng = np.random.default_rng(1)
    free = np.ones(len(u), dtype=bool)
    free[m.domain.gauge_rows()] = False
    for stage in (3, 4):
        if stage == 4:
            assert run_stage(m, 4).solve.status == CONVERGED
            assert m.contact.k_V_kPa > 0 and m.tie.active
        assert m.problem.energy() is not None
        u_k = u.copy()
        w = np.where(free, rng.standard_normal(len(u)), 0.0)
        v = np.where(free, rng.standard_normal(len(u)), 0.0)
        fd, R = _energy_slope(m, u_k + 1e-4 * w, v, 1e-6)
        u[:] = u_k
        assert abs(R @ v) > 1e-3 * np.linalg.norm(R) * np.linalg.norm(v) / np.sqrt(len(v))
        assert fd == pytest.approx(float(R @ v), rel=1e-5)


def test_contact_stages_5_and_6_start_in_equilibrium(deep_wedge_mesh) -> None:
    """At s = 0, stages 5 and 6 solve exactly the converged state of the stage before: the
    out-of-balance force that the stage releases holds only its convergence residual. (It
    once was computed with contact off, so it held the contact forces as well: a jump of
    tens of mN at the first increment, which failed stage 5 of a 45-degree paper job.)"""
    from woundsweep.physics.loadpath import set_up
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage, stage_recipe

    m = WoundModel(deep_wedge_mesh, P1)
    m.set_materials(JobMaterials.table2("stiff", 0.0))
    for k in range(1, 5):
        assert run_stage(m, k).solve.status == CONVERGED
    u = m.u
    for stage in (5, 6):
        rows = m.domain.gauge_rows()
        ramp = set_up(m, stage_recipe(m, stage))
        scale = ramp.force_scale
        start = ramp.load(0.0)
        r = m.problem.residual_array() - start.offset
        r[rows] = 0.0
        contact = m.contact.force_vector(u)
        contact[rows] = 0.0
        assert np.linalg.norm(contact) > 1e-3 * scale  # the contact forces are there ...
        assert np.linalg.norm(r) <= 1e-12 * scale  # ... and balanced at s = 0
        assert run_stage(m, stage).solve.status == CONVERGED


def test_stage_4_starts_and_ends_stable_on_an_overlapping_wedge() -> None:
    """Paper job 8652's geometry (a 0-degree wedge, width 3, depth 1.5): its Dirichlet-closed
    lower flanks overlap. The sutured zone's nodes are tied, not contact points, so the
    contact's curvature term acts only below the zone: the stage-4 starting state is a minimum
    of the potential at the starting penalty, and the state stage 4 reaches is one at 1 GPa
    with the overlap pushed out."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh
    from woundsweep.physics.loadpath import set_up
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import CONTACT_START_kPa, run_stage, stability, stage_recipe

    spec = GeometrySpec.wedge(1.0, 2.0, 6.0, 3.0, 1.5, 0.7, element_degree=1)
    m = WoundModel(build_mesh(spec), P1)
    m.set_materials(JobMaterials.table2("stiff", 0.0))
    for stage in (1, 2, 3):
        assert run_stage(m, stage).solve.status == CONVERGED
    rows = m.domain.gauge_rows()
    set_up(m, stage_recipe(m, 4))  # the stage-4 start: the stage-2 state, dead closure load
    np.testing.assert_array_equal(m.u, m.displacements[2])
    overlap_start = -float(m.contact.gaps(m.u).min())
    eig_start = stability(m, rows, CONTACT_START_kPa)["stability_min_eig_mN_per_mm"]
    assert eig_start > 0.0
    assert run_stage(m, 4).solve.status == CONVERGED
    eig_end = stability(m, rows, 1e6)["stability_min_eig_mN_per_mm"]
    overlap_end = -float(m.contact.gaps(m.u).min())
    print(f"\nlowest eigenvalue: {eig_start:.4g} mN/mm at the start ({CONTACT_START_kPa} kPa), "
          f"{eig_end:.4g} at the end (1 GPa); overlap {overlap_start:.3g} -> {overlap_end:.3g} mm")  # fmt: skip
    assert eig_end > 0.0
    assert overlap_start > 0.05 and overlap_end < 1e-3 * overlap_start


@pytest.mark.fem
def test_a_wedge_whose_points_slide_off_the_other_flank_goes_through_stage_4() -> None:
    """Paper job 6708 (stiff skin, a 0-degree wedge, t_d = 0.5, width 1, depth 0.5, m = 0.7,
    P2): contact points at the wedge's lower edge slide past the other flank's edge into the
    support's fade. With the fade following the state the energy is concave there and Newton
    cycled until its budget ran out; with the support held per solve stage 4 converges in a
    few dozen steps, and the state it reaches is solved with the support it has."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.config.solver import SolverSettings
    from woundsweep.mesh.build import build_mesh
    from woundsweep.physics.loadpath import SUPPORT_TOL, set_up, settle_support
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage, stage_recipe

    spec = dataclasses.replace(GeometrySpec.wedge(0.5, 0.5, 2.0, 1.0, 0.5, 0.7), element_degree=2)
    m = WoundModel(build_mesh(spec), SolverSettings(element_degree=2))
    m.set_materials(JobMaterials.table2("stiff", 0.0))
    for stage in range(1, 7):
        out = run_stage(m, stage)
        assert out.solve.status == CONVERGED, stage
        if stage >= 4:
            assert m.contact.support_change(m.u) <= SUPPORT_TOL
    assert m.results[4].solve.iterations <= 40
    # A state solved with another support than its own is solved again until it is not.
    c = m.contact
    engaged = c.gaps(m.u) <= 0.0
    c._frozen[engaged] *= 0.5
    assert c.support_change(m.u) >= 0.5
    res = settle_support(m, m.results[6].solve, set_up(m, stage_recipe(m, 6)))
    assert res.status == CONVERGED and c.support_change(m.u) <= SUPPORT_TOL
    assert res.iterations > m.results[6].solve.iterations

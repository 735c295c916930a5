"""The closing loads of stages 3-6 (`StageSettings.closure_load`) against independent answers:
the traction's nodal forces against the zone's projected area, the published code's amplitude
against its rule on a homogeneous state, the solved amplitude closing a symmetric slot."""

from __future__ import annotations

import numpy as np
import pytest

from woundsweep.config.paper import StageSettings
from woundsweep.config.solver import SolverSettings

pytestmark = pytest.mark.fem

P1 = SolverSettings(element_degree=1)
# The cylinder of `cylinder_mesh`: L = 4, width 1.2, aspect 0 (a half-round slot of depth 0.6),
# t_d = 1; the default zone spans |y| <= 4/3 and 0.3 below the surface.
ZONE_PROJECTED_AREA = (2 * 4.0 / 3.0) * 0.3


def test_unit_traction_on_the_zone_pulls_each_flank_with_its_projected_area(cylinder_mesh):
    """A unit closing traction acts as |n_x| dA along x: each flank's total is the area of
    the zone's projection on the mid-plane, toward it (+x on the left, -x on the right)."""
    from woundsweep.physics.closing import dermal_zone_facets, traction_shape
    from woundsweep.physics.domain import dof_rows
    from woundsweep.physics.model import WoundModel

    d = WoundModel(cylinder_mesh, P1).domain
    f = traction_shape(d, dermal_zone_facets(d))
    left, right = dof_rows(d.zone_left_nodes, 0), dof_rows(d.zone_right_nodes, 0)
    assert f[left].sum() == pytest.approx(ZONE_PROJECTED_AREA, rel=1e-9)
    assert f[right].sum() == pytest.approx(-ZONE_PROJECTED_AREA, rel=1e-9)
    # x only, and nothing outside the zone.
    assert not f.reshape(-1, 3)[:, 1:].any()
    outside = np.setdiff1d(np.arange(len(d.X)), d.zone_nodes)
    assert not f.reshape(-1, 3)[outside].any()


def test_code_amplitude_on_a_homogeneous_state_is_its_rule(cylinder_mesh):
    """At the homogeneous pre-stretched state every sampled P_xx is the dermis' P_xx: the
    published code's amplitude is 1.3 * 1.4 times it."""
    from woundsweep.physics.closing import code_traction_kPa
    from woundsweep.physics.materials import JobMaterials, first_piola, homogeneous_state
    from woundsweep.physics.model import WoundModel

    m = WoundModel(cylinder_mesh, P1, StageSettings(closure_load="paper-code"))
    materials = JobMaterials.table2("stiff", 45.0)
    m.set_materials(materials)
    m.u[:] = m.pretension_state().ravel()
    lam3 = homogeneous_state(materials.dermis, materials.tsf).lambda3
    F = np.diag([materials.tsf, materials.tsf, lam3])
    P_xx = first_piola(materials.dermis, F)[0, 0]
    assert code_traction_kPa(m.domain, m.u, materials) == pytest.approx(1.82 * P_xx, rel=1e-9)


def test_code_traction_region_is_the_upper_middle_of_the_wound(cylinder_mesh):
    """The published code's region: |y| < L/2 and less than w below the surface; on the
    half-round slot (depth 0.6 < w) the whole depth of the middle half."""
    from woundsweep.physics.closing import code_traction_facets, surface_width, traction_shape
    from woundsweep.physics.model import WoundModel

    d = WoundModel(cylinder_mesh, P1).domain
    assert surface_width(d) == pytest.approx(1.2, rel=1e-12)
    tri = code_traction_facets(d)
    c = d.X[tri].mean(axis=1)
    assert np.all(np.abs(c[:, 1]) < 2.0) and len(tri) > 0
    f = traction_shape(d, tri).reshape(-1, 3)[:, 0]
    # The projected area of the left flank's part (facets chosen by centroid: the region's
    # ends follow the mesh, within one facet of |y| = 2).
    assert f[f > 0].sum() == pytest.approx(0.6 * 4.0, rel=0.05)


def test_solved_amplitude_closes_a_symmetric_slot(cylinder_mesh):
    """The solved closure's amplitude puts the zone's median surface gap at zero (within
    1e-6 w) with the Dirichlet condition released, and is stored per stage."""
    from woundsweep.physics.job import run_stages
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel

    m = WoundModel(cylinder_mesh, P1, StageSettings(closure_load="solved"))
    recs = run_stages(m, JobMaterials.table2("normal", 0.0), 3)
    assert [r.result.status for r in recs] == ["converged"] * 3
    r3 = recs[2].result
    w = 1.2
    assert abs(r3.closure_gap_median_mm) <= 1e-6 * w
    amp = recs[2].diagnostics["closing_traction_kPa"]
    assert amp > 0 and 1 <= recs[2].diagnostics["closing_amplitude_solves"] <= 12
    # Stage 3 is not stage 2: the load is not the Dirichlet closure's reactions.
    assert r3.closure_gap_max_mm > 0.01 * w
    # Its total pull is of the Dirichlet closure's order.
    pull = recs[1].diagnostics["closure_force_left_mN"]
    assert 0.3 < amp * ZONE_PROJECTED_AREA / pull < 3.0


def test_closures_start_stage_4_where_they_say(cylinder_mesh):
    """Stage 4 starts from stage 2 (reactions, tied), stage 1 (paper-code) or stage 3 (solved);
    only the reactions tie the zone."""
    from woundsweep.core.schema import start_stage
    from woundsweep.physics.model import WoundModel

    assert [start_stage(4, c) for c in ("reactions", "paper-code", "solved")] == [2, 1, 3]
    for closure, tied in (("reactions", True), ("paper-code", False), ("solved", False)):
        m = WoundModel(cylinder_mesh, P1, StageSettings(closure_load=closure))
        assert (m.tie is not None) is tied


def test_amplitude_steps_bracket_the_closed_gap():
    """The amplitude's next value: 10 % the way the gap asks first, then a secant step, kept
    inside a known bracket."""
    from woundsweep.physics.stages import _next_amplitude

    assert _next_amplitude([(10.0, 0.5)]) == pytest.approx(11.0)
    assert _next_amplitude([(10.0, -0.5)]) == pytest.approx(9.0)
    # A linear gap g = 1 - a / 20 is closed at a = 20: the secant lands on it.
    g = lambda a: 1.0 - a / 20.0  # noqa: E731
    assert _next_amplitude([(10.0, g(10.0)), (11.0, g(11.0))]) == pytest.approx(20.0)
    # A secant that leaves the bracket [12, 13.5] gives way to its midpoint.
    assert _next_amplitude([(12.0, 0.1), (14.0, -0.1), (13.5, -0.09)]) == pytest.approx(12.75)


def test_unknown_closure_is_refused():
    with pytest.raises(ValueError, match="closure_load 'sutures'"):
        StageSettings(closure_load="sutures")

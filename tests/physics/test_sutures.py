"""Sutures on the fusiform excision: the plan's positions, the load's gradient, the case's
checks, the evened placement (closed forms), and on a small wound the sutured closure (force
balance against the Dirichlet closure it replaces, closure measures, the load after closure)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from woundsweep.config.case import ClinicalCase
from woundsweep.config.sutures import CaseError, ItchLoad, SuturePlan
from woundsweep.studies.case import even_positions

# -- the plan -----------------------------------------------------------------------------------


def test_positions_by_count_spacing_and_list() -> None:
    assert SuturePlan(count=3).positions(20.0) == pytest.approx((-5.0, 0.0, 5.0))
    # Spacing = bite width (3 mm) by default: ceil(20 / 3) - 1 = 6 sutures, centred.
    assert SuturePlan().positions(20.0) == pytest.approx((-7.5, -4.5, -1.5, 1.5, 4.5, 7.5))
    assert SuturePlan(spacing_mm=5.0).positions(20.0) == pytest.approx((-5.0, 0.0, 5.0))
    assert SuturePlan(positions_mm=(-2.0, 3.0)).positions(20.0) == (-2.0, 3.0)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"count": 0},
        {"count": 2, "spacing_mm": 3.0},
        {"spacing_mm": -1.0},
        {"bite_width_mm": math.nan},
        {"bite_depth_mm": 0.0},
        {"count": True},
    ],
)
def test_bad_plans_are_refused(kwargs: dict) -> None:
    with pytest.raises(CaseError):
        SuturePlan(**kwargs)


def test_positions_outside_the_wound_are_refused() -> None:
    with pytest.raises(CaseError, match="within the wound"):
        SuturePlan(positions_mm=(0.0, 10.0)).positions(20.0)
    with pytest.raises(CaseError, match="no suture"):
        SuturePlan(spacing_mm=30.0).positions(20.0)


def test_stretch_across_the_langer_line() -> None:
    # A wound along the Langer line (orientation 90: the line along y): a stretch across it
    # (90 degrees to the line) is along x.
    E = np.array(ItchLoad(0.1, 90.0, "stretch").gradient(90.0))
    assert E == pytest.approx(np.array([[0.1, 0.0], [0.0, 0.0]]), abs=1e-12)
    # At orientation 65 (25 degrees to the line), a stretch along the line: E n = 0.1 n.
    E = np.array(ItchLoad(0.1, 0.0, "stretch").gradient(65.0))
    n = np.array([math.cos(math.radians(65)), math.sin(math.radians(65))])
    assert E @ n == pytest.approx(0.1 * n)
    assert E @ np.array([-n[1], n[0]]) == pytest.approx([0.0, 0.0], abs=1e-12)


def test_shear_is_symmetric_and_traceless() -> None:
    E = np.array(ItchLoad(0.2, 30.0, "shear").gradient(10.0))
    assert E == pytest.approx(E.T)
    assert np.trace(E) == pytest.approx(0.0, abs=1e-12)
    # Engineering shear 0.2 between n and m: m . E n = 0.1.
    phi = math.radians(40.0)
    n = np.array([math.cos(phi), math.sin(phi)])
    m = np.array([-n[1], n[0]])
    assert m @ E @ n == pytest.approx(0.1)


@pytest.mark.parametrize(
    "kwargs", [{"strain": -0.1}, {"strain": 0.6}, {"angle_to_langer_deg": 200}, {"kind": "twist"}]
)
def test_bad_loads_are_refused(kwargs: dict) -> None:
    with pytest.raises(CaseError):
        ItchLoad(**kwargs)


# -- the case -----------------------------------------------------------------------------------


def test_case_angle_and_defaults() -> None:
    c = ClinicalCase(length_mm=20.0, angle_deg=25.0)
    assert c.orientation_deg == 65.0  # docs/model.md: orientation = 90 - angle
    assert c.width == pytest.approx(20 / 3)
    assert (c.dermis, c.subcutis) == (2.5, 5.0)  # the upper back's preset
    assert c.depth == pytest.approx(2.5 + 0.25 * 5.0)
    spec = c.geometry()
    assert spec.shape == "fusiform" and spec.wound_length_mm == 20.0
    assert spec.patch_half_length_mm == pytest.approx(2.7 * 20.0)
    assert spec.zone_depth_fraction == pytest.approx(2.5 / 3.75)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"angle_deg": 95.0},
        {"width_mm": 25.0},
        {"site": "moon"},
        {"skin_type": "leather"},
        {"depth_mm": 2.0},  # within the dermis
        {"depth_mm": 8.0},  # through the patch
        {"mesh_size_factor": 0.0},
        {"element_degree": 3},
        {"sutures": SuturePlan(bite_depth_mm=3.5)},  # below the walls' reach
        {"length_mm": math.inf},
    ],
)
def test_bad_cases_are_refused(kwargs: dict) -> None:
    with pytest.raises(CaseError):
        ClinicalCase(**kwargs)


# -- the evened placement -----------------------------------------------------------------------


def test_even_positions_keep_an_even_load_where_it_is() -> None:
    # Equal forces on equal stretches: the placement is already even.
    ys = np.array([-7.5, -4.5, -1.5, 1.5, 4.5, 7.5])
    new = even_positions(ys, np.full(6, 10.0), 9.0, 0.0)
    # Stretches [-9,-6], [-6,-3], ... each hold 10: quantiles at their centres.
    assert new == pytest.approx(ys)


def test_even_positions_crowd_where_the_load_is() -> None:
    # Two sutures at -5 and 5 on [-10, 10]; the left carries 3 times the right: the load per
    # length is 30/10 on [-10, 0] and 10/10 on [0, 10]; quantiles 1/4 and 3/4 of the 40 total
    # lie at y = -10 + 10/3 and at 0 + 10 * (30 - 30) / 10 = 0.
    new = even_positions(np.array([-5.0, 5.0]), np.array([30.0, 10.0]), 10.0, 0.0)
    assert new == pytest.approx([-10 + 10 / 3, 0.0])
    # The end margin keeps them off the apices.
    assert even_positions(np.array([-5.0, 5.0]), np.array([1e6, 1.0]), 10.0, 3.0)[0] >= -7.0


# -- on a small wound ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def closure():
    from small_wound import small_closure

    from woundsweep.physics.materials import JobMaterials

    sc, case = small_closure()
    steps = sc.close(JobMaterials.table2("normal", 90.0), 90.0)
    assert [s.status for s in steps] == ["converged", "converged"]
    return sc, case


@pytest.mark.fem
def test_sutures_hold_what_the_dirichlet_closure_held(closure) -> None:
    sc, case = closure
    step = sc.suture(case.sutures)
    assert step.status == "converged"
    st = step.state
    f = st.suture_force_mN
    assert len(f) == 3 and np.all(f > 0)
    # Balance: the tied sutures carry the pull their footprints' Dirichlet condition carried
    # (the contact takes over only where the walls between the sutures touch again).
    assert f.sum() == pytest.approx(sc.dirichlet_force_mN.sum(), rel=0.05)
    # And each the share of the whole zone's stage-2 pull its footprint held: the three
    # footprints cover most of the zone, so the total is close to the stage-2 pull.
    stage2 = sc.model.results[2].diagnostics["closure_force_left_mN"]
    assert 0.8 * stage2 < f.sum() < 1.05 * stage2
    # The centre suture carries most (the wound is widest there), the ends alike.
    assert f[1] > f[0] and f[0] == pytest.approx(f[2], rel=1e-3)
    # Closed under and between the sutures (the median gap); beyond the last suture the
    # walls toward the apices stand open, and that is the widest gap.
    assert st.closure.gap_median_per_w < 0.001
    widest = abs(st.gap_y_mm[np.argmax(st.gap_mm)])
    assert widest > 2.25 and st.closure.gap_max_mm > 0.01 * st.closure.width_mm
    assert st.dog_ear_height_mm > 0


@pytest.mark.fem
def test_the_load_after_closure_raises_every_suture_force(closure) -> None:
    sc, case = closure
    before = sc.suture(case.sutures).state.suture_force_mN
    steps = sc.itch(ItchLoad(0.1, 90.0), steps=2)
    assert [s.status for s in steps] == ["converged", "converged"]
    f1, f2 = (s.state.suture_force_mN for s in steps)
    assert np.all(f1 > before) and np.all(f2 > f1)


@pytest.mark.fem
def test_shares_blend_halfway_between_sutures() -> None:
    from woundsweep.physics.sutures import BLEND_mm, SuturedClosure

    ys = (-3.0, 0.0, 3.0)
    y = np.array([-3.0, -1.5, -1.5 + BLEND_mm / 4, -1.5 + BLEND_mm, 0.2, 4.0])
    W = SuturedClosure.shares(y, ys)
    assert W.sum(axis=1) == pytest.approx(np.ones(len(y)))
    assert W[0] == pytest.approx([1, 0, 0])
    assert W[1] == pytest.approx([0.5, 0.5, 0])  # halfway: half each
    # A quarter of the band past halfway: |y - y_j| - |y - y_i| = BLEND / 2, so 3/4 for i.
    assert W[2] == pytest.approx([0.25, 0.75, 0])
    assert W[3] == pytest.approx([0, 1, 0])
    assert W[4] == pytest.approx([0, 1, 0]) and W[5] == pytest.approx([0, 0, 1])

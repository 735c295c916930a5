"""Sutures as threads (`woundsweep.physics.thread`, `SuturedClosure.thread`): the slit closed
by threads against its closed form, a thread's pull on its flank, the tension's independence
of the thread's stiffness, and the tying rule that pulls every knot with one tension until
the walls meet under every suture."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from woundsweep.physics.thread import NYLON_4_0

pytestmark = pytest.mark.fem


# -- the slit in closed form (woundsweep.verify.threads) ------------------------------------


@pytest.fixture(scope="module")
def slit():
    from woundsweep.verify.threads import slit_threads

    return {n: slit_threads(n, degree=1, grid=4) for n in (1, 2)}


def test_threads_carry_the_slits_closed_form_force(slit) -> None:
    for r in slit.values():
        # Equilibrium of a half: the threads (and what the gauge pins pass) carry f L.
        assert r.total_pull_mN + r.pin_transfer_mN == pytest.approx(r.expected_total_mN, rel=1e-5)
        assert r.total_pull_mN == pytest.approx(r.expected_total_mN, rel=0.03)
        # Evenly spaced on a translation-invariant slit: each its share f L / n.
        assert 2 * r.tension_mN == pytest.approx(np.full(r.sutures, r.expected_pull_mN), rel=0.05)
    assert slit[2].tension_mN[0] == pytest.approx(slit[2].tension_mN[1], rel=1e-6)


def test_more_threads_bring_the_slit_closer_to_the_homogeneous_state(slit) -> None:
    assert slit[2].misfit_far < 0.75 * slit[1].misfit_far


# -- threads on a wound ---------------------------------------------------------------------


def _small_wound():
    from small_wound import small_closure

    from woundsweep.physics.materials import JobMaterials

    sc, case = small_closure()
    steps = sc.close(JobMaterials.table2("normal", 90.0), 90.0)
    assert [s.status for s in steps] == ["converged", "converged"]
    return sc, case


@pytest.fixture(scope="module")
def tied():
    sc, case = _small_wound()
    step = sc.thread(case.sutures, radius_mm=0.75)
    assert step.status == "converged"
    return sc, case, step.state, sc.bite_pressure()


def test_a_thread_pulls_its_flank_with_twice_its_tension(tied) -> None:
    sc, case, st, _ = tied
    T = st.suture_force_mN
    assert len(T) == 3 and np.all(T > 0)
    assert T[0] == pytest.approx(T[2], rel=1e-3)  # a mirror-symmetric placement
    assert sc.thread_pull() == pytest.approx(2 * T, rel=0.05)
    r = sc.model.problem.residual_array()
    free = np.setdiff1d(np.arange(len(r)), sc.domain.gauge_rows())
    assert np.abs(r[free]).max() < 1e-6 * float(T.max())
    # Tied at the length the loops have with the edges held together, the bites' tissue
    # springs back: the threads hold less than the Dirichlet closure pulled, and the edges
    # part at the sutures.
    assert np.all(sc.thread_pull() < sc.apposition_forces(st.suture_y_mm))
    assert np.all(sc.gaps_at_sutures() > 0.3)


def test_the_tension_does_not_depend_on_the_threads_stiffness(tied) -> None:
    sc, case, st, _ = tied
    stiffer = dataclasses.replace(NYLON_4_0, modulus_kPa=10 * NYLON_4_0.modulus_kPa)
    again = sc.thread(case.sutures, material=stiffer, radius_mm=0.75)
    assert again.status == "converged"
    assert again.state.suture_force_mN == pytest.approx(st.suture_force_mN, rel=0.01)


def test_the_knots_are_pulled_with_one_tension_until_the_edges_meet(tied) -> None:
    from woundsweep.physics.sutures import AIM, AIM_TOLERANCE

    sc, case, untightened, loose_bites = tied
    step = sc.thread(case.sutures, radius_mm=0.75, apposed_gap_mm=0.1)
    assert step.status == "converged"
    # The walls meet under every suture, the widest of their closest approaches at the aim:
    # apposed, not crushed.
    approach = sc.approach_at_sutures()
    assert abs(approach.max() - AIM * 0.1) <= AIM_TOLERANCE * 0.1 + 1e-12
    T = step.state.suture_force_mN
    assert T == pytest.approx(np.full(3, sc.knot_tension_mN), rel=1e-6)  # held at one pull
    assert np.all(T > untightened.suture_force_mN)
    assert np.all(sc.shortening_mm > 0)
    assert sc.shortening_mm[0] == pytest.approx(sc.shortening_mm[2], rel=1e-3)
    # Drawn tighter, the threads press harder on the tissue under their bites, the end
    # sutures' alike.
    bites = sc.bite_pressure()
    assert np.all(loose_bites > 0) and np.all(bites > loose_bites)
    assert bites[0] == pytest.approx(bites[2], rel=1e-3)

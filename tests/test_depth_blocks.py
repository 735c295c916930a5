"""The two-block known-answer problem of test_contact_blocks with the material-depth model.

Same blocks, load and stages (see that module). With `woundsweep.depth.DepthContact` the depth
phi of a point of R in L is measured in L's reference configuration; in the homogeneous state
F = diag(l_x, l_t, l_t) the deformed overlap is d = l_x phi and grad_x phi = e_x / l_x, so a
contact point carries the force c phi / l_x, c = k_V A_q / (2 h) per pass. Both passes see the
overlap, so the pressure per reference area is p = k_V phi / (h l_x) and

    d = l_x phi = p h l_x^2 / k_V,

which shrinks like 1 / k_V. Inside the engagement ramp of `WOUND_OPTIONS` (p below engage_kPa)
phi solves r(phi) = p h l_x / k_V instead; r depends on k_V phi only, so d still shrinks like
1 / k_V. The total contact force balances the load p A.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from test_contact_blocks import (
    AREA_MM2,
    DEPTH_PRELOAD_MM,
    K_V_GPA,
    N_BOX,
    PRESSURE_KPA,
    solve_blocks,
    uniaxial_state,
)

from woundsweep.contact import GPA_TO_KPA
from woundsweep.depth import WOUND_OPTIONS
from woundsweep.materials import Fung

pytestmark = pytest.mark.fem


@pytest.fixture(scope="module", autouse=True)
def _release_solutions():
    yield
    solve_blocks.cache_clear()


@pytest.fixture(scope="module", params=[N_BOX, N_BOX + 1], ids=["matching", "non-matching"])
def solved(request) -> dict[str, Any]:
    return solve_blocks(request.param, "depth")


@pytest.fixture(scope="module")
def matching() -> dict[str, Any]:
    return solve_blocks(N_BOX, "depth")


def test_preloaded_start_engages_every_contact_point(solved) -> None:
    # R pushed rigidly by DEPTH_PRELOAD_MM into L: every point of both passes at that depth.
    prob, start = solved["prob"], solved["start"]
    n_facets = sum(len(f) for f in prob.contact.facets)
    assert len(start.depth) == 6 * n_facets
    np.testing.assert_allclose(start.depth, DEPTH_PRELOAD_MM, rtol=1e-6)


@pytest.mark.parametrize("k_gpa", K_V_GPA)
def test_contact_force_balances_the_load(solved, k_gpa: float) -> None:
    run = solved["runs"][k_gpa]
    assert run.status == "converged"
    load = PRESSURE_KPA * AREA_MM2
    s = run.summary
    assert abs(s.contact_force_mN - load) / load < 0.01
    assert s.max_penetration_mm > 0
    assert s.n_deep == 0
    assert abs(abs(run.reaction_x_mN) - load) / load < 0.01


def test_penetration_shrinks_like_one_over_k_V(solved) -> None:
    pen = {k: run.summary.max_penetration_mm for k, run in solved["runs"].items()}
    for k in K_V_GPA[1:]:
        ratio = pen[K_V_GPA[0]] / pen[k]
        assert ratio == pytest.approx(k / K_V_GPA[0], rel=0.2), (k, ratio)


@pytest.mark.parametrize("k_gpa", K_V_GPA)
def test_matching_faces_overlap_is_p_h_lx2_over_k_V(matching, k_gpa: float) -> None:
    # Each point carries c r(phi) / l_x, so p = k_V r(phi) / (h l_x): r(phi) = rho = p h l_x /
    # k_V. Without the engagement ramp (or above delta) phi = rho and d = l_x phi = p h l_x^2 /
    # k_V; inside it, delta t^2 (2 - t) = rho with phi = t delta, delta = engage h / k_V.
    from scipy.optimize import brentq

    s = matching["runs"][k_gpa].summary
    lx, _ = uniaxial_state(Fung.normal(0.0), PRESSURE_KPA)
    h = float(np.sqrt(4.0 * (0.5 / N_BOX**2) / np.sqrt(3.0)))
    k_V = k_gpa * GPA_TO_KPA
    rho = PRESSURE_KPA * h * lx / k_V
    delta = WOUND_OPTIONS["engage_kPa"] * h / k_V
    if rho < delta:
        phi = delta * brentq(lambda t: t * t * (2.0 - t) - rho / delta, 0.0, 1.0, xtol=1e-15)
    else:
        phi = rho
    assert s.max_penetration_mm == pytest.approx(lx * phi, rel=0.01)
    assert s.n_penetrating == 2 * 6 * 2 * N_BOX**2  # 2 passes, 6 points, 2 n^2 facets


def test_matching_faces_solution_is_the_homogeneous_uniaxial_state(matching) -> None:
    """Up to the overlap d: a point of R at depth phi in L pushes on all four nodes of its
    cell, the inner one with weight lam ~ phi / h, so the solution departs from the
    homogeneous state by O(d) (measured: 0.3 d), which vanishes like 1 / k_V."""
    prob = matching["prob"]
    lx, lt = uniaxial_state(Fung.normal(0.0), PRESSURE_KPA)
    X = prob.X
    for k, run in matching["runs"].items():
        exact = np.c_[(lx - 1.0) * (X[:, 0] + 1.0), (lt - 1.0) * X[:, 1], (lt - 1.0) * X[:, 2]]
        exact[prob.in_right, 0] -= run.summary.max_penetration_mm
        err = np.abs(run.u.reshape(-1, 3) - exact).max()
        assert err < 0.5 * run.summary.max_penetration_mm, (k, err)

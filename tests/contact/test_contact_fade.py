"""The contact summary's engaged points in the support's fade (`FlankContact.summary`).

Two 4 x 4 squares pressed 0.02 into each other. Matching, every engaged point's master lies
under its whole kernel or its edge (t >= 1/4 > 0.05): no point is in the fade. With the right
square slid by 0.93 along y, the overlap's rim has points past the other square's edge whose
support step is strictly between 0 and 1: the four corners of the overlap strip (two per
square). Every gap is -0.02, so a point's force is c s^2 0.02 and the fade's share is below its
share of the engaged points.
"""

from __future__ import annotations

import numpy as np
import pytest
from contact_surfaces import make_contact, two_squares


def _pressed(slide_mm: float):
    X, left, right, rnodes = two_squares(4, 4)
    X[rnodes, 1] += slide_mm
    c = make_contact(X, left, right)
    U = np.zeros_like(X)
    U[rnodes, 0] = -0.02
    return c, U.ravel()


def test_matching_squares_have_no_point_in_the_fade() -> None:
    c, u = _pressed(0.0)
    s = c.summary(u)
    assert s.n_penetrating == 2 * 25 and s.contact_force_mN > 0
    assert s.n_fade_points == 0 and s.fade_force_share == 0.0


def test_points_past_the_masters_edge_are_counted_with_their_force_share() -> None:
    c, u = _pressed(0.93)
    s = c.summary(u)
    mu = c.penalty_multipliers(u)
    n_engaged = int(np.count_nonzero(mu < 0))
    assert s.n_fade_points == 4 and n_engaged == s.n_penetrating + 4
    # Faded points carry c s^2 (-g) with s < 1: less than their share of the points.
    assert 0.0 < s.fade_force_share < s.n_fade_points / n_engaged
    # The held support at this state is the state's own: the same summary.
    c.freeze_support(u)
    assert c.summary(u) == s
    # The share is the penalty's ratio of forces: the same at k_V = 0 (no force at all).
    c.k_V_kPa = 0.0
    assert c.summary(u).fade_force_share == pytest.approx(s.fade_force_share, rel=1e-12)

"""Line loads along the wound are binned symmetrically: a wound symmetric about its mid-line
gives a symmetric profile even where nodes lie on bin edges (`physics.closure.ClosureLine`)."""

from __future__ import annotations

import numpy as np
import pytest

from woundsweep.physics.closure import ClosureLine

W = 2.0
YS = np.linspace(-1.0, 1.0, 21)  # 5 bins of 4 spacings: nodes at +-0.2 and +-0.6 on bin edges


def _slot() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts, pairs = [], []
    for y in YS:
        for z in (0.0, -0.5):
            pairs.append((len(pts), len(pts) + 1))
            pts += [(-W / 2, y, z), (W / 2, y, z)]
    pairs_a = np.array(pairs)
    return np.array(pts), pairs_a, pairs_a[:, 0]


def test_a_symmetric_load_gives_a_symmetric_profile() -> None:
    """Concentrated forces at the zone's ends (y = +-0.6, on bin edges) and a lopsided-looking
    but symmetric spread elsewhere: every bin equals its mirror bin, and the forces add up."""
    X, pairs, left = _slot()
    line = ClosureLine(X, pairs, left, z_top=0.0)
    assert np.allclose(line.edges, -line.edges[::-1])
    y = X[left, 1]
    on_edge = np.isclose(y[:, None], line.edges[1:-1][None, :]).any(axis=1)
    assert on_edge.any()  # the case that a one-sided rule gets wrong
    fx = 1.0 + y**2 + np.where(np.isclose(np.abs(y), 0.6), 20.0, 0.0)
    f = np.zeros(X.size)
    f[3 * left] = fx
    loads = line.line_loads(f, None)
    profile = loads.closing_mN_per_mm
    assert np.allclose(profile, profile[::-1], rtol=1e-12)
    assert np.allclose(loads.y_mm, -loads.y_mm[::-1])
    assert np.sum(profile * np.diff(line.edges)) == pytest.approx(fx.sum(), rel=1e-12)


def test_an_asymmetric_load_stays_asymmetric() -> None:
    """The symmetric binning does not symmetrise the data: a force on one side only reads
    on that side only."""
    X, pairs, left = _slot()
    line = ClosureLine(X, pairs, left, z_top=0.0)
    f = np.zeros(X.size)
    f[3 * left] = np.where(X[left, 1] > 0.3, 1.0, 0.0)
    profile = line.line_loads(f, None).closing_mN_per_mm
    assert profile[0] == 0.0 and profile[1] == 0.0 and profile[-1] > 0.0

"""Material-depth contact (woundsweep.depth) on two blocks, numpy only: depths, forces, tangent.

L = [-1, 0] x [0, 1]^2 and R = [0, 1] x [0, 1]^2 with disjoint nodes touch on x = 0; the contact
surface is the two x = 0 faces. Pushing R rigidly by -d along x makes every contact point of
each block sit at material depth d in the other block (the depth field of a flat face is
exactly linear, which P1 represents), so the forces are known in closed form.
"""

from __future__ import annotations

import numpy as np
import pytest
from box_mesh import boundary_facets, box_tets

from woundsweep.depth import DepthContact, material_depth

K_V = 1.0e6  # kPa


def blocks(n: int = 2, m: int = 3, **kw) -> tuple[DepthContact, np.ndarray, int]:
    """Contact of L (n^3 grid boxes) and R (n x m x m: non-matching faces)."""
    pL, cL = box_tets(n, (-1.0, 0.0, 0.0), (0.0, 1.0, 1.0))
    pR, cR = box_tets((n, m, m), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    X = np.vstack([pL, pR])
    cells = np.vstack([cL, cR + len(pL)])
    side = np.r_[np.zeros(len(cL), bool), np.ones(len(cR), bool)]
    bf = boundary_facets(cells)
    surface = bf[np.abs(X[bf].mean(axis=1)[:, 0]) < 1e-12]
    c = DepthContact(X, cells, side, surface, max_depth_mm=0.5, **kw)
    c.k_V_kPa = K_V
    return c, X, len(pL)


def shift_right(X: np.ndarray, nL: int, d: float) -> np.ndarray:
    u = np.zeros_like(X)
    u[nL:, 0] = -d
    return u.ravel()


def test_material_depth_of_a_square() -> None:
    # The unit square z = 0 (two triangles): above it the distance is |z|, beside it the
    # distance to the nearest edge.
    X = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [0.3, 0.6, -0.2], [1.5, 0.5, 0.0], [2.0, 2.0, 1.0]], dtype=float)  # fmt: skip
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    d = material_depth(X, np.arange(7), tri)
    np.testing.assert_allclose(d, [0, 0, 0, 0, 0.2, 0.5, np.sqrt(3.0)], atol=1e-15)


def test_touching_start_engages_every_point_without_force() -> None:
    c, X, nL = blocks()
    st = c.state(np.zeros(X.size))
    assert len(st.depth) == sum(6 * len(f) for f in c.facets)
    np.testing.assert_allclose(st.depth, 0.0, atol=1e-15)
    np.testing.assert_allclose(c.force_vector(np.zeros(X.size)), 0.0, atol=1e-12)


def test_separated_blocks_carry_no_contact() -> None:
    c, X, nL = blocks()
    u = shift_right(X, nL, -0.01)  # a gap of 0.01 mm
    assert len(c.state(u).depth) == 0
    assert c.summary(u).n_penetrating == 0


@pytest.mark.parametrize("smooth", [False, True])
def test_rigid_overlap_force_is_k_d_area_over_h(smooth: bool) -> None:
    # Every point of both passes at depth d, grad phi = -+e_x: each pass pushes R by
    # sum_q c_q d = (1/2) k_V d sum_q A_q / h_q; the faces' facets have one size per block.
    d = 1e-3
    c, X, nL = blocks(smooth_normal=smooth)
    u = shift_right(X, nL, d)
    st = c.state(u)
    np.testing.assert_allclose(st.depth, d, rtol=1e-12)
    f = -c.force_vector(u).reshape(-1, 3)  # force on the nodes = - residual
    expected = sum(0.5 * K_V * d * 1.0 / p.size_mm[0] for p in c.points)
    assert f[nL:, 0].sum() == pytest.approx(expected, rel=1e-12)
    assert f[:nL, 0].sum() == pytest.approx(-expected, rel=1e-12)
    np.testing.assert_allclose(f[:, 1:].sum(axis=0), 0.0, atol=1e-9 * expected)
    s = c.summary(u)
    assert s.max_penetration_mm == pytest.approx(d, rel=1e-12)
    assert s.contact_force_mN == pytest.approx(expected, rel=1e-12)  # both passes: the load


def _perturbed(seed: int) -> tuple[DepthContact, np.ndarray]:
    c, X, nL = blocks(smooth_normal=True)
    rng = np.random.default_rng(seed)
    u = shift_right(X, nL, 2e-3) + 2e-4 * rng.standard_normal(X.size)
    return c, u


def test_force_is_the_energy_gradient() -> None:
    c, u = _perturbed(0)
    c.smooth_normal = False
    dv = np.random.default_rng(1).standard_normal(u.size) * 1e-7
    de = c.energy(u + dv) - c.energy(u - dv)
    assert de == pytest.approx(2.0 * c.force_vector(u) @ dv, rel=1e-6)


@pytest.mark.parametrize("smooth", [False, True])
def test_tangent_is_the_force_derivative(smooth: bool) -> None:
    # Exact for the depth gradient; with smoothed normals, exact while they are frozen.
    c, u = _perturbed(2)
    c.smooth_normal = smooth
    c.freeze(u)
    K = c.tangent_csr(u)
    dv = np.random.default_rng(3).standard_normal(u.size) * 1e-7
    fd = (c.force_vector(u + dv) - c.force_vector(u - dv)) / 2.0
    assert np.linalg.norm(K @ dv - fd) < 1e-6 * np.linalg.norm(fd)
    if smooth:
        # Unfrozen, the normals follow the nodes and the tangent misses that part.
        c.unfreeze()
        fd = (c.force_vector(u + dv) - c.force_vector(u - dv)) / 2.0
        assert np.linalg.norm(K @ dv - fd) > 1e-4 * np.linalg.norm(fd)


def test_contact_forces_balance() -> None:
    c, u = _perturbed(4)
    for smooth in (False, True):
        c.smooth_normal = smooth
        c.unfreeze()
        f = c.force_vector(u).reshape(-1, 3)
        assert np.abs(f).max() > 0
        np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12 * np.abs(f).max())


def test_refresh_reports_a_change_of_the_normals() -> None:
    c, u = _perturbed(5)
    c.freeze(u)
    assert not c.refresh(u, tol=1e-12)  # same state: same normals
    c.freeze(np.zeros_like(u))  # normals of the undeformed blocks
    assert c.refresh(u, tol=1e-12)

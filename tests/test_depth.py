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

from woundsweep.depth import WOUND_OPTIONS, DepthContact, material_depth

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


def test_linearised_normals_make_the_tangent_exact() -> None:
    # Live nodal normals: the tangent adds c phi lam_i d n_i / dx over the cells around the
    # master nodes, and then matches the force's derivative without any freezing.
    c, u = _perturbed(6)
    c.linearised = True
    c.unfreeze()
    K = c.tangent_csr(u)
    dv = np.random.default_rng(7).standard_normal(u.size) * 1e-7
    fd = (c.force_vector(u + dv) - c.force_vector(u - dv)) / 2.0
    assert np.linalg.norm(K @ dv - fd) < 1e-6 * np.linalg.norm(fd)
    c.freeze(u)
    assert not c.frozen  # linearised normals are never frozen


def test_engagement_ramp_keeps_the_force_a_function_of_k_times_depth() -> None:
    # Magnitude c r(phi) with r = delta t^2 (2 - t), t = phi / delta, below delta, phi above, and
    # delta = engage h / k_V: the force depends on k_V phi only, so penetrations still scale
    # like 1 / k_V; one point below delta, one above, against the closed form.
    c, X, nL = blocks()
    c.engage_kPa = 50.0
    forces = []
    for k, d in ((1e6, 1e-5), (5e6, 2e-6), (1e8, 1e-7)):  # inside the ramp
        c.k_V_kPa = k
        forces.append(-c.force_vector(shift_right(X, nL, d)).reshape(-1, 3)[nL:, 0].sum())
    np.testing.assert_allclose(forces, forces[0], rtol=1e-9)
    c.k_V_kPa = K_V
    for d in (2e-5, 1e-3):  # delta = 50 h / k_V is of order 2e-5 here: near it, and far above
        f = -c.force_vector(shift_right(X, nL, d)).reshape(-1, 3)[nL:, 0].sum()
        expected = 0.0
        for p in c.points:
            h = p.size_mm[0]
            delta = 50.0 * h / K_V
            r = delta * (d / delta) ** 2 * (2 - d / delta) if d < delta else d
            expected += 0.5 * K_V * r / h
        assert f == pytest.approx(expected, rel=1e-10)


def test_exits_remove_the_jump_of_a_point_entering_past_the_rim() -> None:
    # R pressed into L and slid along y past L's edge y = 1: R's contact points with y > 1 are
    # outside L, those just inside enter through L's face y = 1 (an exit) at full depth d.
    # Without the fade the force jumps as each point crosses; with it the force on a point
    # rises from 0 while its distance to the exit grows to fade x its depth, so the total
    # force varies continuously.
    d = 0.02
    s = np.linspace(0.0, 0.2, 401)
    # The other remedy, exit_depth: the depth is measured to the exits too, so a point
    # entering through one starts at depth 0.
    steps = {}
    for name, kw in (
        ("none", {}),
        ("fade", {"exit_fade": 1.0}),
        ("exit depth", {"exact_depth": True, "exit_depth": True}),
    ):
        c, X, nL = blocks(n=2, m=5, **kw)
        F = []
        for sy in s:
            u = shift_right(X, nL, d).reshape(-1, 3)
            u[nL:, 1] += sy
            F.append(-c.force_vector(u.ravel()).reshape(-1, 3)[nL:, 0].sum())
        steps[name] = np.abs(np.diff(F))
    for fixed in ("fade", "exit depth"):
        assert steps["none"].max() > 10 * steps[fixed].max()
        # no step far above the smooth variation (the median step of the sliding)
        assert steps[fixed].max() < 20 * np.median(steps[fixed][steps[fixed] > 0])


def _bumped(**kw) -> tuple[DepthContact, np.ndarray, int]:
    """Blocks whose L face x = 0 is bent (x = 0.05 sin(pi y) sin(pi z)): a curved surface."""
    pL, cL = box_tets(4, (-1.0, 0.0, 0.0), (0.0, 1.0, 1.0))
    pL[:, 0] += 0.05 * np.sin(np.pi * pL[:, 1]) * np.sin(np.pi * pL[:, 2]) * (pL[:, 0] + 1.0)
    pR, cR = box_tets(3, (0.1, 0.0, 0.0), (1.1, 1.0, 1.0))
    X = np.vstack([pL, pR])
    cells = np.vstack([cL, cR + len(pL)])
    side = np.r_[np.zeros(len(cL), bool), np.ones(len(cR), bool)]
    bf = boundary_facets(cells)
    cen = X[bf].mean(axis=1)
    surface = bf[(np.abs(cen[:, 0] - 0.1) < 1e-12) | ((cen[:, 0] > -0.01) & (cen[:, 0] < 0.06))]
    c = DepthContact(X, cells, side, surface, max_depth_mm=0.5, **kw)
    c.k_V_kPa = K_V
    return c, X, len(pL)


def test_exact_depth_is_the_distance_to_the_curved_surface() -> None:
    # R pushed 0.14 into the bent face: each R point's depth is the exact distance of the L
    # material point it occupies to L's faceted surface (brute force over all facets); the P1
    # depth differs by the interpolation error of the curvature.
    from woundsweep.contact import point_triangle_distance

    c, X, nL = _bumped(exact_depth=True)
    u = shift_right(X, nL, 0.14)
    st = c.state(u)
    mine = st.master == 0
    assert mine.sum() > 20
    Xq = np.einsum("ni,nij->nj", _lam(c, st, u)[mine], X[st.cell[mine]])
    tri = X[c.facets[0]]
    dist = point_triangle_distance(Xq[:, None], tri[None, :, 0], tri[None, :, 1], tri[None, :, 2])
    np.testing.assert_allclose(st.depth[mine], dist[0].min(axis=1), atol=1e-12)
    c.exact_depth = False
    c._cache = None
    p1 = c.state(u)
    assert np.abs(p1.depth[p1.master == 0] - st.depth[mine]).max() > 1e-4


def _lam(c: DepthContact, st, u: np.ndarray) -> np.ndarray:
    x = c.positions(u)
    return c._eval(st, np.einsum("ni,nij->nj", st.bary, x[st.carrier]), x[st.cell])[1]


def test_tangent_with_every_option_is_the_force_derivative() -> None:
    c, X, nL = _bumped(**WOUND_OPTIONS)
    u = shift_right(X, nL, 0.13) + 1e-3 * np.random.default_rng(8).standard_normal(X.size)
    assert len(c.state(u).depth) > 20
    K = c.tangent_csr(u)
    dv = np.random.default_rng(9).standard_normal(u.size) * 1e-8
    fd = (c.force_vector(u + dv) - c.force_vector(u - dv)) / 2.0
    assert np.linalg.norm(K @ dv - fd) < 1e-5 * np.linalg.norm(fd)

"""Contact geometry and penalty (woundsweep.contact) without DOLFINx.

Gap derivatives and penalty forces are checked against central finite differences, the
point-triangle distance, the facet orientation and the flank split against hand-computed
answers, and the total contact force against the module's penalty law: per contact point of
reference area A_q on a slave facet of size h, stiffness c = w k_V A_q / h with w = 1/2 (two
passes), force c (-g); so a uniform overlap d between two matching surfaces of area A gives
2 passes x (1/2) k_V d A / h = k_V d A / h, the pressure p = k_V d / h times A.
"""

from __future__ import annotations

import numpy as np
import pytest
from box_mesh import boundary_facets, box_tets

from woundsweep.contact import GPA_TO_KPA, FlankContact, orient_outward, split_wound_flanks
from woundsweep.contact.geometry import (
    barycentric_derivatives,
    fade_weight,
    gap_derivatives,
    point_triangle_distance,
)

# -- helpers -----------------------------------------------------------------------------------


def normals(X: np.ndarray, tri: np.ndarray) -> np.ndarray:
    p = X[tri]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def square_grid(n: int, x0: float, sign: float, first: int):
    """Triangulated unit square {x = x0} x [0, 1]^2 (2 n^2 equal right triangles) with nodes
    numbered from ``first`` and every facet normal pointing to ``sign`` * e_x."""
    s = np.linspace(0.0, 1.0, n + 1)
    Y, Z = np.meshgrid(s, s, indexing="ij")
    pts = np.c_[np.full(Y.size, x0), Y.ravel(), Z.ravel()]
    idx = lambda i, j: first + i * (n + 1) + j  # noqa: E731
    i, j = (a.ravel() for a in np.meshgrid(range(n), range(n), indexing="ij"))
    tri = np.concatenate([np.c_[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                          np.c_[idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]])  # fmt: skip
    local = np.vstack([np.zeros((first, 3)), pts])
    flip = normals(local, tri)[:, 0] * sign < 0
    tri[flip, 1], tri[flip, 2] = tri[flip, 2].copy(), tri[flip, 1].copy()
    return pts, tri


def two_squares(n_left: int, n_right: int):
    """Two facing unit squares on x = 0 with disjoint nodes: the left body's surface (normal
    +x, into the gap) and the right body's (normal -x). Returns (X, left, right, right_nodes)."""
    pl, tl = square_grid(n_left, 0.0, +1.0, 0)
    pr, tr = square_grid(n_right, 0.0, -1.0, len(pl))
    X = np.vstack([pl, pr])
    return X, tl, tr, np.arange(len(pl), len(X))


def facet_size(n: int) -> float:
    """Contact size h of a facet of `square_grid`: equilateral side of area 1 / (2 n^2)."""
    return float(np.sqrt(4.0 * (0.5 / n**2) / np.sqrt(3.0)))


def random_triangles(rng: np.random.Generator, N: int):
    """Random well-shaped triangles (|m| >= 0.5, no edge below 0.4) and random points."""
    out = []
    while sum(len(o[0]) for o in out) < N:
        x1, x2, x3 = (rng.normal(size=(4 * N, 3)) for _ in range(3))
        xs = rng.normal(size=(4 * N, 3))
        m = np.linalg.norm(np.cross(x2 - x1, x3 - x1), axis=1)
        edges = np.minimum.reduce([np.linalg.norm(x2 - x1, axis=1),
                                   np.linalg.norm(x3 - x2, axis=1),
                                   np.linalg.norm(x1 - x3, axis=1)])  # fmt: skip
        ok = (m >= 0.5) & (edges >= 0.4)
        out.append((xs[ok], x1[ok], x2[ok], x3[ok]))
    return tuple(np.concatenate([o[k] for o in out])[:N] for k in range(4))


def gap_of_q(q: np.ndarray) -> np.ndarray:
    """g for stacked coordinates q (..., 12) = (xs, x1, x2, x3)."""
    shape = q.shape[:-1]
    q = q.reshape(-1, 12)
    g, _, _ = gap_derivatives(q[:, 0:3], q[:, 3:6], q[:, 6:9], q[:, 9:12], hessian=False)
    return g.reshape(shape)


def grad_of_q(q: np.ndarray) -> np.ndarray:
    """dg/dq (..., 12) for stacked coordinates q (..., 12)."""
    shape = q.shape
    q = q.reshape(-1, 12)
    _, grad, _ = gap_derivatives(q[:, 0:3], q[:, 3:6], q[:, 6:9], q[:, 9:12], hessian=False)
    return grad.reshape(shape)


# -- gap_derivatives ------------------------------------------------------------------------


def test_gap_is_the_signed_distance_above_a_triangle_in_the_xy_plane() -> None:
    # Triangle (0,0,0), (2,0,0), (0,2,0): normal (2 e_x) x (2 e_y) / |..| = +e_z.
    x1 = np.array([[0.0, 0.0, 0.0]] * 3)
    x2 = np.array([[2.0, 0.0, 0.0]] * 3)
    x3 = np.array([[0.0, 2.0, 0.0]] * 3)
    xs = np.array([[0.5, 0.5, 0.75], [0.5, 0.5, -0.25], [5.0, -3.0, 1.5]])
    g, grad, H = gap_derivatives(xs, x1, x2, x3)
    np.testing.assert_allclose(g, [0.75, -0.25, 1.5], rtol=0, atol=1e-15)
    # dg/dxs = n = e_z. Moving the triangle up by t lowers g by t: sum of the master parts is -n.
    np.testing.assert_allclose(grad[:, 0:3], [[0, 0, 1]] * 3, atol=1e-15)
    np.testing.assert_allclose(grad[:, 3:6] + grad[:, 6:9] + grad[:, 9:12], [[0, 0, -1]] * 3,
                               atol=1e-15)  # fmt: skip
    # Hand-computed: lifting vertex x2 by t tilts the plane; for xs = (0.5, 0.5, z) the plane
    # height under xs is t * (barycentric weight of x2 at (0.5, 0.5)) = t / 4, and with the
    # tilt the normal distance is (z - t/4) cos(angle): first order dg/dz2 = -1/4.
    assert grad[0, 8] == pytest.approx(-0.25, abs=1e-14)
    assert grad[0, 11] == pytest.approx(-0.25, abs=1e-14)
    assert grad[0, 5] == pytest.approx(-0.5, abs=1e-14)
    # Sliding a vertex within the plane leaves the plane, hence g, unchanged to first order.
    np.testing.assert_allclose(grad[:, [3, 4, 6, 7, 9, 10]], 0.0, atol=1e-15)
    assert H is not None and H.shape == (3, 12, 12)


def test_gap_gradient_matches_central_differences() -> None:
    rng = np.random.default_rng(1)
    xs, x1, x2, x3 = random_triangles(rng, 40)
    q = np.concatenate([xs, x1, x2, x3], axis=1)
    _, grad, _ = gap_derivatives(xs, x1, x2, x3, hessian=False)
    h = 1e-6
    E = np.eye(12) * h
    fd = (gap_of_q(q[:, None, :] + E) - gap_of_q(q[:, None, :] - E)) / (2 * h)
    err = np.linalg.norm(fd - grad, axis=1) / np.linalg.norm(grad, axis=1)
    assert err.max() < 1e-6


def test_gap_hessian_matches_central_differences() -> None:
    rng = np.random.default_rng(2)
    xs, x1, x2, x3 = random_triangles(rng, 25)
    q = np.concatenate([xs, x1, x2, x3], axis=1)
    g, grad, H = gap_derivatives(xs, x1, x2, x3)
    assert H is not None
    np.testing.assert_allclose(H, np.transpose(H, (0, 2, 1)), atol=1e-12)
    # Second central differences of g itself: (g(++) - g(+-) - g(-+) + g(--)) / (4 h^2).
    h = 1e-4
    E = np.eye(12) * h
    Ei, Ej = E[:, None, :], E[None, :, :]
    qq = q[:, None, None, :]
    fd = (gap_of_q(qq + Ei + Ej) - gap_of_q(qq + Ei - Ej) - gap_of_q(qq - Ei + Ej)
          + gap_of_q(qq - Ei - Ej)) / (4 * h * h)  # fmt: skip
    err = np.linalg.norm(fd - H, axis=(1, 2)) / np.linalg.norm(H, axis=(1, 2))
    assert err.max() < 1e-4
    # And the Hessian is the derivative of the analytic gradient (tighter: first differences).
    h = 1e-6
    E = np.eye(12) * h
    dgrad = (grad_of_q(q[:, None, :] + E) - grad_of_q(q[:, None, :] - E)) / (2 * h)
    # dgrad[n, j, i] = d grad_i / d q_j = H[n, i, j]
    err = np.linalg.norm(dgrad - np.transpose(H, (0, 2, 1)), axis=(1, 2))
    assert (err / np.linalg.norm(H, axis=(1, 2))).max() < 1e-6


# -- point_triangle_distance ----------------------------------------------------------------


def test_point_triangle_distance_hand_computed() -> None:
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
    p = np.array([
        [0.25, 0.25, 2.0],  # over the interior: |g| = 2; barycentric (0.5, 0.25, 0.25)
        [0.5, -1.0, 1.0],  # beyond edge ab: nearest (0.5, 0, 0), sqrt(1 + 1)
        [2.0, -1.0, -3.0],  # beyond vertex b: sqrt(1 + 1 + 9)
        [1.0, 1.0, 0.0],  # beyond the hypotenuse, in the plane: nearest (0.5, 0.5, 0)
        [-0.5, 0.5, -0.5],  # beyond edge ca: nearest (0, 0.5, 0), sqrt(0.25 + 0.25)
    ])  # fmt: skip
    dist, g, bmin = point_triangle_distance(p, a, b, c)
    np.testing.assert_allclose(dist, [2.0, np.sqrt(2), np.sqrt(11), np.sqrt(0.5), np.sqrt(0.5)],
                               rtol=1e-14)  # fmt: skip
    np.testing.assert_allclose(g, [2.0, 1.0, -3.0, 0.0, -0.5], atol=1e-15)
    # Barycentric coordinates of the projection: (1 - b - c, b, c) with b = x, c = y.
    np.testing.assert_allclose(bmin, [0.25, -1.0, -1.0, -1.0, -0.5], atol=1e-15)
    # Broadcast over leading axes: (2 points, 1) against (1, 3 triangles).
    tri_b = np.stack([b, 2 * b, 3 * b])[None]
    d2, _, _ = point_triangle_distance(p[:2, None, :], a[None, None], tri_b, c[None, None])
    assert d2.shape == (2, 3)
    assert d2[0, 0] == pytest.approx(2.0)


# -- orient_outward, split_wound_flanks -----------------------------------------------------


@pytest.mark.parametrize("flipped", [False, True])
def test_orient_outward_on_a_box(flipped: bool) -> None:
    rng = np.random.default_rng(3)
    X, cells = box_tets(2, (0.0, 0.0, 0.0), (2.0, 1.0, 3.0))
    # Scramble the local vertex order of the cells: orientation must not depend on it.
    cells = np.take_along_axis(cells, np.argsort(rng.random(cells.shape), axis=1), axis=1)
    bf = boundary_facets(cells)
    assert len(bf) == 2 * 6 * 4  # 6 faces x 4 squares x 2 triangles
    given = bf[:, [0, 2, 1]] if flipped else bf
    given = given[rng.permutation(len(given))]
    out = orient_outward(X, cells, given)
    # Same facets, same order, only the orientation may change.
    np.testing.assert_array_equal(np.sort(out, axis=1), np.sort(given, axis=1))
    centre = np.array([1.0, 0.5, 1.5])
    nrm = normals(X, out)
    assert np.all(np.einsum("ij,ij->i", nrm, X[out].mean(axis=1) - centre) > 0)
    # Each normal is the outward axis direction of its face of the box.
    unit = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    assert np.all(np.abs(unit).max(axis=1) == pytest.approx(1.0))
    # Idempotent.
    np.testing.assert_array_equal(orient_outward(X, cells, out), out)


def test_orient_outward_rejects_a_non_face() -> None:
    X, cells = box_tets(1, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="not a face"):
        orient_outward(X, cells, np.array([[1, 2, 4]]))


def test_split_wound_flanks_by_centroid_x() -> None:
    """Two blocks [-1, -0.25] and [0.25, 1] (x) with a 'wound' between them: the wound facets
    are their inner faces; the flanks split at x_c = 0 and face each other across the gap."""
    rng = np.random.default_rng(4)
    XL, cL = box_tets(2, (-1.0, 0.0, 0.0), (-0.25, 1.0, 1.0))
    XR, cR = box_tets(2, (0.25, 0.0, 0.0), (1.0, 1.0, 1.0))
    X = np.vstack([XL, XR])
    cells = np.vstack([cL, cR + len(XL)])
    bf = boundary_facets(cells)
    cx = X[bf].mean(axis=1)[:, 0]
    inner = bf[np.isclose(cx, -0.25) | np.isclose(cx, 0.25)]
    assert len(inner) == 16
    wound = inner[rng.permutation(len(inner))]
    wound[::2] = wound[::2, [0, 2, 1]]  # half of them given inward
    left, right = split_wound_flanks(X, cells, wound, x_c=0.0)
    assert len(left) == len(right) == 8
    np.testing.assert_allclose(X[left][..., 0], -0.25)
    np.testing.assert_allclose(X[right][..., 0], 0.25)
    # Outward = into the wound cavity: left flank normals +x, right flank normals -x.
    assert np.all(normals(X, left)[:, 0] > 0) and np.all(normals(X, right)[:, 0] < 0)
    # Every given facet lands in exactly one flank.
    got = {tuple(sorted(f)) for f in np.vstack([left, right])}
    assert got == {tuple(sorted(f)) for f in wound}
    # With the mirror plane elsewhere everything is on one side.
    left2, right2 = split_wound_flanks(X, cells, wound, x_c=0.5)
    assert len(left2) == 16 and len(right2) == 0


# -- FlankContact -----------------------------------------------------------------------------


def penetrating_state(rng: np.random.Generator, X: np.ndarray, right_nodes: np.ndarray,
                      depth: float, noise: float) -> np.ndarray:  # fmt: skip
    """Flat displacement: the right surface pushed by ``depth`` into the left (-x), plus a
    random displacement of every node of size ``noise``."""
    U = noise * rng.standard_normal(X.shape)
    U[right_nodes, 0] -= depth
    return U.ravel()


def assert_same_pairing(contact: FlankContact, ref, u: np.ndarray) -> None:
    """The active pairs at ``u`` are those of ``ref`` (a `ContactPairs`): finite differences
    then see a smooth function. (The evaluation at ``u`` stays cached for the next call.)"""
    b = contact.pairs(u)
    assert len(ref.gap_mm) == len(b.gap_mm)
    np.testing.assert_array_equal(ref.master, b.master)
    np.testing.assert_array_equal(ref.slave, b.slave)
    np.testing.assert_array_equal(ref.bary, b.bary)


def make_contact(X, left, right, **kw) -> FlankContact:
    kw.setdefault("max_depth_mm", 0.5)
    c = FlankContact(X, left, right, **kw)
    c.k_V_kPa = 1.0 * GPA_TO_KPA
    return c


@pytest.fixture(scope="module")
def squares():
    # Non-matching triangulations (3 x 3 against 4 x 4), so that the contact points of one
    # surface fall at generic places of the other's facets.
    return two_squares(3, 4)


def test_force_vector_is_the_gradient_of_the_energy(squares) -> None:
    X, left, right, rnodes = squares
    contact = make_contact(X, left, right)
    rng = np.random.default_rng(5)
    u0 = penetrating_state(rng, X, rnodes, depth=0.03, noise=0.01)
    f = contact.force_vector(u0)
    pr = contact.pairs(u0)
    assert np.all(pr.gap_mm < 0) and len(pr.gap_mm) > 0.8 * 6 * (len(left) + len(right))
    assert np.any(pr.weight < 1.0)  # points in an edge fade band are covered too
    h = 1e-6
    fd = np.empty_like(u0)
    for i in range(len(u0)):
        e = np.zeros_like(u0)
        e[i] = h
        assert_same_pairing(contact, pr, u0 + e)
        ep = contact.energy(u0 + e)
        assert_same_pairing(contact, pr, u0 - e)
        fd[i] = (ep - contact.energy(u0 - e)) / (2 * h)
    assert np.linalg.norm(fd - f) <= 1e-7 * np.linalg.norm(f)
    # Action = reaction: no net force, and on the right surface it pushes toward -x in the
    # residual (the contact force on the right body is +x: out of the left body).
    F = f.reshape(-1, 3)
    np.testing.assert_allclose(F.sum(axis=0), 0.0, atol=1e-9 * np.abs(F).max())
    assert F[rnodes, 0].sum() < 0


@pytest.mark.parametrize("exact_depth_rel", [np.inf, 1e-3])
def test_tangent_is_the_derivative_of_the_force(squares, exact_depth_rel: float) -> None:
    """With the geometric term everywhere (exact_depth_rel = inf, the default) at a deep generic
    state; with the quasi-Newton cut-off 1e-3 at a state where every |g| <= 1e-3 h (the term is then kept)."""
    X, left, right, rnodes = squares
    contact = make_contact(X, left, right, exact_depth_rel=exact_depth_rel)
    rng = np.random.default_rng(6)
    if np.isfinite(exact_depth_rel):
        # Shallow state: in-plane noise only (both surfaces stay flat), overlap 1e-4 while
        # h = 0.27 (4 x 4) and 0.36 (3 x 3): the geometric term is ~1e-4 of the tangent.
        u0 = penetrating_state(rng, X, rnodes, depth=0.0, noise=0.01)
        U = u0.reshape(-1, 3)
        U[:, 0] = 0.0
        U[rnodes, 0] = -1e-4
        pr = contact.pairs(u0)
        assert np.all(np.abs(pr.gap_mm) <= exact_depth_rel * pr.size_mm)
    else:
        u0 = penetrating_state(rng, X, rnodes, depth=0.03, noise=0.01)
    pr = contact.pairs(u0)
    K = contact.tangent_csr(u0).toarray()
    np.testing.assert_allclose(K, K.T, atol=1e-10 * np.abs(K).max())
    h = 1e-7
    fd = np.empty_like(K)
    for i in range(len(u0)):
        e = np.zeros_like(u0)
        e[i] = h
        assert_same_pairing(contact, pr, u0 + e)
        fp = contact.force_vector(u0 + e)
        assert_same_pairing(contact, pr, u0 - e)
        fd[:, i] = (fp - contact.force_vector(u0 - e)) / (2 * h)
    assert np.linalg.norm(fd - K) <= 1e-6 * np.linalg.norm(K)


def test_uniform_overlap_gives_pressure_k_V_d_over_h() -> None:
    """Matching surfaces (n x n each) overlapped by d everywhere. Every contact point of both
    passes has g = -d; c = (1/2) k_V A_q / h, sum of A_q over one pass = A = 1 mm^2, so the
    total normal force is 2 * (1/2) k_V d A / h = k_V d / h (mN with kPa, mm) and it acts in x:
    +x on the right body (the residual holds minus the force on a node)."""
    n = 3
    X, left, right, rnodes = two_squares(n, n)
    contact = make_contact(X, left, right)
    h = facet_size(n)
    d = 2e-3
    for k_gpa in (1.0, 5.0, 100.0):
        contact.k_V_kPa = k_gpa * GPA_TO_KPA
        U = np.zeros_like(X)
        U[rnodes, 0] = -d
        u = U.ravel()
        expected = contact.k_V_kPa * d / h  # p A, A = 1
        f = contact.force_vector(u).reshape(-1, 3)
        assert -f[rnodes, 0].sum() == pytest.approx(expected, rel=1e-12)
        lnodes = np.setdiff1d(np.arange(len(X)), rnodes)
        assert f[lnodes, 0].sum() == pytest.approx(expected, rel=1e-12)
        np.testing.assert_allclose(f[:, 1:], 0.0, atol=1e-12 * expected)
        s = contact.summary(u)
        assert s.n_penetrating == 2 * 6 * len(left)  # both passes, 6 points per facet
        assert s.max_penetration_mm == pytest.approx(d, rel=1e-12)
        assert s.max_penetration_rel == pytest.approx(d / h, rel=1e-12)
        assert s.contact_force_mN == pytest.approx(expected, rel=1e-12)
        assert s.n_deep == 0
        assert contact.energy(u) == pytest.approx(0.5 * expected * d, rel=1e-12)


def test_summary_touching_separated_deep_and_switched_off() -> None:
    X, left, right, rnodes = two_squares(2, 2)
    contact = make_contact(X, left, right, max_depth_mm=0.01)
    U = np.zeros_like(X)
    # Touching: every point engaged at g = 0, no force, no penetration.
    pr = contact.pairs(U.ravel())
    assert len(pr.gap_mm) == 2 * 6 * len(left) and np.all(pr.gap_mm == 0)
    assert contact.summary(U.ravel()) == (0, 0.0, 0.0, 0.0, 0)
    assert not np.any(contact.force_vector(U.ravel()))
    # Separated: no pairs.
    U[rnodes, 0] = 0.05
    assert len(contact.pairs(U.ravel()).gap_mm) == 0
    assert contact.summary(U.ravel()) == (0, 0.0, 0.0, 0.0, 0)
    # Deeper than max_depth_mm: left out and counted.
    U[rnodes, 0] = -0.02
    s = contact.summary(U.ravel())
    assert s.n_deep == 2 * 6 * len(left) and s.n_penetrating == 0
    assert not np.any(contact.force_vector(U.ravel()))
    # k_V = 0: penetrations measured, no forces.
    U[rnodes, 0] = -0.005
    contact.k_V_kPa = 0.0
    s = contact.summary(U.ravel())
    assert s.n_penetrating == 2 * 6 * len(left)
    assert s.max_penetration_mm == pytest.approx(0.005)
    assert s.contact_force_mN == 0.0
    assert not np.any(contact.force_vector(U.ravel()))


def test_flanks_that_do_not_face_each_other_are_not_in_contact() -> None:
    """Both surfaces oriented +x (a smooth continuation, not two facing flanks): n_s . n = 1 >
    normal_cos = 0, so an overlap is not taken for penetration."""
    pl, tl = square_grid(2, 0.0, +1.0, 0)
    pr, tr = square_grid(2, 0.0, +1.0, len(pl))
    X = np.vstack([pl, pr])
    contact = make_contact(X, tl, tr)
    U = np.zeros_like(X)
    U[len(pl) :, 0] = -0.01
    assert len(contact.pairs(U.ravel()).gap_mm) == 0


def test_frozen_pairing_engages_live_and_refresh_reports_a_new_pairing(squares) -> None:
    """Frozen mode (used by the stages): the pairing of `freeze` is kept while engagement
    follows the state; `refresh` re-searches and says whether the forces changed."""
    X, left, right, rnodes = squares
    contact = make_contact(X, left, right)
    U = np.zeros_like(X)
    U[rnodes, 0] = 0.01  # apart by 0.01 < h: every point is a candidate, none engaged
    contact.freeze(U.ravel())
    searches = contact.searches
    assert len(contact.pairs(U.ravel()).gap_mm) == 0
    U[rnodes, 0] = -0.001  # pushed in: engaged with the frozen pairing, no new search
    pr = contact.pairs(U.ravel())
    assert len(pr.gap_mm) > 0 and contact.searches == searches
    np.testing.assert_allclose(pr.gap_mm, -0.001, rtol=1e-9)
    assert not contact.refresh(U.ravel(), tol=1e-9)  # pushed straight in: same pairing
    U[rnodes, 1] = 0.6 * facet_size(4)  # slid along the surface: other master facets
    assert contact.refresh(U.ravel(), tol=1e-9)
    assert not contact.refresh(U.ravel(), tol=1e-9)  # now consistent with its own pairing
    contact.unfreeze()
    assert not contact.frozen and contact.refresh(U.ravel(), tol=1e-9) is False


# -- edge fade ----------------------------------------------------------------------------------


def test_barycentric_derivatives_match_finite_differences() -> None:
    rng = np.random.default_rng(11)
    xs, x1, x2, x3 = random_triangles(rng, 40)
    lam, dlam = barycentric_derivatives(xs, x1, x2, x3)
    np.testing.assert_allclose(lam.sum(axis=1), 1.0, atol=1e-12)
    # The projection sum lam_i x_i differs from xs only along the normal.
    proj = lam[:, 0:1] * x1 + lam[:, 1:2] * x2 + lam[:, 2:3] * x3
    n = np.cross(x2 - x1, x3 - x1)
    np.testing.assert_allclose(np.cross(xs - proj, n), 0.0, atol=1e-10)
    q = np.concatenate([xs, x1, x2, x3], axis=1)
    h = 1e-6
    for j in range(12):
        e = np.zeros(12)
        e[j] = h
        qp, qm = q + e, q - e
        lp = barycentric_derivatives(qp[:, 0:3], qp[:, 3:6], qp[:, 6:9], qp[:, 9:12])[0]
        lm = barycentric_derivatives(qm[:, 0:3], qm[:, 3:6], qm[:, 6:9], qm[:, 9:12])[0]
        np.testing.assert_allclose((lp - lm) / (2 * h), dlam[:, :, j], atol=1e-7)


def test_fade_weight_values_and_derivatives() -> None:
    width = 0.25
    lam = np.array([[0.2, 0.5, 0.3], [-0.125, 0.6, 0.525], [-0.3, 0.5, 0.8], [-0.05, -0.1, 1.15]])
    w, dw, d2w = fade_weight(lam, width)
    # s(lam) = 1 - 3 t^2 + 2 t^3, t = -lam / width: t = 1/2 gives 1/2; t >= 1 gives 0.
    np.testing.assert_allclose(w[:3], [1.0, 0.5, 0.0])
    s = lambda t: 1 - 3 * t**2 + 2 * t**3  # noqa: E731
    np.testing.assert_allclose(w[3], s(0.2) * s(0.4))
    h = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        wp, dwp, _ = fade_weight(lam + e, width)
        wm, dwm, _ = fade_weight(lam - e, width)
        np.testing.assert_allclose((wp - wm) / (2 * h), dw[:, j], atol=1e-7)
        np.testing.assert_allclose((dwp - dwm) / (2 * h), d2w[:, :, j], atol=1e-5)


def slid(X: np.ndarray, right_nodes: np.ndarray, dy: float) -> np.ndarray:
    """Flat displacement: the right surface pushed 1e-3 into the left (-x) and slid by dy."""
    U = np.zeros_like(X)
    U[right_nodes, 0] = -1e-3
    U[right_nodes, 1] = dy
    return U.ravel()


def _slide_forces(steps: int, fade_width: float = 0.25) -> np.ndarray:
    """x-force on the right square (3 x 3 facets, pushed 1e-3 into the left 4 x 4 one) while it
    slides by 0.3 along y, so that left contact points cross its boundary edge at y = 1."""
    X, left, right, rnodes = two_squares(4, 3)
    contact = make_contact(X, left, right, fade_width=fade_width)
    out = []
    for dy in np.linspace(0.0, 0.3, steps):
        out.append(contact.force_vector(slid(X, rnodes, dy)).reshape(-1, 3)[rnodes, 0].sum())
    return np.array(out)


def test_force_fades_continuously_off_a_boundary_edge() -> None:
    """Without the fade a contact point leaving the other surface over its edge drops its
    whole force at once, and the largest jump between slide steps stays when the step is
    halved (checked: fade_width 1e-9 gives a ratio of ~1). With it the force is Lipschitz in
    the slide: halving the step halves the largest jump."""
    coarse, fine = np.abs(_slide_forces(61)), np.abs(_slide_forces(121))
    jump_c, jump_f = np.abs(np.diff(coarse)).max(), np.abs(np.diff(fine)).max()
    assert coarse[-1] < 0.8 * coarse[0]  # the overlap area shrinks: points did leave
    assert jump_f / jump_c < 0.6


# -- pairing 2-cycles ---------------------------------------------------------------------------


def _masters(found) -> dict[int, list[tuple[int, float]]]:
    """Contact point id -> [(master facet id, carried area)] of one search."""
    out: dict[int, list[tuple[int, float]]] = {}
    for p, m, a in zip(found.pid, found.mkey, found.area_mm2, strict=True):
        out.setdefault(int(p), []).append((int(m), float(a)))
    return out


@pytest.mark.parametrize("share", [True, False])
def test_a_master_that_flips_back_is_shared_half_and_half(squares, share: bool) -> None:
    """A point whose master goes A -> B -> A over successive searches keeps both A and B with
    half its area each (so its force is the mean of the two facets' forces) while the search
    gives it A or B; a point that moves on to a third facet has one master again."""
    X, left, right, rnodes = squares
    contact = make_contact(X, left, right, share_cycles=share)
    h = facet_size(4)

    def state(dy: float) -> np.ndarray:
        return slid(X, rnodes, dy)

    contact.freeze(state(0.0))
    first = _masters(contact._found)
    contact.refresh(state(0.4 * h), tol=0.0)
    second = _masters(contact._found)
    flipped = {p for p in first if p in second and first[p][0][0] != second[p][0][0]}
    assert len(flipped) > 10  # a slide of 0.4 h moves many points onto other facets
    contact.refresh(state(0.0), tol=0.0)
    third = _masters(contact._found)
    assert third.keys() == first.keys()
    # Sharing needs B to be valid for the point back at the first state: its projection on
    # B's plane (all facets lie in x = 0) at most fade_width past B's edges.
    x = X + state(0.0).reshape(-1, 3)
    pts = np.vstack([np.einsum("qi,qij->qj", p.bary, x[p.carrier]) for p in contact.points])
    facets = np.vstack([srf.facets for srf in contact.surfaces])

    def margin(p: int, f: int) -> float:
        a, b, c = x[facets[f]][:, 1:]
        lam = np.linalg.solve(np.c_[b - a, c - a], pts[p, 1:] - a)
        return float(min(1 - lam.sum(), *lam) + contact.fade_width)

    margins = {p: margin(p, second[p][0][0]) for p in flipped}
    shared = {p for p in flipped if margins[p] > 1e-9}
    assert len(shared) > 10
    for p, entries in third.items():
        if p in flipped and abs(margins[p]) <= 1e-9:
            continue  # on the edge of the fade band: either way
        if share and p in shared:
            a = first[p][0][1]
            assert sorted(entries) == sorted([(first[p][0][0], a / 2), (second[p][0][0], a / 2)])
        else:
            assert entries == first[p]
    # Shared points stay shared at a state where the search gives them A or B ...
    contact.refresh(state(0.4 * h), tol=0.0)
    fourth = _masters(contact._found)
    two = {p for p, e in fourth.items() if len(e) == 2}
    if share:
        assert len(two) > 10 and two <= flipped
        assert all({m for m, _ in fourth[p]} == {first[p][0][0], second[p][0][0]} for p in two)
    else:
        assert not two
    # ... and have one master again once the search gives them a third facet.
    contact.refresh(state(-0.8 * h), tol=0.0)
    fifth = _masters(contact._found)
    moved = {p for p in two if p in fifth and fifth[p][0][0] not in
             (first[p][0][0], second[p][0][0])}  # fmt: skip
    assert (bool(moved) == share) and all(len(fifth[p]) == 1 for p in moved)


def test_a_retry_from_the_accepted_state_gets_its_pairing_back(squares) -> None:
    """`freeze` at the state of the last accepted `refresh` (a converged state, where a retried
    load increment starts) restores that pairing, shared points included, even after the
    pairing history moved on; elsewhere it searches."""
    X, left, right, rnodes = squares
    contact = make_contact(X, left, right)
    h = facet_size(4)

    def state(dy: float) -> np.ndarray:
        return slid(X, rnodes, dy)

    contact.freeze(state(0.0))
    contact.refresh(state(0.4 * h), tol=0.0)
    contact.refresh(state(0.0), tol=0.0)  # the flips back are shared now
    assert not contact.refresh(state(0.0), tol=0.0)  # same state, same pairing: accepted
    accepted = _masters(contact._found)
    assert sum(len(e) == 2 for e in accepted.values()) > 10
    f_accepted = contact.force_vector(state(0.0))
    contact.refresh(state(-0.8 * h), tol=0.0)  # a failed attempt wandered off ...
    contact.freeze(state(0.0))  # ... and the increment is retried from the accepted state
    assert _masters(contact._found) == accepted
    np.testing.assert_array_equal(contact.force_vector(state(0.0)), f_accepted)
    contact.freeze(state(0.1 * h))
    assert _masters(contact._found) != accepted

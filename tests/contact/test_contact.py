"""Contact geometry and penalty (woundsweep.contact) without DOLFINx.

The implicit surface's derivatives and the penalty's forces and tangent are checked against
central finite differences; its gap against exact answers (a plane; concentric cylinders,
where the gap error must fall like h^2); sliding across facet edges against continuity of the
force and quadratic convergence of Newton; the facet orientation and flank split against
hand-computed answers; the total contact force against the penalty law (per contact point of
reference area A_q and size h, stiffness c = w k_V A_q / h with w = 1/2, two passes).
"""

from __future__ import annotations

import numpy as np
import pytest
from box_mesh import boundary_facets, box_tets
from contact_surfaces import cylinder_surface, make_contact, normals, penetrating_state, two_squares

from woundsweep.contact import FlankContact, orient_outward, split_wound_flanks
from woundsweep.contact.implicit import pair_terms

# -- the implicit surface ---------------------------------------------------------------------


def test_pair_terms_derivatives_match_central_differences() -> None:
    rng = np.random.default_rng(0)
    P = 20
    x1 = rng.normal(size=(P, 3))
    x2, x3 = x1 + rng.normal(size=(P, 3)), x1 + rng.normal(size=(P, 3))
    x = (x1 + x2 + x3) / 3 + 0.4 * rng.normal(size=(P, 3))
    rho = np.full(P, 2.5)
    q = np.concatenate([x, x1, x2, x3], axis=1)

    def terms(q):
        return pair_terms(q[:, 0:3], q[:, 3:6], q[:, 6:9], q[:, 9:12], rho)

    t, eps = terms(q), 1e-6
    assert np.all(t.D > 0)  # every pair inside its kernel
    for f, df, d2f in (("N", "dN", "d2N"), ("D", "dD", "d2D")):
        g, H = np.zeros((P, 12)), np.zeros((P, 12, 12))
        for j in range(12):
            e = np.zeros(12)
            e[j] = eps
            tp, tm = terms(q + e), terms(q - e)
            g[:, j] = (getattr(tp, f) - getattr(tm, f)) / (2 * eps)
            H[:, :, j] = (getattr(tp, df) - getattr(tm, df)) / (2 * eps)
        np.testing.assert_allclose(getattr(t, df), g, atol=1e-7)
        np.testing.assert_allclose(getattr(t, d2f), H, atol=1e-6)


def test_gap_is_the_signed_distance_to_a_plane(squares) -> None:
    """Two flat faces: the implicit gap of every node is its x-offset (exact on a plane)."""
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    rng = np.random.default_rng(2)
    U = np.zeros_like(X)
    U[rnodes, 0] = 0.05 * rng.standard_normal(len(rnodes))  # right nodes moved along x only
    # (the left face, the right face's master, stays flat: a right node's gap is its offset)
    g = c.gaps(U.ravel())
    right_pts = c.passes[1].nodes
    np.testing.assert_allclose(g[len(c.passes[0].nodes) :], U[right_pts, 0], atol=1e-12)


def test_concentric_cylinders_gap_converges_like_h_squared() -> None:
    """Inner flank r = 1 (normals out), outer flank r = 1 - d (normals in): every node of the
    inner one overlaps the outer surface by d. The faceted master lies inside its circle by at
    most the sagitta, so the gap error must fall like h^2 (observed order near 2)."""
    d = 0.01
    errs, hs = [], []
    for n in (8, 16, 32):
        pi, ti = cylinder_surface(n, n // 2, 1.0, +1.0)
        po, to = cylinder_surface(n + 3, (n + 3) // 2, 1.0 - d, -1.0, first=len(pi))
        X = np.vstack([pi, po])
        c = make_contact(X, ti, to)
        g = c.gaps(np.zeros(X.size))[: len(c.passes[0].nodes)]
        inner = c.passes[0].nodes
        theta = np.arctan2(X[inner, 2], X[inner, 0])
        mid = (theta < -0.2) & (theta > -np.pi + 0.2)  # away from the surfaces' edges
        errs.append(float(np.max(np.abs(g[mid] + d))))
        hs.append(np.pi / (n + 3))
    order = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert 1.7 < order < 2.5, (order, errs)
    assert errs[-1] < 0.5 * hs[-1] ** 2, (errs, hs)  # a fraction of the sagitta's scale


# -- FlankContact -----------------------------------------------------------------------------


def _central_differences(c: FlankContact, u: np.ndarray, eps: float = 1e-7):
    """The energy's gradient and the force's Jacobian at ``u`` by central differences."""
    fd, Kfd = np.zeros(len(u)), np.zeros((len(u), len(u)))
    for j in range(len(u)):
        e = np.zeros_like(u)
        e[j] = eps
        fd[j] = (c.energy(u + e) - c.energy(u - e)) / (2 * eps)
        Kfd[:, j] = (c.force_vector(u + e) - c.force_vector(u - e)) / (2 * eps)
    return fd, Kfd


def test_force_is_the_gradient_of_the_energy_and_tangent_its_derivative(squares) -> None:
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    u = penetrating_state(np.random.default_rng(1), X, rnodes, 0.05, 0.01)
    f, K = c.force_vector(u), c.tangent_csr(u).toarray()
    fd, Kfd = _central_differences(c, u)
    assert np.abs(f).max() > 1e3 and np.abs(K).max() > 1e4  # a real contact state
    np.testing.assert_allclose(f, fd, atol=1e-9 * np.abs(f).max())
    np.testing.assert_allclose(K, Kfd, atol=1e-8 * np.abs(K).max())
    np.testing.assert_allclose(K, K.T, atol=1e-12 * np.abs(K).max())


def test_uniform_overlap_gives_pressure_k_V_d_over_h() -> None:
    """Matching faces pushed together by d: total force k_V d A / h (A = 1), h the node size."""
    X, left, right, rnodes = two_squares(4, 4)
    c = make_contact(X, left, right)
    d = 1e-3
    U = np.zeros_like(X)
    U[rnodes, 0] = -d
    s = c.summary(U.ravel())
    h = c.passes[0].size_mm[0]
    np.testing.assert_allclose(c.passes[0].size_mm, h)
    assert s.contact_force_mN == pytest.approx(c.k_V_kPa * d / h, rel=1e-12)
    assert s.n_penetrating == 2 * 25 and s.max_penetration_mm == pytest.approx(d, rel=1e-12)
    c.k_V_kPa = 0.0
    assert c.energy(U.ravel()) == 0.0 and c.summary(U.ravel()).contact_force_mN == 0.0


def test_separated_faces_have_no_force(squares) -> None:
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    U = np.zeros_like(X)
    U[rnodes, 0] = 0.01  # right face moved away: open gap
    u = U.ravel()
    assert c.energy(u) == 0.0 and not np.any(c.force_vector(u))
    assert c.summary(u).n_penetrating == 0


def test_sliding_across_facet_edges_is_smooth_and_newton_is_quadratic() -> None:
    """A flat slave patch (rigid, one normal dof w) pressed by a load P onto a faceted
    half-cylinder master while it slides along the axis over many facet edges. At each slide
    position Newton solves for w; its error must fall quadratically. Along the path w must be
    continuous: halving the slide step shrinks the largest change between samples (toward
    half of it; a jump would keep it)."""
    pm, tm = cylinder_surface(12, 9, 1.0, +1.0)  # master, normals out
    s = np.linspace(-0.15, 0.15, 4)
    Y, Xs = np.meshgrid(s, s, indexing="ij")
    ps = np.c_[Xs.ravel(), Y.ravel() + 0.3, np.full(Y.size, -1.0)]
    n0 = len(pm)
    k = lambda i, j: n0 + i * 4 + j  # noqa: E731
    i, j = (a.ravel() for a in np.meshgrid(range(3), range(3), indexing="ij"))
    ts = np.concatenate([np.c_[k(i, j), k(i + 1, j), k(i + 1, j + 1)],
                         np.c_[k(i, j), k(i + 1, j + 1), k(i, j + 1)]])  # fmt: skip
    X = np.vstack([pm, ps])
    flip = normals(X, ts)[:, 2] < 0  # the slave faces the master (normals +z)
    ts[flip, 1], ts[flip, 2] = ts[flip, 2].copy(), ts[flip, 1].copy()
    c = FlankContact(X, tm, ts)
    c.k_V_kPa = 1e3
    slave = np.arange(n0, len(X))
    load = 0.05  # mN pressing the slave up (+z)
    dz = np.zeros(X.size)
    dz[3 * slave + 2] = 1.0

    def equilibrium(slide: float) -> float:
        U = np.zeros_like(X)
        U[slave, 1] = slide
        w, err = 0.02, []  # start pressed in: every slave node engaged
        for _ in range(30):
            U[slave, 2] = w
            u = U.ravel()
            r = c.force_vector(u) @ dz - load  # the contact reaction balances the load
            err.append(abs(r))
            if abs(r) < 1e-13:
                break
            w -= r / float(dz @ (c.tangent_csr(u) @ dz))
        assert err[-1] < 1e-13, err
        e = np.array([v for v in err if v > 1e-11])
        if len(e) >= 3:  # quadratic: e_{i+1} <= C e_i^2
            assert np.all(e[2:] / e[1:-1] ** 2 < 1e3), err
        assert c.summary(U.ravel()).contact_force_mN == pytest.approx(load, rel=0.02)
        return w

    period = 2.0 / 9  # the master's facet length along y
    coarse = np.array([equilibrium(t) for t in np.linspace(0.0, 2 * period, 41)])
    fine = np.array([equilibrium(t) for t in np.linspace(0.0, 2 * period, 81)])
    assert np.ptp(coarse) > 0  # the path does cross the facets' structure
    assert np.abs(np.diff(fine)).max() <= 0.75 * np.abs(np.diff(coarse)).max()
    np.testing.assert_allclose(fine[::2], coarse, rtol=0, atol=1e-15)


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


def test_a_held_support_weights_a_point_past_the_edge_without_pushing_it_along() -> None:
    """The right square slid past the left one's edge (y + 0.93) and pressed into it: its
    points near the edge sit in the support's fade. With the fade following the state, their
    force has a component along the flat master (the energy falls as they slide off it);
    with the support held (`freeze_support`) it is normal to it, and the force is still the
    gradient of that energy and the tangent its derivative. `support_change` measures how
    far the held support is from the state's."""
    X, left, right, rnodes = two_squares(4, 4)
    X[rnodes, 1] += 0.93
    c = make_contact(X, left, right)
    U = np.zeros_like(X)
    U[rnodes, 0] = -0.02
    u = U.ravel().copy()
    f_live = c.force_vector(u).reshape(-1, 3)
    assert np.abs(f_live[:, 1]).max() > 1e-3 * np.abs(f_live[:, 0]).max()
    c.freeze_support(u)
    assert c.support_change(u) == 0.0
    f, K = c.force_vector(u), c.tangent_csr(u).toarray()
    assert np.abs(f.reshape(-1, 3)[:, 1]).max() <= 1e-10 * np.abs(f).max()
    fd, Kfd = _central_differences(c, u)
    np.testing.assert_allclose(f, fd, atol=1e-9 * np.abs(f).max())
    np.testing.assert_allclose(K, Kfd, atol=1e-8 * np.abs(K).max())
    U[rnodes, 1] += 0.02  # further off the edge: the fading points' support falls
    assert c.support_change(U.ravel()) > 0.05
    c.freeze_support(None)
    np.testing.assert_array_equal(c.force_vector(u), f_live.ravel())

"""woundsweep.contact.tie: mirror pairing, exact derivatives, inert under mirror symmetry, a
known slip force (pure numpy: two flat flanks facing each other across x = x_c)."""

from __future__ import annotations

import numpy as np
import pytest

from woundsweep.contact.tie import ZoneTie

X_C = 0.5
K_V = 2.0e3  # kPa


def _flanks(n: int = 5, a: float = 0.1, gap: float = 0.2):
    """Two n x n node grids (spacing a) on the planes x = x_c -+ gap / 2, y-z triangulated,
    and the left grid's facets. Returns X, left nodes, right nodes, left facets, flank area."""
    ys, zs = np.meshgrid(np.arange(n) * a, -np.arange(n) * a, indexing="ij")
    grid = np.stack([ys.ravel(), zs.ravel()], 1)
    left = np.column_stack([np.full(n * n, X_C - gap / 2), grid])
    right = np.column_stack([np.full(n * n, X_C + gap / 2), grid])
    # Shuffle the right flank so the pairing has to search.
    perm = np.random.default_rng(0).permutation(n * n)
    X = np.vstack([left, right[perm]])
    idx = np.arange(n * n).reshape(n, n)
    tris = []
    for i in range(n - 1):
        for j in range(n - 1):
            p, q, r, s = idx[i, j], idx[i + 1, j], idx[i, j + 1], idx[i + 1, j + 1]
            tris += [(p, q, s), (p, s, r)]
    return X, np.arange(n * n), n * n + np.arange(n * n), np.array(tris), ((n - 1) * a) ** 2


def test_each_zone_node_pairs_with_its_mirror_image() -> None:
    X, left, right, facets, _ = _flanks()
    tie = ZoneTie(X, left, right, facets, X_C)
    assert len(tie) == len(left)
    a, b = X[tie.pairs[:, 0]], X[tie.pairs[:, 1]]
    np.testing.assert_allclose(a[:, 0] + b[:, 0], 2 * X_C, atol=1e-15)
    np.testing.assert_array_equal(a[:, 1:], b[:, 1:])


def test_a_zone_node_without_a_mirror_image_is_an_error() -> None:
    X, left, right, facets, _ = _flanks()
    X[right[3], 1] += 1e-3
    with pytest.raises(ValueError, match="1 closure-zone nodes have no mirror image"):
        ZoneTie(X, left, right, facets, X_C)


def test_tie_weights_carry_the_flank_area() -> None:
    X, left, right, facets, area = _flanks()
    tie = ZoneTie(X, left, right, facets, X_C)
    # weight = A_p / h_p; with the uniform grid h_p is constant away from the border, and the
    # lumped areas sum to the flank's area.
    from woundsweep.contact.surfaces import lumped_area

    assert lumped_area(X, facets, left).sum() == pytest.approx(area, rel=1e-12)
    assert np.all(tie.weight > 0)


def test_tie_is_inert_until_set_and_after_release() -> None:
    X, left, right, facets, _ = _flanks()
    tie = ZoneTie(X, left, right, facets, X_C)
    u = np.random.default_rng(1).standard_normal(X.size)
    assert tie.energy(u, K_V) == 0.0 and not tie.force_vector(u, K_V).any()
    tie.set_reference(np.zeros(X.size))
    assert tie.energy(u, K_V) > 0.0
    tie.release()
    assert tie.energy(u, K_V) == 0.0 and not tie.slip(u).any()


def test_motion_of_the_pairs_together_carries_no_tie_force() -> None:
    """The tie holds the pairs' relative offset only: a pair moving together (any rigid motion
    of the closed zone, e.g. off the mid-plane at 45 degrees) carries nothing, while a
    mirror-symmetric opening (u_x odd across x = x_c) is held."""
    X, left, right, facets, _ = _flanks()
    tie = ZoneTie(X, left, right, facets, X_C)
    rng = np.random.default_rng(2)
    tie.set_reference(np.zeros(X.size))
    u = np.zeros((len(X), 3))
    f = rng.standard_normal((len(tie), 3))
    u[tie.pairs[:, 0]] = f
    u[tie.pairs[:, 1]] = f
    assert tie.energy(u.ravel(), K_V) == 0.0
    assert not tie.force_vector(u.ravel(), K_V).any()
    u[tie.pairs[:, 1]] = f * np.array([-1.0, 1.0, 1.0])  # the flanks open or close
    opening = 2.0 * f[:, 0]
    fv = tie.force_vector(u.ravel(), K_V).reshape(-1, 3)
    np.testing.assert_allclose(fv[tie.pairs[:, 0], 0], K_V * tie.weight * opening, rtol=1e-12)
    assert not fv[:, 1:].any()


@pytest.mark.parametrize("comp", [0, 1, 2])
def test_a_uniform_offset_gives_the_penalty_law_force(comp: int) -> None:
    X, left, right, facets, _ = _flanks()
    tie = ZoneTie(X, left, right, facets, X_C)
    tie.set_reference(np.zeros(X.size))
    delta = np.zeros(3)
    delta[comp] = 3e-4  # offset of the left flank against the right (mm)
    delta[(comp + 1) % 3] = -1e-4
    u = np.zeros((len(X), 3))
    u[left] = delta
    u = u.ravel()
    np.testing.assert_allclose(tie.slip(u), np.tile(delta, (len(tie), 1)), atol=1e-18)
    c = K_V * tie.weight  # mN/mm per pair
    f = tie.force_vector(u, K_V).reshape(-1, 3)
    np.testing.assert_allclose(f[tie.pairs[:, 0]], c[:, None] * delta, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(f[tie.pairs[:, 1]], -c[:, None] * delta, rtol=1e-12, atol=1e-18)
    assert tie.energy(u, K_V) == pytest.approx(0.5 * c.sum() * (delta @ delta), rel=1e-12)
    assert tie.force_mN(u, K_V) == pytest.approx(c.sum() * np.linalg.norm(delta), rel=1e-12)


def test_force_and_tangent_are_the_derivatives_of_the_energy() -> None:
    X, left, right, facets, _ = _flanks()
    tie = ZoneTie(X, left, right, facets, X_C)
    rng = np.random.default_rng(3)
    tie.set_reference(1e-3 * rng.standard_normal(X.size))
    u = 1e-3 * rng.standard_normal(X.size)
    v = rng.standard_normal(X.size)
    eps = 1e-7
    fd = (tie.energy(u + eps * v, K_V) - tie.energy(u - eps * v, K_V)) / (2 * eps)
    assert fd == pytest.approx(float(tie.force_vector(u, K_V) @ v), rel=1e-7)
    dfd = (tie.force_vector(u + eps * v, K_V) - tie.force_vector(u - eps * v, K_V)) / (2 * eps)
    K = tie.tangent_csr(K_V)
    np.testing.assert_allclose(K @ v, dfd, rtol=1e-6, atol=1e-9 * np.abs(dfd).max())
    assert abs(K - K.T).max() == 0.0

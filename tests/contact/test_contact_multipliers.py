"""The semi-smooth contact step (woundsweep.contact.multipliers): the carried multipliers
against the penalty's own forces, the active set they keep, and their linearisation."""

from __future__ import annotations

import numpy as np
from contact_surfaces import make_contact, penetrating_state

from woundsweep.contact import ContactMultipliers


def test_penalty_multipliers_give_the_penalty_tangent(squares) -> None:
    """mu = c psi(u) is the pure penalty: the same tangent (curvature term included)."""
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    u = penetrating_state(np.random.default_rng(1), X, rnodes, 0.05, 0.01)
    K0 = c.tangent_csr(u).toarray()
    mu = c.penalty_multipliers(u)
    assert np.count_nonzero(mu) > 10 and np.all(mu <= 0.0)
    c.mult = mu
    np.testing.assert_allclose(c.tangent_csr(u).toarray(), K0, rtol=0, atol=1e-12 * abs(K0).max())
    # The curvature term follows the multipliers: doubling them changes the tangent.
    c.mult = 2.0 * mu
    assert np.abs(c.tangent_csr(u).toarray() - K0).max() > 1e-6 * abs(K0).max()


def test_a_compressive_multiplier_keeps_an_opened_point_engaged(squares) -> None:
    """Faces 0.01 apart: the penalty has no force. A point whose multiplier is compressive
    stays engaged (its linearised contact pulls it back); with mu = 0 it is released."""
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    U = np.zeros_like(X)
    U[rnodes, 0] = 0.01
    u = U.ravel()
    assert not np.any(c.force_vector(u)) and c.tangent_csr(u).nnz == 0
    c.mult = np.full(c.n_points, -1.0)
    f = c.force_vector(u)
    # Pulled back toward the left face (the residual's x part at the right nodes is > 0).
    inner = rnodes[(np.abs(X[rnodes, 1] - 0.5) < 0.3) & (np.abs(X[rnodes, 2] - 0.5) < 0.3)]
    assert np.all(f[3 * inner] > 0.0)
    K = c.tangent_csr(u).toarray()
    assert np.all(np.diag(K)[3 * inner] > 0.0)
    np.testing.assert_allclose(K, K.T, atol=1e-12 * abs(K).max())
    c.mult = np.zeros(c.n_points)
    assert not np.any(c.force_vector(u))


def test_linearization_is_the_first_order_change_of_the_force(squares) -> None:
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    rng = np.random.default_rng(4)
    u = penetrating_state(rng, X, rnodes, 0.02, 0.002)
    du = 1e-3 * rng.standard_normal(u.shape)
    a, b = c.linearization(u, du)
    engaged = a < 0.0
    assert engaged.sum() > 10
    np.testing.assert_allclose(a, c.penalty_multipliers(u))
    for eps in (1e-3, 5e-4):
        change = c.penalty_multipliers(u + eps * du) - a
        # Second order in eps: halving eps quarters the error.
        err = np.abs(change - eps * b)[engaged].max()
        assert err < 1e-2 * np.abs(eps * b)[engaged].max()


def test_carried_multipliers_predict_commit_and_restart(squares) -> None:
    """Over one solve: begin from the penalty, accept a relaxed prediction (clipped to
    compression), commit; the next solve starts from the committed values, a stage reset
    forgets them."""
    X, left, right, rnodes = squares
    c = make_contact(X, left, right)
    u = penetrating_state(np.random.default_rng(5), X, rnodes, 0.02, 0.0)
    m = ContactMultipliers(c, lambda: u)
    m.begin()
    np.testing.assert_array_equal(c.mult, c.penalty_multipliers(u))
    du = np.zeros_like(u)
    du[3 * rnodes] = 0.03  # opens every point past its penetration: predicted tension
    pred = m.predict(du)
    m.accept(pred, 0.5)
    half = np.minimum(pred[0] + 0.5 * pred[1], 0.0)
    np.testing.assert_array_equal(c.mult, half)
    m.accept(pred, 1.0)
    assert not np.any(c.mult)  # released: mu = min(0, c (psi + dpsi . du)) = 0
    m.restore(half)
    m.commit()
    m.begin()
    np.testing.assert_array_equal(c.mult, half)
    m.reset()
    assert c.mult is None
    c.k_V_kPa = 0.0  # penalty off: nothing carried
    m.begin()
    assert c.mult is None and m.predict(du) is None

"""The sutures' threads (`woundsweep.contact.cable`): the residual is the energy's gradient and
the tangent its Hessian (finite differences), tension only, and the weights' coupling."""

from __future__ import annotations

import numpy as np
import pytest

from woundsweep.contact import Anchor, Cables


def _loops(rng: np.random.Generator, n_nodes: int) -> tuple[np.ndarray, list[list[Anchor]]]:
    X = rng.normal(size=(n_nodes, 3)) * 2.0
    loops = []
    for _ in range(2):
        anchors = []
        for _ in range(4):
            nodes = rng.choice(n_nodes, size=5, replace=False)
            w = rng.uniform(-0.2, 1.0, size=5)  # P2 weights may be negative
            anchors.append(Anchor(nodes, w / w.sum()))
        loops.append(anchors)
    return X, loops


def test_residual_and_tangent_are_the_energy_s_derivatives() -> None:
    rng = np.random.default_rng(3)
    X, loops = _loops(rng, 30)
    c = Cables(X, loops, EA_mN=50.0)
    u0 = rng.normal(size=3 * len(X)) * 0.05
    c.tie(u0, shorten_mm=0.3)  # taut: rest length 0.3 mm short of the length at u0
    u = u0 + rng.normal(size=3 * len(X)) * 0.02
    assert np.all(c.tensions(u) > 0)
    f, K = c.force_vector(u), c.tangent_csr(u).toarray()
    eps = 1e-6
    for i in rng.choice(len(u), size=25, replace=False):
        e = np.zeros_like(u)
        e[i] = eps
        fd = (c.energy(u + e) - c.energy(u - e)) / (2 * eps)
        assert fd == pytest.approx(f[i], rel=1e-6, abs=1e-9)
        dk = (c.force_vector(u + e) - c.force_vector(u - e)) / (2 * eps)
        assert dk == pytest.approx(K[:, i], rel=1e-5, abs=1e-7)
    assert K == pytest.approx(K.T)
    # K is the sparse part plus U diag(c) U^T (`low_rank`): a loop of A anchors depends on
    # their differences only, so each of its two terms adds at most 3 (A - 1) columns; the
    # sparse part stays in the pattern of the representatives.
    U, cv = c.low_rank(u)
    assert U.shape == (len(u), len(cv)) and len(cv) <= len(loops) * 2 * 3 * (4 - 1)
    S = c.sparse_tangent_csr(u).tocoo()
    assert np.all(c.coupling_pattern()[S.row, S.col] == 1)
    assert c.coupling_pattern().nnz <= len(loops) * (3 * 4) ** 2


def test_tension_only_and_balanced() -> None:
    rng = np.random.default_rng(5)
    X, loops = _loops(rng, 30)
    c = Cables(X, loops, EA_mN=50.0)
    u0 = np.zeros(3 * len(X))
    assert not c.active and np.all(c.force_vector(u0) == 0)
    c.tie(u0, shorten_mm=-0.5)  # slack by 0.5 mm
    assert np.all(c.tensions(u0) == 0) and c.energy(u0) == 0
    c.tie(u0, shorten_mm=0.1)
    T = c.tensions(u0)
    assert T == pytest.approx(50.0 / c.rest_mm * 0.1)
    # A loop's forces on the tissue balance (no net force from a closed thread).
    f = c.force_vector(u0).reshape(-1, 3)
    assert f.sum(axis=0) == pytest.approx(np.zeros(3), abs=1e-9)


def test_a_straight_pull_between_two_anchors() -> None:
    # Two anchors 10 mm apart along x, each the mean of two nodes: a loop of two strands,
    # perimeter 20 mm; shortened by 0.2 mm, T = EA / L0 * 0.2 and each anchor is pulled
    # toward the other with 2 T, shared equally by its nodes.
    X = np.array([[0.0, -1, 0], [0.0, 1, 0], [10.0, -1, 0], [10.0, 1, 0]])
    half = np.array([0.5, 0.5])
    c = Cables(X, [[Anchor(np.array([0, 1]), half), Anchor(np.array([2, 3]), half)]], 1000.0)
    c.tie(np.zeros(12), shorten_mm=0.2)
    T = float(c.tensions(np.zeros(12))[0])
    assert T == pytest.approx(1000.0 / 19.8 * 0.2)
    f = c.force_vector(np.zeros(12)).reshape(-1, 3)
    assert f[:, 0] == pytest.approx([-T, -T, T, T])  # dPi/du: the pull is minus it


def test_a_pulled_loop_is_the_gradient_of_t_times_its_length_and_holds_there() -> None:
    rng = np.random.default_rng(7)
    X, loops = _loops(rng, 30)
    c = Cables(X, loops, EA_mN=50.0)
    c.pull(3.0)
    u = rng.normal(size=3 * len(X)) * 0.05
    assert c.tensions(u) == pytest.approx([3.0, 3.0])
    assert c.energy(u) == pytest.approx(3.0 * c.lengths(u).sum())
    f, K = c.force_vector(u), c.tangent_csr(u).toarray()
    eps = 1e-6
    for i in rng.choice(len(u), size=20, replace=False):
        e = np.zeros_like(u)
        e[i] = eps
        assert (c.energy(u + e) - c.energy(u - e)) / (2 * eps) == pytest.approx(
            f[i], rel=1e-6, abs=1e-9
        )
        dk = (c.force_vector(u + e) - c.force_vector(u - e)) / (2 * eps)
        assert dk == pytest.approx(K[:, i], rel=1e-5, abs=1e-7)
    # Held at that state, each loop carries the pull there and resists stretching.
    c.hold(u)
    assert c.pull_mN is None and c.tensions(u) == pytest.approx([3.0, 3.0], rel=1e-9)

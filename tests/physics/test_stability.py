"""lowest_eigenvalues against dense eigenvalues of the same matrices."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from woundsweep.physics.stability import lowest_eigenvalues


def _laplacian_like(n: int, shift: float) -> scipy.sparse.csr_matrix:
    """1D stiffness tridiag(-1, 2, -1) minus ``shift`` I: eigenvalues 2 - 2 cos(j pi / (n+1))
    - shift, so a shift above the smallest makes the lowest ones negative (an unstable state)."""
    main = np.full(n, 2.0 - shift)
    off = -np.ones(n - 1)
    return scipy.sparse.diags([off, main, off], [-1, 0, 1], format="csr")


@pytest.mark.parametrize("shift", [0.0, 1e-3, 0.05])
def test_eigenvalues_nearest_zero_of_the_free_block(shift: float) -> None:
    n = 400
    rng = np.random.default_rng(3)
    K = _laplacian_like(n, shift).tolil()
    # A non-symmetric perturbation (a follower load): only the symmetric part counts.
    for _ in range(50):
        i, j = rng.integers(0, n, size=2)
        K[i, j] += 1e-3
    K = K.tocsr()
    free = np.ones(n, dtype=bool)
    free[[0, 17, n - 1]] = False  # Dirichlet dofs dropped
    got = lowest_eigenvalues(K, free, k=3)
    idx = np.flatnonzero(free)
    D = K.toarray()[np.ix_(idx, idx)]
    w = np.linalg.eigvalsh(0.5 * (D + D.T))
    nearest = np.sort(w[np.argsort(np.abs(w))[:3]])
    np.testing.assert_allclose(got, nearest, rtol=1e-8, atol=1e-10)
    # The smallest eigenvalue of the unshifted matrix is about 6e-5: shifted past it, unstable.
    assert (got[0] < 0.0) == (shift >= 1e-3)


def test_small_problems_are_solved_densely_and_exactly() -> None:
    K = scipy.sparse.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.0, 5.0]]))
    got = lowest_eigenvalues(K, np.array([True, True, False]), k=3)
    np.testing.assert_allclose(got, np.sort(np.linalg.eigvalsh([[2.0, 1.0], [1.0, -1.0]]))[:1])


def test_no_free_dofs_is_an_error() -> None:
    with pytest.raises(ArithmeticError):
        lowest_eigenvalues(scipy.sparse.eye(3, format="csr"), np.zeros(3, dtype=bool))

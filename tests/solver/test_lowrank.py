"""The Woodbury solve of a tangent with a low-rank part (`woundsweep.solver.lowrank`) against a
dense solve of the whole matrix, Dirichlet rows eliminated as Newton eliminates them."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from woundsweep.solver.lowrank import LowRankUpdate


@pytest.mark.parametrize("signs", [(1.0, 1.0, 0.0), (1.0, -0.5, 2.0)])
def test_woodbury_matches_the_dense_solve(signs: tuple[float, ...]) -> None:
    rng = np.random.default_rng(11)
    n, r = 40, 3
    M = rng.normal(size=(n, n))
    A = M @ M.T + n * np.eye(n)  # regular, symmetric
    U = scipy.sparse.csr_matrix(rng.normal(size=(n, r)) * (rng.uniform(size=(n, r)) < 0.3))
    c = 5.0 * np.array(signs)
    rows = np.array([0, 7, 19])
    rhs = rng.normal(size=n)
    # The whole matrix with the rows (and columns) eliminated, the prescribed values lifted.
    J = A + U.toarray() @ np.diag(c) @ U.toarray().T
    free = np.setdiff1d(np.arange(n), rows)
    expected = np.empty(n)
    expected[rows] = rhs[rows]
    b = rhs[free] - J[np.ix_(free, rows)] @ rhs[rows]
    expected[free] = np.linalg.solve(J[np.ix_(free, free)], b)
    # A eliminated the same way (as `NewtonSolver._factor` under LDL^T), its lift in rhs.
    Ae = A.copy()
    work = rhs.copy()
    work[free] -= A[np.ix_(free, rows)] @ rhs[rows]
    Ae[rows, :] = 0.0
    Ae[:, rows] = 0.0
    Ae[rows, rows] = 1.0
    lr = LowRankUpdate(U, c, rows, work, lambda v: np.linalg.solve(Ae, v))
    du = lr.correct(np.linalg.solve(Ae, work))
    assert du == pytest.approx(expected, rel=1e-10, abs=1e-12)
    assert Ae @ du + lr.apply(du) == pytest.approx(work, rel=1e-10, abs=1e-12)

"""Stability of an equilibrium: the eigenvalues nearest zero of the symmetric part of the tangent.

A contact stage that fails either stalls at a stable state or follows an equilibrium path that has lost
stability and turns back in the penalty (a limit point: an eigenvalue of the tangent passes
through zero, and no equilibrium is near at a larger penalty). The wound model records, for a
failed contact stage, the lowest of the eigenvalues nearest zero at the last converged state,
so the two kinds of failure can be told apart (docs/model.md, "Stability of a failed contact stage").

The tangent is restricted to the free dofs (the Dirichlet rows and columns dropped) and
symmetrised, (K + K^T) / 2. For a conservative problem that is the second variation of the
energy, which decides stability; the contact stages are conservative, their closure traction
a dead load. Eigenvalues are in the tangent's units, mN/mm.
They are found by shift-invert Lanczos (scipy ``eigsh``) around a shift just below zero, so
the ones nearest zero come first, from either side.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

__all__ = ["lowest_eigenvalues"]


def lowest_eigenvalues(K: scipy.sparse.spmatrix, free: np.ndarray, k: int = 3) -> np.ndarray:
    """The ``k`` eigenvalues nearest zero (ascending) of the symmetric part of ``K`` restricted
    to the dofs where ``free`` is True. Raises ``ArithmeticError`` if they cannot be found."""
    K = scipy.sparse.csr_matrix(K)
    idx = np.flatnonzero(np.asarray(free, dtype=bool))
    Kf = K[idx][:, idx]
    S = (0.5 * (Kf + Kf.T)).tocsc()
    n = S.shape[0]
    if n == 0:
        raise ArithmeticError("no free dofs")
    k = min(k, n - 1) if n > 1 else 1
    if n <= 200:  # small: dense is exact and cheap
        return np.sort(np.linalg.eigvalsh(S.toarray()))[:k]
    scale = float(np.abs(S.diagonal()).max())
    # A shift exactly at an eigenvalue (0 at a limit point) would make the factorisation
    # singular: shift just below zero.
    sigma = -1e-6 * scale
    try:
        w = scipy.sparse.linalg.eigsh(S, k=k, sigma=sigma, which="LM", return_eigenvectors=False)
    except (RuntimeError, ValueError, scipy.sparse.linalg.ArpackError) as exc:
        raise ArithmeticError(f"eigenvalues not found: {exc}") from exc
    return np.sort(np.asarray(w, dtype=float))

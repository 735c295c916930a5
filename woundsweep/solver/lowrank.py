"""A tangent with a low-rank part kept out of the assembled matrix: J = A + U diag(c) U^T.

A problem may give part of its tangent in this form (``low_rank``; the sutures' threads,
whose assembled tangent would couple whole anchor regions densely, `woundsweep.contact.cable`).
Newton then factorises A alone and solves J du = b by the Woodbury identity,

    du = y - Z (I + diag(c) U^T Z)^-1 diag(c) U^T y,   y = A^-1 b,  Z = A^-1 U,

which holds for any c (zero or negative entries included): r more solves with A's factors a
step, r the columns of U, and an r x r dense solve.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse

__all__ = ["LowRankUpdate"]


class LowRankUpdate:
    """The Woodbury solve of (A + U diag(c) U^T) du = b with the Dirichlet ``rows``
    eliminated as A's are (the term's columns there lifted into the right-hand side, then its
    rows and columns zeroed); ``solve_a`` applies A^-1 with the current factors."""

    def __init__(
        self,
        U: Any,
        c: np.ndarray,
        rows: np.ndarray,
        rhs: np.ndarray,
        solve_a: Callable[[np.ndarray], np.ndarray],
    ) -> None:
        x0 = np.zeros(U.shape[0])
        x0[rows] = rhs[rows]
        if np.any(x0):  # the prescribed values' column terms move to the right-hand side
            lifted = U @ (c * (U.T @ x0))
            lifted[rows] = 0.0
            rhs -= lifted
        keep = np.ones(U.shape[0])
        keep[rows] = 0.0
        self.U = (scipy.sparse.diags(keep) @ U).tocsc()
        self.c = np.asarray(c, dtype=float)
        self.Z = np.empty(self.U.shape)
        for j in range(self.U.shape[1]):
            self.Z[:, j] = solve_a(self.U[:, j].toarray().ravel())
        S = np.eye(len(self.c)) + self.c[:, None] * (self.U.T @ self.Z)
        self._S = scipy.linalg.lu_factor(S)

    def correct(self, y: np.ndarray) -> np.ndarray:
        """du from y = A^-1 b (module docstring)."""
        return y - self.Z @ scipy.linalg.lu_solve(self._S, self.c * (self.U.T @ y))

    def apply(self, du: np.ndarray) -> np.ndarray:
        """U diag(c) U^T du: the term's share of J du."""
        return self.U @ (self.c * (self.U.T @ du))

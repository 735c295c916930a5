"""The sutured zone's tie (stages 4-6): the closed flanks held together where they are sutured.

Each closure-zone node of the left flank is paired with its mirror image across x = x_c on the
right flank (the mesh is mirror-symmetric, so the pairs are exact), and the pair's offset,
the change of u_L - u_R since the tie was set (the stage-2 state, where the zone is closed by
its Dirichlet condition), is held by the contact's penalty law in all three directions::

    Pi_t = sum_p (1/2) c_p |s_p|^2,   s_p = (u_L - u_R) - s0_p,   c_p = k_V A_p / h_p,

A_p and h_p the left node's lumped area and element size, k_V the stage's penalty. Across the
wound (x) the tie is the suture: it keeps the closed zone closed against whatever pushes the
flanks apart nearby; along it (y, z) it keeps the sutured flanks from sliding on each other.
A tied node is not a contact point (`FlankContact`'s ``tied``): the tie already keeps it off
its partner, and a second law on the same pair would fight the first at the scale of the
implicit surface's O(h^2) offset from the facets.

Why the tangential part: without it the two halves of the patch, joined only beneath the
wound, slide along the closed flanks almost freely at 45 degrees (lowest tangent eigenvalue
about 1e-3 mN/mm), and that mode makes the contact stages' Newton iterations cycle
(docs/model.md). A pair offset stays zero where nothing else acts: the tie carries only what
the closure load alone does not hold.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .surfaces import lumped_area, surface

__all__ = ["ZoneTie"]


class ZoneTie:
    """Mirror pairs of closure-zone nodes tied together (module docstring).

    ``X`` (n, 3) reference node coordinates; ``left_nodes``, ``right_nodes`` the zone's nodes
    on each flank; ``left_facets`` the left flank's facets (node numbering, for A_p and h_p);
    ``x_c`` the mirror plane. ValueError if a left node has no mirror image among
    ``right_nodes``. The tie is inert until `set_reference`.
    """

    def __init__(
        self,
        X: np.ndarray,
        left_nodes: np.ndarray,
        right_nodes: np.ndarray,
        left_facets: np.ndarray,
        x_c: float,
    ) -> None:
        X = np.asarray(X, dtype=float)
        left = np.asarray(left_nodes, dtype=np.int64)
        right = np.asarray(right_nodes, dtype=np.int64)
        left = left[np.abs(X[left, 0] - x_c) > 0]  # a node on the mirror plane is its own image
        self.n_dofs = 3 * len(X)
        if len(left) == 0 or len(right) == 0:
            self.pairs = np.zeros((0, 2), dtype=np.int64)
            self.weight = np.zeros(0)
        else:
            image = X[left].copy()
            image[:, 0] = 2.0 * x_c - image[:, 0]
            dist, idx = cKDTree(X[right]).query(image)
            tol = 1e-9 * float(np.ptp(X, axis=0).max())
            if np.any(dist > tol):
                raise ValueError(
                    f"{int(np.sum(dist > tol))} closure-zone nodes have no mirror image "
                    "across the wound's mid-plane"
                )
            self.pairs = np.stack([left, right[idx]], axis=1)
            flank = surface(X, np.asarray(left_facets, dtype=np.int64))
            at = np.searchsorted(flank.nodes, left)
            self.weight = lumped_area(X, flank.facets, left) / flank.size_mm[at]  # A_p / h_p
        self._dofs = np.concatenate([3 * self.pairs + k for k in (0, 1, 2)], axis=0)  # (3p, 2)
        self._w = np.tile(self.weight, 3)  # A_p / h_p per row of _dofs
        self._s0: np.ndarray | None = None
        self._unit: Any = None  # the tangent for k_V = 1, built once

    def __len__(self) -> int:
        return len(self.pairs)

    def _raw(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u)
        return u[self._dofs[:, 0]] - u[self._dofs[:, 1]]

    def set_reference(self, u: np.ndarray) -> None:
        """Tie the pairs at the state ``u``: its slip is zero."""
        self._s0 = self._raw(u)

    def release(self) -> None:
        """Untie (no forces until the next `set_reference`)."""
        self._s0 = None

    @property
    def active(self) -> bool:
        return self._s0 is not None and len(self.pairs) > 0

    def _slip_rows(self, u: np.ndarray) -> np.ndarray:
        """Offset change per row of ``_dofs`` (x, then y, then z components); zeros while
        untied."""
        if not self.active:
            return np.zeros(len(self._dofs))
        return self._raw(u) - self._s0

    def slip(self, u: np.ndarray) -> np.ndarray:
        """Offset change (mm) of every pair, (p, 3): x, y and z (zeros while untied)."""
        return self._slip_rows(u).reshape(3, -1).T

    def energy(self, u: np.ndarray, k_V_kPa: float) -> float:
        """Tie energy (mN mm)."""
        return float(0.5 * k_V_kPa * np.sum(self._w * self._slip_rows(u) ** 2))

    def force_vector(self, u: np.ndarray, k_V_kPa: float) -> np.ndarray:
        """dPi_t/du (flat, mN)."""
        out = np.zeros(self.n_dofs)
        f = k_V_kPa * self._w * self._slip_rows(u)
        out[self._dofs[:, 0]] += f  # each dof appears once: a node has one mirror image
        out[self._dofs[:, 1]] -= f
        return out

    def tangent_csr(self, k_V_kPa: float) -> Any:
        """d2Pi_t/du2 as a scipy CSR matrix (n_dofs square); it does not depend on u."""
        import scipy.sparse

        if self._unit is None:
            a, b, w = self._dofs[:, 0], self._dofs[:, 1], self._w
            rows = np.concatenate([a, b, a, b])
            cols = np.concatenate([a, b, b, a])
            vals = np.concatenate([w, w, -w, -w])
            shape = (self.n_dofs, self.n_dofs)
            self._unit = scipy.sparse.coo_matrix((vals, (rows, cols)), shape=shape).tocsr()
        return self._unit * k_V_kPa

    def coupling_pattern(self) -> Any:
        """Structure of the tangent (scipy CSR of ones, n_dofs square): fixed by the pairs."""
        K = self.tangent_csr(1.0)
        return type(K)((np.ones(K.nnz), K.indices, K.indptr), shape=K.shape)

    def force_mN(self, u: np.ndarray, k_V_kPa: float) -> float:
        """Total tie force, sum over pairs of |c_p s_p| (mN)."""
        s = self.slip(u)
        return float(np.sum(k_V_kPa * self.weight * np.linalg.norm(s, axis=1)))

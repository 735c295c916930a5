"""Interrupted sutures as closed loops of thread through four anchors (docs/model.md,
"Sutures").

A simple interrupted suture enters the skin at its left bite (E_L, a bite width outside the
wound's edge), runs down through the tissue and out of the left wall at the bite depth (W_L),
across the wound into the right wall (W_R), up to the right bite (E_R), and is knotted over the
top back to E_L. The thread slides freely through the tissue, so it has one tension T along
the loop; its length is::

    L = |W_L - E_L| + (x_WR - x_WL) + |E_R - W_R| + |E_L - E_R|,

the crossing measured across the wound (x: the wound's mid-plane is x = x_c), so it stays
smooth when the walls meet. An anchor is a weighted mean of node positions, p = sum_a w_a
(X_a + u_a), sum w_a = 1 (interpolation weights of a point in its cell,
`woundsweep.physics.sutures`). The loop carries tension only::

    Pi_s = sum_i (k / 2) <L_i - L0_i>_+^2,   T_i = k <L_i - L0_i>_+  (mN),

k the thread's axial stiffness (mN/mm), L0_i its rest length, set when it is tied (`tie`).
The force on the tissue at anchor j is -T dL/dp_j: at a bite, toward the other bite over the
top and toward its wall point; at a wall point, across the wound toward the other wall and
back toward its bite. Each suture's forces sum to zero. The tangent is exact:
B^T (k G G^T + T H) B, G = dL/dp, H = d2L/dp2 (the three chords' (I - e e^T) / l blocks), B
the anchors' interpolation.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse

__all__ = ["ANCHORS", "SutureMembers"]

# The anchors of a loop, in order: the left bite, the left wall point, the right wall point,
# the right bite.
ANCHORS = ("bite_left", "wall_left", "wall_right", "bite_right")
_CHORDS = ((0, 1), (2, 3), (3, 0))  # straight runs of thread: (from, to)
_EX = np.array([1.0, 0.0, 0.0])


class SutureMembers:
    """n suture loops (module docstring). ``anchors``: per suture four (nodes, weights), in
    the order of `ANCHORS`; ``stiffness_mN_per_mm``: k. Inactive until `tie`."""

    def __init__(
        self,
        n_nodes: int,
        anchors: Sequence[Sequence[tuple[np.ndarray, np.ndarray]]],
        stiffness_mN_per_mm: float,
    ) -> None:
        if not anchors:
            raise ValueError("no sutures")
        if not (np.isfinite(stiffness_mN_per_mm) and stiffness_mN_per_mm > 0):
            raise ValueError(f"suture stiffness {stiffness_mN_per_mm!r} must be positive")
        self.n_dofs = 3 * int(n_nodes)
        self.k = float(stiffness_mN_per_mm)
        self.nodes: list[np.ndarray] = []  # per suture: the anchors' nodes, concatenated
        self.B: list[np.ndarray] = []  # per suture: (4, nodes) interpolation weights
        for loop in anchors:
            if len(loop) != len(ANCHORS):
                raise ValueError(f"a suture needs {len(ANCHORS)} anchors")
            nodes = np.concatenate([np.asarray(n, dtype=np.int64) for n, _ in loop])
            B = np.zeros((len(ANCHORS), len(nodes)))
            at = 0
            for j, (n, w) in enumerate(loop):
                w = np.asarray(w, dtype=float)
                if len(w) != len(n) or len(w) == 0 or abs(w.sum() - 1) > 1e-9 or np.any(w < 0):
                    raise ValueError("an anchor's weights must be non-negative and sum to 1")
                B[j, at : at + len(w)] = w
                at += len(w)
            self.nodes.append(nodes)
            self.B.append(B)
        self.rest: np.ndarray | None = None
        self._pattern: Any = None

    def __len__(self) -> int:
        return len(self.nodes)

    @property
    def active(self) -> bool:
        return self.rest is not None

    def anchor_positions(self, u: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Deformed anchor positions (n, 4, 3)."""
        x = X + np.asarray(u).reshape(-1, 3)
        return np.array([B @ x[n] for n, B in zip(self.nodes, self.B)])

    @staticmethod
    def _length(p: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """L, G = dL/dp (4, 3) and H = d2L/dp2 (12, 12) of one loop's anchors p (4, 3)."""
        L = float(p[2, 0] - p[1, 0])
        G = np.zeros((4, 3))
        G[1] -= _EX
        G[2] += _EX
        H = np.zeros((12, 12))
        for a, b in _CHORDS:
            d = p[b] - p[a]
            ell = float(np.linalg.norm(d))
            e = d / ell
            L += ell
            G[a] -= e
            G[b] += e
            h = (np.eye(3) - np.outer(e, e)) / ell
            for i, j, s in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
                H[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += s * h
        return L, G, H

    def lengths(self, u: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Each loop's length L (mm)."""
        return np.array([self._length(p)[0] for p in self.anchor_positions(u, X)])

    def tension(self, u: np.ndarray, X: np.ndarray) -> np.ndarray:
        """T_i (mN): k times the stretch beyond the rest length; 0 while untied or slack."""
        if self.rest is None:
            return np.zeros(len(self))
        return self.k * np.maximum(self.lengths(u, X) - self.rest, 0.0)

    def tie(self, u: np.ndarray, X: np.ndarray, tension_mN: np.ndarray) -> None:
        """Tie every loop at the state ``u`` so that it carries ``tension_mN`` there:
        L0 = L - T / k."""
        t = np.asarray(tension_mN, dtype=float)
        if t.shape != (len(self),) or np.any(t < 0) or not np.all(np.isfinite(t)):
            raise ValueError("one non-negative tension per suture")
        self.rest = self.lengths(u, X) - t / self.k

    def release(self) -> None:
        self.rest = None

    def energy(self, u: np.ndarray, X: np.ndarray) -> float:
        """Pi_s (mN mm)."""
        return float(0.5 * np.sum(self.tension(u, X) ** 2) / self.k)

    def _dofs(self, i: int) -> np.ndarray:
        return (3 * self.nodes[i][:, None] + np.arange(3)[None, :]).ravel()

    def force_vector(self, u: np.ndarray, X: np.ndarray) -> np.ndarray:
        """dPi_s/du (flat, mN)."""
        out = np.zeros(self.n_dofs)
        if self.rest is None:
            return out
        for i, p in enumerate(self.anchor_positions(u, X)):
            L, G, _ = self._length(p)
            T = self.k * max(L - self.rest[i], 0.0)
            if T > 0.0:
                f = self.B[i].T @ (T * G)  # (nodes, 3)
                np.add.at(out, self._dofs(i), f.ravel())
        return out

    def _matrix(self, blocks: list[tuple[int, np.ndarray]]) -> Any:
        shape = (self.n_dofs, self.n_dofs)
        if not blocks:
            return scipy.sparse.csr_matrix(shape)
        rows, cols, vals = [], [], []
        for i, K in blocks:
            dofs = self._dofs(i)
            rows.append(np.repeat(dofs, len(dofs)))
            cols.append(np.tile(dofs, len(dofs)))
            vals.append(K.ravel())
        coo = scipy.sparse.coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape
        )
        return coo.tocsr()

    def tangent_csr(self, u: np.ndarray, X: np.ndarray) -> Any:
        """d2Pi_s/du2 (scipy CSR, n_dofs square)."""
        blocks = []
        if self.rest is not None:
            for i, p in enumerate(self.anchor_positions(u, X)):
                L, G, H = self._length(p)
                T = self.k * max(L - self.rest[i], 0.0)
                if T <= 0.0:
                    continue
                g = G.ravel()
                Kp = self.k * np.outer(g, g) + T * H  # (12, 12) over the anchors
                Bx = np.kron(self.B[i], np.eye(3))  # (12, 3 nodes)
                blocks.append((i, Bx.T @ Kp @ Bx))
        return self._matrix(blocks)

    def coupling_pattern(self) -> Any:
        """Structure of the tangent (CSR of ones): each loop's anchor nodes coupled."""
        if self._pattern is None:
            blocks = [(i, np.ones((3 * len(n), 3 * len(n)))) for i, n in enumerate(self.nodes)]
            P = self._matrix(blocks)
            P.data[:] = 1.0
            self._pattern = P
        return self._pattern

"""Sutures as threads: tension-only loops through anchor regions (docs/model.md, "Sutures").

A suture is a closed loop of thread through anchor points in the tissue (a simple interrupted
stitch: the entry point and the deep point of each flank's needle track, the knot's strand
above the wound and the buried strand below it). An anchor point is a fixed weighted average
of node positions (a distributing coupling, as an RBE3 element): x_a = sum_k w_k (X_k + u_k),
sum_k w_k = 1, so the thread's pull is spread over the anchor's nodes in proportion to the
weights and no node is held. The thread slides through the tissue without friction, so the
whole loop carries one tension; with its length l (the polygon's perimeter through the
anchor points), its rest length L0 and its axial stiffness k = EA / L0 the energy is::

    Pi_c = sum_i (1/2) k_i <l_i - L0_i>^2,   T_i = k_i <l_i - L0_i>   (tension only)

The force on anchor j is T g_j, g_j = dl/dx_j = e_(j-1,j) - e_(j,j+1) (the unit vectors of
its two strands), and on node k of it w_k T g_j; the tangent between anchors is
k H(l - L0) g g^T + T d2l/dx2, d2l/dx2 the strands' (1 / l_s)(I - e e^T) (H(0) = 1: a loop
tied taut resists stretching from its first step), mapped to the nodes by the weights. It is
the exact Hessian of Pi_c, so the problem keeps its potential and its symmetric tangent. It is
given in two parts: a sparse one (each anchor's heaviest node standing for it), assembled with
the tissue's, and a low-rank remainder the solver takes apart (`low_rank`). The
weights and the node sets are the caller's (`woundsweep.physics.thread`); this module needs
no finite-element library.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import scipy.sparse

__all__ = ["Anchor", "Cables"]


class Anchor(NamedTuple):
    """A distributing coupling: ``nodes`` (k,) and ``weights`` (k,) summing to 1."""

    nodes: np.ndarray
    weights: np.ndarray


class Cables:
    """Tension-only closed loops, the i-th through the anchors ``loops[i]`` in order (module
    docstring). ``X`` (n, 3) reference node coordinates; ``EA_mN`` the thread's axial
    stiffness (mN, modulus times cross-section). Slack (no force) until `tie`."""

    def __init__(self, X: np.ndarray, loops: list[list[Anchor]], EA_mN: float) -> None:
        if not loops or any(len(lp) < 2 for lp in loops):
            raise ValueError("every loop needs at least two anchors")
        if not (np.isfinite(EA_mN) and EA_mN > 0):
            raise ValueError(f"EA={EA_mN!r} mN must be positive")
        self.X = np.asarray(X, dtype=float)
        self.n_dofs = 3 * len(self.X)
        self.loops = [list(lp) for lp in loops]
        for lp in self.loops:
            for a in lp:
                if abs(float(np.sum(a.weights)) - 1.0) > 1e-9:
                    raise ValueError("an anchor's weights must sum to 1")
        self.EA_mN = float(EA_mN)
        self.rest_mm: np.ndarray | None = None
        # Pulled (`pull`): every loop carries this tension whatever its length (mN).
        self.pull_mN: float | None = None
        # Per loop: its nodes (unique) and the (anchors, nodes) weight matrix onto them.
        self._nodes: list[np.ndarray] = []
        self._W: list[np.ndarray] = []
        for lp in self.loops:
            nodes, inv = np.unique(np.concatenate([a.nodes for a in lp]), return_inverse=True)
            W = np.zeros((len(lp), len(nodes)))
            at = 0
            for j, a in enumerate(lp):
                np.add.at(W[j], inv[at : at + len(a.nodes)], a.weights)
                at += len(a.nodes)
            self._nodes.append(nodes.astype(np.int64))
            self._W.append(W)
        # Per loop, each anchor's heaviest node (`sparse_tangent_csr`).
        self._reps = [
            np.array([a.nodes[np.argmax(np.abs(a.weights))] for a in lp], dtype=np.int64)
            for lp in self.loops
        ]
        self._pattern: Any = None

    def __len__(self) -> int:
        return len(self.loops)

    @property
    def active(self) -> bool:
        return self.rest_mm is not None or self.pull_mN is not None

    def anchors(self, u: np.ndarray) -> list[np.ndarray]:
        """Per loop, (anchors, 3) its anchor points at the displacement ``u`` (flat dofs)."""
        x = self.X + np.asarray(u).reshape(-1, 3)
        return [W @ x[nodes] for W, nodes in zip(self._W, self._nodes)]

    @staticmethod
    def _strands(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors (anchors, 3) and lengths of the strands j -> j + 1 (closed)."""
        d = np.roll(p, -1, axis=0) - p
        ell = np.linalg.norm(d, axis=1)
        return d / ell[:, None], ell

    def lengths(self, u: np.ndarray) -> np.ndarray:
        return np.array([self._strands(p)[1].sum() for p in self.anchors(u)])

    def tie(self, u: np.ndarray, shorten_mm: float | np.ndarray = 0.0) -> None:
        """Tie every loop at the state ``u``: its rest length is its length there, less
        ``shorten_mm``."""
        self.pull_mN = None
        self.rest_mm = self.lengths(u) - np.asarray(shorten_mm, dtype=float)
        if np.any(self.rest_mm <= 0):
            raise ValueError("a loop's rest length must be positive")

    def pull(self, tension_mN: float) -> None:
        """Pull every loop with ``tension_mN`` whatever its length (a knot drawn with a
        given force): Pi_c = T sum_i l_i."""
        if not (np.isfinite(tension_mN) and tension_mN > 0):
            raise ValueError(f"tension={tension_mN!r} mN must be positive")
        self.rest_mm, self.pull_mN = None, float(tension_mN)

    def hold(self, u: np.ndarray) -> None:
        """Tie every pulled loop at the state ``u`` so that it carries the pull there: rest
        length l / (1 + T / EA), so k (l - L0) = T."""
        if self.pull_mN is None:
            raise RuntimeError("pull() first")
        t = self.pull_mN
        self.pull_mN = None
        self.rest_mm = self.lengths(u) / (1.0 + t / self.EA_mN)

    def release(self) -> None:
        self.rest_mm = self.pull_mN = None

    def stiffness(self) -> np.ndarray:
        """k_i = EA / L0_i (mN/mm)."""
        assert self.rest_mm is not None
        return self.EA_mN / self.rest_mm

    def tensions(self, u: np.ndarray) -> np.ndarray:
        """T_i (mN), zero while slack or untied."""
        if self.pull_mN is not None:
            return np.full(len(self), self.pull_mN)
        if self.rest_mm is None:
            return np.zeros(len(self))
        return self.stiffness() * np.maximum(self.lengths(u) - self.rest_mm, 0.0)

    def energy(self, u: np.ndarray) -> float:
        if self.pull_mN is not None:
            return float(self.pull_mN * self.lengths(u).sum())
        if self.rest_mm is None:
            return 0.0
        stretch = np.maximum(self.lengths(u) - self.rest_mm, 0.0)
        return float(0.5 * np.sum(self.stiffness() * stretch**2))

    def anchor_forces(self, u: np.ndarray) -> list[np.ndarray]:
        """Per loop, (anchors, 3): the force T g_j the tissue exerts on each anchor point
        through the thread, dPi_c/dx_j (the thread pulls the tissue with minus it)."""
        out = []
        for p, t in zip(self.anchors(u), self.tensions(u)):
            e, _ = self._strands(p)
            out.append(t * (np.roll(e, 1, axis=0) - e))
        return out

    def force_vector(self, u: np.ndarray) -> np.ndarray:
        """dPi_c/du (flat, mN)."""
        out = np.zeros(self.n_dofs)
        if not self.active:
            return out
        for nodes, W, f in zip(self._nodes, self._W, self.anchor_forces(u)):
            out.reshape(-1, 3)[nodes] += W.T @ f
        return out

    def _dofs(self, nodes: np.ndarray) -> np.ndarray:
        return (3 * nodes[:, None] + np.arange(3)[None, :]).ravel()

    def _anchor_tangent(self, p: np.ndarray, k: float, t: float) -> np.ndarray:
        """(3A, 3A) d2Pi/dx_a2 of one loop through the anchor points ``p``."""
        A = len(p)
        e, ell = self._strands(p)
        g = (np.roll(e, 1, axis=0) - e).ravel()
        K = k * np.outer(g, g)
        for j in range(A):
            P = (np.eye(3) - np.outer(e[j], e[j])) * (t / ell[j])
            a, b = 3 * j, 3 * ((j + 1) % A)
            K[a : a + 3, a : a + 3] += P
            K[b : b + 3, b : b + 3] += P
            K[a : a + 3, b : b + 3] -= P
            K[b : b + 3, a : a + 3] -= P
        return K

    def _loop_tangents(self, u: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """Per loop that pulls: (its index, its anchor tangent d2Pi/dx_a2, (3A, 3A))."""
        T = self.tensions(u)
        L = self.lengths(u)
        out = []
        for i, p in enumerate(self.anchors(u)):
            if self.pull_mN is not None:  # a constant pull: the strands' turning only
                out.append((i, self._anchor_tangent(p, 0.0, self.pull_mN)))
            elif self.rest_mm is not None:
                k = float(self.stiffness()[i]) if L[i] >= self.rest_mm[i] else 0.0
                out.append((i, self._anchor_tangent(p, k, float(T[i]))))
        return out

    def sparse_tangent_csr(self, u: np.ndarray) -> Any:
        """The tangent's sparse part (scipy CSR, n_dofs square): each loop's anchor tangent on
        its anchors' representative nodes (each anchor's heaviest) alone. It stands for the
        loop in the assembled matrix, which then stays regular where only the threads join
        the tissue (a wound cut through); `low_rank` holds the rest."""
        rows, cols, vals = [], [], []
        for i, Ka in self._loop_tangents(u):
            dofs = self._dofs(self._reps[i])
            rows.append(np.repeat(dofs, len(dofs)))
            cols.append(np.tile(dofs, len(dofs)))
            vals.append(Ka.ravel())
        if not vals:
            return scipy.sparse.csr_matrix((self.n_dofs, self.n_dofs))
        K = scipy.sparse.coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(self.n_dofs, self.n_dofs),
        ).tocsr()
        K.sum_duplicates()
        return K

    def low_rank(self, u: np.ndarray) -> tuple[Any, np.ndarray]:
        """The tangent less its sparse part, U diag(c) U^T: (U, scipy CSR n_dofs x r; c,
        (r,)). Per loop, with Ka = V diag(lam) V^T its anchor tangent's eigenpairs of
        non-zero eigenvalue (a loop's energy depends on its anchors' differences only: at
        most 3 (A - 1)), the columns B^T V with lam and E^T V with -lam, B the weights' map
        from nodes to anchor points and E the representatives'. Assembled, B^T Ka B would
        couple every node of a loop to every other, a dense block the factorisation fills;
        Newton takes this part by the Woodbury identity instead (`woundsweep.solver.newton`)."""
        rows, cols, vals, cs = [], [], [], []
        r = 0
        for i, Ka in self._loop_tangents(u):
            lam, V = np.linalg.eigh(Ka)
            keep = np.abs(lam) > 1e-12 * max(float(np.abs(lam).max()), 1e-300)
            m = int(keep.sum())
            if m == 0:
                continue
            V = V[:, keep]
            W = self._W[i]
            for nodes, B, sign in (
                (self._nodes[i], np.kron(W, np.eye(3)), 1.0),
                (self._reps[i], np.eye(3 * len(W)), -1.0),
            ):
                dofs = self._dofs(nodes)
                rows.append(np.repeat(dofs, m))
                cols.append(np.tile(np.arange(r, r + m), len(dofs)))
                vals.append((B.T @ V).ravel())
                cs.append(sign * lam[keep])
                r += m
        if r == 0:
            return scipy.sparse.csr_matrix((self.n_dofs, 0)), np.zeros(0)
        U = scipy.sparse.coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(self.n_dofs, r),
        ).tocsr()
        U.sum_duplicates()
        return U, np.concatenate(cs)

    def tangent_csr(self, u: np.ndarray) -> Any:
        """d2Pi_c/du2 assembled (scipy CSR, n_dofs square): dense over each loop's nodes."""
        U, c = self.low_rank(u)
        return (self.sparse_tangent_csr(u) + U @ scipy.sparse.diags(c) @ U.T).tocsr()

    def coupling_pattern(self) -> Any:
        """`sparse_tangent_csr`'s structure (CSR of ones): each loop's representatives."""
        if self._pattern is None:
            rows, cols = [], []
            for reps in self._reps:
                dofs = self._dofs(reps)
                rows.append(np.repeat(dofs, len(dofs)))
                cols.append(np.tile(dofs, len(dofs)))
            r, c = np.concatenate(rows), np.concatenate(cols)
            P = scipy.sparse.csr_matrix(
                (np.ones(len(r), dtype=np.int32), (r, c)), shape=(self.n_dofs, self.n_dofs)
            )
            P.sum_duplicates()
            P.data[:] = 1
            self._pattern = P
        return self._pattern

"""The displacement element: Lagrange tetrahedra of degree 1 (P1) or 2 (P2).

A P2 cell's ten nodes are its four vertices and its six edge midpoints (DOLFINx's layout:
vertices first, then the edges of the reference tetrahedron in `EDGES` order, checked
against the coordinates). For the surface algorithms (closure zone, contact, tie) a P2
boundary triangle is split into four flat triangles through its six nodes, with the parent's
orientation; for P1 the triangle is its own. Kinematics: the displacement gradient of a P2
cell is linear, and is evaluated at the four points of the degree-2 quadrature rule, where
the energy is evaluated (the P1 gradient is constant).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EDGES", "POINTS", "Element"]

# Local vertex pairs of the edges of the reference tetrahedron, in DOLFINx's (Basix's) order.
EDGES = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))
# Barycentric coordinates of the symmetric 4-point degree-2 rule on a tetrahedron.
_A, _B = 0.5854101966249685, 0.1381966011250105
POINTS = np.full((4, 4), _B) + np.eye(4) * (_A - _B)


class Element:
    """Node bookkeeping and kinematics of a Lagrange element on a tetrahedral mesh.

    ``X`` (n, 3) node coordinates; ``cell_nodes`` (m, 4) or (m, 10) node indices per cell;
    ``Dm_inv`` (m, 3, 3) the inverse of each cell's edge matrix [x1 - x0, x2 - x0, x3 - x0].
    """

    def __init__(self, X: np.ndarray, cell_nodes: np.ndarray, Dm_inv: np.ndarray) -> None:
        width = cell_nodes.shape[1]
        if width not in (4, 10):
            raise ValueError(f"expected 4 or 10 nodes per cell, got {width}")
        self.degree = 1 if width == 4 else 2
        self.n_nodes = len(X)
        self.cell_nodes = cell_nodes
        self.Dm_inv = Dm_inv
        if self.degree == 1:
            return
        verts = cell_nodes[:, :4].astype(np.int64)  # edge keys reach n^2: no int32
        pairs = np.asarray(EDGES)
        a, b = verts[:, pairs[:, 0]], verts[:, pairs[:, 1]]
        mids = cell_nodes[:, 4:]
        scale = float(np.ptp(X, axis=0).max())
        if np.abs(0.5 * (X[a] + X[b]) - X[mids]).max() > 1e-9 * scale:
            raise ValueError("the P2 dofs are not at the cells' edge midpoints")
        keys = np.minimum(a, b).ravel() * self.n_nodes + np.maximum(a, b).ravel()
        self._edge_keys, first = np.unique(keys, return_index=True)
        self._edge_mid = mids.ravel()[first]
        # Gradients of the ten basis functions at the rule's points, per cell: (m, 4, 10, 3).
        # grad lambda_i are the rows of Dm_inv (i = 1..3) and minus their sum (i = 0).
        g = np.empty((len(verts), 4, 3))
        g[:, 1:, :] = Dm_inv
        g[:, 0, :] = -Dm_inv.sum(axis=1)
        G = np.zeros((len(verts), len(POINTS), 10, 3))
        for k, lam in enumerate(POINTS):
            for i in range(4):
                G[:, k, i] = (4.0 * lam[i] - 1.0) * g[:, i]
            for e, (i, j) in enumerate(EDGES):
                G[:, k, 4 + e] = 4.0 * (lam[j] * g[:, i] + lam[i] * g[:, j])
        self._G = G

    def midpoints(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The midpoint nodes of the edges (a, b) (P2; KeyError-like ValueError if none)."""
        a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
        keys = np.minimum(a, b) * self.n_nodes + np.maximum(a, b)
        pos = np.minimum(np.searchsorted(self._edge_keys, keys), len(self._edge_keys) - 1)
        if not np.all(self._edge_keys[pos] == keys):
            raise ValueError("an edge of a boundary triangle is not an edge of the mesh")
        return self._edge_mid[pos]

    def triangle_nodes(self, tri: np.ndarray) -> np.ndarray:
        """Every node of the boundary triangles ``tri`` (k, 3 vertex nodes), unique."""
        return np.unique(self.sub_triangles(tri))

    def sub_triangles(self, tri: np.ndarray) -> np.ndarray:
        """Flat triangles through the nodes of ``tri`` (k, 3), oriented as their parents:
        ``tri`` itself for P1, four per triangle for P2."""
        tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
        if self.degree == 1:
            return tri
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        ab, bc, ca = self.midpoints(a, b), self.midpoints(b, c), self.midpoints(c, a)
        return np.stack(
            [np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))],
            axis=1,
        ).reshape(-1, 3)

    def grad(self, w: np.ndarray) -> np.ndarray:
        """Displacement gradients (p, 3, 3) of a vector field given as flat dofs: one per
        P1 cell, one per quadrature point (`POINTS`) of each P2 cell."""
        W = w.reshape(-1, 3)[self.cell_nodes]
        if self.degree == 1:
            Dw = np.transpose(W[:, 1:, :] - W[:, :1, :], (0, 2, 1))
            return Dw @ self.Dm_inv
        return np.einsum("mkad,mac->mkcd", self._G, W).reshape(-1, 3, 3)

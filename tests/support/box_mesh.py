"""Structured tetrahedral boxes for the contact and stage tests (numpy only)."""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_facets", "box_tets", "grid_tets"]


def grid_tets(*axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tensor grid of the three coordinate arrays ``axes``, each grid box split into six
    tets. Returns (points, cells)."""
    nx, ny, nz = (len(a) - 1 for a in axes)
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k  # noqa: E731
    ii, jj, kk = (a.ravel() for a in np.meshgrid(range(nx), range(ny), range(nz), indexing="ij"))
    corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1),
               (0, 1, 1)]  # fmt: skip
    V = np.stack([idx(ii + a, jj + b, kk + c) for a, b, c in corners], axis=1)
    tets = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]
    return pts, np.concatenate([V[:, list(t)] for t in tets])


def box_tets(n: int | tuple[int, int, int], lo: tuple[float, float, float],
             hi: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Box [lo, hi] split into n (or n[0] x n[1] x n[2]) grid boxes of six tets each.

    Returns (points, cells)."""
    counts = (n, n, n) if isinstance(n, int) else n
    return grid_tets(*(np.linspace(a, b, m + 1) for a, b, m in zip(lo, hi, counts)))


def boundary_facets(cells: np.ndarray) -> np.ndarray:
    """Faces that belong to one cell only (sorted node order, i.e. arbitrary orientation)."""
    faces = np.concatenate([cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]],
                            cells[:, [0, 1, 2]]])  # fmt: skip
    uniq, count = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    return uniq[count == 1]

"""Topology of the wound's triangle surfaces: which cell owns a facet, outward orientation,
and the split of the wound surface into its two flanks."""

from __future__ import annotations

import numpy as np

__all__ = ["face_keys", "orient_outward", "owning_cells", "split_wound_flanks"]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def face_keys(tri: np.ndarray, n: int) -> np.ndarray:
    """One int64 key per triangle (k, 3) of point indices below ``n``, whatever its vertex
    order: equal keys, same face."""
    t = np.sort(np.asarray(tri, dtype=np.int64), axis=1)
    return (t[:, 0] * n + t[:, 1]) * n + t[:, 2]


def owning_cells(cells: np.ndarray, facets: np.ndarray, n_points: int) -> np.ndarray:
    """Index of a cell (m, 4) of which each facet (k, 3) is a face (same node numbering)."""
    cells = np.asarray(cells, dtype=np.int64)
    faces = np.concatenate([cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]],
                            cells[:, [0, 1, 2]]])  # fmt: skip
    owner = np.tile(np.arange(len(cells)), 4)
    keys = face_keys(faces, n_points)
    order = np.argsort(keys)
    want = face_keys(facets, n_points)
    pos = np.minimum(np.searchsorted(keys, want, sorter=order), len(order) - 1)
    if not np.all(keys[order[pos]] == want):
        raise ValueError("a boundary facet is not a face of any cell")
    return owner[order[pos]]


def orient_outward(X: np.ndarray, cells: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Boundary facets (node indices) reordered so that their normal points out of the body.

    ``X`` (n, 3) node coordinates, ``cells`` (m, 4) tetrahedra in the same node numbering.
    """
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 3)
    owner = np.asarray(cells, dtype=np.int64)[owning_cells(cells, facets, len(X))]
    apex = owner[np.all(owner[:, :, None] != facets[:, None, :], axis=2)]  # node off the facet
    inner = X[apex]
    p = X[facets]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = _dot(nrm, inner - p[:, 0]) > 0.0  # normal points toward the cell: flip it
    out = facets.copy()
    out[flip, 1], out[flip, 2] = facets[flip, 2], facets[flip, 1]
    return out


def split_wound_flanks(
    X: np.ndarray, cells: np.ndarray, wound_facets: np.ndarray, x_c: float
) -> tuple[np.ndarray, np.ndarray]:
    """The wound facets (node indices) split into (left, right) flanks by reference centroid
    x < x_c, each oriented outward (`orient_outward`)."""
    wound_facets = orient_outward(X, cells, wound_facets)
    left = X[wound_facets].mean(axis=1)[:, 0] < x_c
    return wound_facets[left], wound_facets[~left]

"""The pairing search: the master facet of each contact point at a deformed state."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from .geometry import edge_distance, facing_mask, fade_weight, projection
from .surfaces import Surface

__all__ = ["Closest", "closest_facets"]


class Closest(NamedTuple):
    """The master facet found for each contact point."""

    facet: np.ndarray  # (N,) master facet index (valid where ok)
    gap: np.ndarray  # (N,) signed plane distance to it
    ok: np.ndarray  # (N,) projection inside the facet's fade band, not excluded, facing


def closest_facets(
    x: np.ndarray,
    pts: np.ndarray,
    normals: np.ndarray,
    exclude: np.ndarray,
    master: Surface,
    shares: np.ndarray,
    *,
    neighbours: int,
    normal_cos: float,
    fade_width: float,
) -> Closest:
    """Master facet of each point: the best valid one (score: exact distance, plus the fade
    deficit times the facet size) among the ``neighbours`` facets with the nearest centroids.
    Valid: no node shared with ``exclude`` (N, j), facing the point's facet, projection
    inside the fade band. ``shares`` (N,) marks the points whose ``exclude`` nodes are on
    the master surface at all (the others cannot share a node: their check is skipped)."""
    tri = master.facets
    k = min(neighbours, len(tri))
    _, cand = cKDTree(x[tri].mean(axis=1)).query(pts, k=k)
    cand = np.asarray(cand).reshape(len(pts), k)
    ct = tri[cand]  # (N, k, 3)
    v = x[ct]
    v0, v1, v2 = v[..., 0, :], v[..., 1, :], v[..., 2, :]
    g, lam = projection(pts[:, None, :], v0, v1, v2)
    own = np.zeros(cand.shape, dtype=bool)
    rows = np.flatnonzero(shares)
    own[rows] = np.any(ct[rows, :, :, None] == exclude[rows, None, None, :], axis=(2, 3))
    m = np.cross(v1 - v0, v2 - v0)
    mu = np.linalg.norm(m, axis=-1)
    facing = facing_mask(normals[:, None, :], m, mu, normal_cos)
    # A point stays paired up to fade_width beyond the facet's edges (its weight fading
    # to 0 there); where the surface goes on, a neighbour takes over first. Only valid
    # facets compete, so a point is dropped only when none is left (a closest facet that
    # is not valid must not hide a valid one behind it: that made pairings flip).
    lam_min = lam.min(axis=2)
    valid = ~own & facing & (lam_min > -fade_width)
    # Exact distance: |g| where the projection is on the facet, else to the nearest edge,
    # computed for valid candidates only (most of the k are far outside their facet).
    dist = np.abs(g)
    fading = valid & (lam_min < 0.0)
    if fading.any():
        pp = np.broadcast_to(pts[:, None, :], v0.shape)[fading]
        dist[fading] = edge_distance(pp, v0[fading], v1[fading], v2[fading])
    # Prefer the facet that the projection falls into: past the edges between facets the
    # exact distances tie (distance to the shared edge), the weights do not.
    deficit = np.zeros(lam.shape[:2])
    deficit[fading] = 1.0 - fade_weight(lam[fading], fade_width)[0]
    score = np.where(valid, dist + deficit * np.sqrt(mu), np.inf)
    best = np.argmin(score, axis=1)
    r = np.arange(len(pts))
    facet = cand[r, best]
    ok = valid[r, best]
    return Closest(facet, g[r, best], ok)

"""Contact surfaces in node numbering, with the element size at their nodes (reference), and
the passes of a two-pass contact with their point-facet neighbour search."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["FlankPass", "Surface", "lumped_area", "near_pairs", "surface", "triangle_areas"]


class Surface(NamedTuple):
    """One contact surface in node numbering (reference configuration)."""

    facets: np.ndarray  # (nf, 3) node indices, normal (right-hand rule) points out of the body
    nodes: np.ndarray  # (ns,) the facets' nodes, sorted
    size_mm: np.ndarray  # (ns,) element size at each node (mean over its facets)


def triangle_areas(p: np.ndarray) -> np.ndarray:
    """Areas of triangles given as (k, 3, 3) vertex coordinates."""
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def surface(X: np.ndarray, facets: np.ndarray) -> Surface:
    """The surface of outward-oriented ``facets`` with the element size at each node."""
    area = triangle_areas(X[facets])
    nodes, inv = np.unique(facets.ravel(), return_inverse=True)
    tri_area = np.bincount(inv, weights=np.repeat(area, 3), minlength=len(nodes))
    count = np.bincount(inv, minlength=len(nodes))
    size = np.sqrt(4.0 * (tri_area / count) / np.sqrt(3.0))  # side of the equilateral triangle
    return Surface(facets, nodes, size)


def lumped_area(X: np.ndarray, facets: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """A third of the reference area of the facets around each of ``nodes`` (mm^2)."""
    area = triangle_areas(X[facets])
    per_node = np.bincount(facets.ravel(), weights=np.repeat(area / 3.0, 3), minlength=len(X))
    return per_node[nodes]


class FlankPass(NamedTuple):
    """One pass: the slave flank's contact points against the master flank's facets."""

    nodes: np.ndarray  # (nq,) slave nodes
    area_mm2: np.ndarray  # (nq,) reference area per point
    size_mm: np.ndarray  # (nq,) h per point
    facets: np.ndarray  # (nf, 3) master facets, outward
    rho_mm: np.ndarray  # (nf,) kernel radius per master facet
    support_mm2: np.ndarray  # (nq,) D_full of each point: pi rho^2 / 4 at its own size


def near_pairs(x: np.ndarray, ps: FlankPass, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(point, facet) index pairs of pass ``ps`` at positions ``x``, ordered by point then
    facet, with the point closer than ``scale`` kernel radii to the facet's centroid."""
    if len(ps.nodes) == 0 or len(ps.facets) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    cen = x[ps.facets].mean(axis=1)
    xq = x[ps.nodes]
    r = scale * ps.rho_mm
    found = cKDTree(xq).sparse_distance_matrix(
        cKDTree(cen), max_distance=float(r.max()), output_type="ndarray"
    )
    q = found["i"].astype(np.int64)
    f = found["j"].astype(np.int64)
    order = np.argsort(q * len(ps.facets) + f)  # the tree gives them in no set order
    q, f = q[order], f[order]
    d2 = np.sum((xq[q] - cen[f]) ** 2, axis=1)
    near = d2 < r[f] ** 2
    return q[near], f[near]

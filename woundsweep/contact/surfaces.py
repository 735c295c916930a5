"""Contact surfaces in node numbering, with the element size at their nodes (reference)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Surface", "lumped_area", "surface", "triangle_areas"]


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

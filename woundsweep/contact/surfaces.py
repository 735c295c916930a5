"""Contact surfaces and the contact points their facets carry (reference configuration)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["RULE_BARY", "RULE_WEIGHT", "ContactPoints", "Surface", "contact_points", "surface"]


class Surface(NamedTuple):
    """One contact surface in node numbering (reference configuration)."""

    facets: np.ndarray  # (nf, 3) node indices, normal (right-hand rule) points out of the body
    nodes: np.ndarray  # (ns,) the facets' nodes, sorted
    size_mm: np.ndarray  # (ns,) element size at each node (mean over its facets)


def surface(X: np.ndarray, facets: np.ndarray) -> Surface:
    """The surface of outward-oriented ``facets`` with the element size at each node."""
    p = X[facets]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    nodes, inv = np.unique(facets.ravel(), return_inverse=True)
    tri_area = np.bincount(inv, weights=np.repeat(area, 3), minlength=len(nodes))
    count = np.bincount(inv, minlength=len(nodes))
    size = np.sqrt(4.0 * (tri_area / count) / np.sqrt(3.0))  # side of the equilateral triangle
    return Surface(facets, nodes, size)


# Contact points per slave facet (barycentric coordinates, share of the facet's area): the
# symmetric 3-point rule (2/3, 1/6, 1/6) carries 3/4 of the area, and three points close to
# the vertices (1 - 2 a, a, a) with a = 1/50 carry 1/12 each, so that no corner of a flank can
# cross the other flank unseen (with the 3-point rule alone the top corners of a closed wound
# crossed by 6% of an element). The points stay inside the facet: no point sits on a vertex or
# an edge, where the master facet of a mirror-image mesh would be ambiguous.
_A = 1.0 / 50.0
RULE_BARY = np.concatenate(
    [
        np.array([[4.0, 1.0, 1.0], [1.0, 4.0, 1.0], [1.0, 1.0, 4.0]]) / 6.0,
        np.array([[1 - 2 * _A, _A, _A], [_A, 1 - 2 * _A, _A], [_A, _A, 1 - 2 * _A]]),
    ]
)
RULE_WEIGHT = np.array([0.25, 0.25, 0.25, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 12.0])


class ContactPoints(NamedTuple):
    """Contact points of one slave surface (``len(RULE_WEIGHT)`` per facet)."""

    carrier: np.ndarray  # (nq, 3) nodes of the slave facet that holds the point
    bary: np.ndarray  # (nq, 3) the point's shape function values on that facet
    area_mm2: np.ndarray  # (nq,) reference area carried by the point
    size_mm: np.ndarray  # (nq,) h of the facet
    facet: np.ndarray  # (nq,) slave facet index


def contact_points(X: np.ndarray, facets: np.ndarray) -> ContactPoints:
    """The contact points of the slave facets ``facets`` (`RULE_BARY`, `RULE_WEIGHT`)."""
    p = X[facets]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    size = np.sqrt(4.0 * area / np.sqrt(3.0))  # side of the equilateral triangle of that area
    nq = len(RULE_WEIGHT)
    facet = np.repeat(np.arange(len(facets)), nq)
    return ContactPoints(
        facets[facet],
        np.tile(RULE_BARY, (len(facets), 1)),
        (area[:, None] * RULE_WEIGHT).ravel(),
        size[facet],
        facet,
    )

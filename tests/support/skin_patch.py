"""The two-layer skin patch of the stage tests: a structured tetrahedral box, its exact
homogeneous pre-stretch, and the relative L2 distance used to compare fields."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from box_mesh import boundary_facets, grid_tets

from woundsweep.physics.materials import homogeneous_state

SKIN_TYPES = ("normal", "stiff", "soft")
T_D, T_TOTAL, HALF = 1.0, 2.0, 2.0  # dermis and total thickness, patch half-length (mm)


class Patch(NamedTuple):
    points: np.ndarray
    cells: np.ndarray
    cell_tags: np.ndarray
    facets: np.ndarray
    facet_tags: np.ndarray


def box_patch(n_xy: int = 6, rotate: bool = False) -> Patch:
    """Two-layer square patch [-HALF, HALF]^2 x [-T_TOTAL, 0], six tets per grid box.

    ``rotate`` turns the points by +90 degrees about z (same cells), for the symmetry test.
    """
    xs = np.linspace(-HALF, HALF, n_xy + 1)
    zs = np.r_[np.linspace(-T_TOTAL, -T_D, 3)[:-1], np.linspace(-T_D, 0.0, 4)]
    pts, cells = grid_tets(xs, xs, zs)
    if rotate:
        pts = np.c_[-pts[:, 1], pts[:, 0], pts[:, 2]]
    mid = pts[cells].mean(axis=1)
    ctags = np.where(mid[:, 2] > -T_D, 1, 2).astype(np.int32)
    bf = boundary_facets(cells)
    c = pts[bf].mean(axis=1)
    ft = np.zeros(len(bf), dtype=np.int32)
    e = 1e-9
    ft[np.abs(c[:, 0] + HALF) < e], ft[np.abs(c[:, 0] - HALF) < e] = 11, 12
    ft[np.abs(c[:, 1] + HALF) < e], ft[np.abs(c[:, 1] - HALF) < e] = 13, 14
    ft[np.abs(c[:, 2] + T_TOTAL) < e], ft[np.abs(c[:, 2]) < e] = 15, 16
    assert (ft > 0).all()
    return Patch(pts, cells, ctags, bf, ft)


def homogeneous_field(points: np.ndarray, skin: str, angle: float) -> np.ndarray:
    """Displacement of the per-layer homogeneous pre-stretch (bottom fixed at z = -T_TOTAL)."""
    from woundsweep.physics.materials import JobMaterials

    mats = JobMaterials.table2(skin, angle)
    l_d = homogeneous_state(mats.dermis, mats.tsf).lambda3
    l_s = homogeneous_state(mats.subcutis, mats.tsf).lambda3
    x, y, z = points.T
    uz = np.where(
        z <= -T_D,
        (l_s - 1) * (z + T_TOTAL),
        (l_s - 1) * (T_TOTAL - T_D) + (l_d - 1) * (z + T_D),
    )
    return np.c_[(mats.tsf - 1) * x, (mats.tsf - 1) * y, uz]


def rel_l2(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))

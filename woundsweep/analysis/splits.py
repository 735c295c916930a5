"""Quantile classes and the two split schemes (row indices into the analysis rows).

* ``random``: rows drawn at random into train / validation / test, as the paper did; the
  stages, skin types and orientations of one geometry land in several sets.
* ``geometry``: whole physical geometries (all geometry keys except the mesh size factor, so
  the same wound meshed at several resolutions counts once) go to one set only.

Quantile edges are computed on each scheme's training rows only, so test rows never help
place them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pandas as pd

from ..core.errors import AnalysisError

__all__ = [
    "Split",
    "assign_quantiles",
    "geometry_groups",
    "geometry_split",
    "quantile_edges",
    "random_split",
]


def quantile_edges(stress: np.ndarray, q: int) -> np.ndarray:
    """``q + 1`` edges in kPa: the minimum, the ``k/q`` quantiles, the maximum."""
    s = np.asarray(stress, dtype=np.float64)
    if len(s) < q:
        raise AnalysisError(f"{len(s)} training rows cannot fill {q} quantiles")
    edges = np.quantile(s, np.linspace(0.0, 1.0, q + 1))
    if np.any(np.diff(edges[1:-1]) <= 0) or edges[1] <= edges[0]:
        raise AnalysisError(
            f"too few distinct stress values for {q} quantiles (tied quantile edges)"
        )
    return edges


def assign_quantiles(stress: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Class 0..q-1 of each stress; values outside the training range go to the end classes."""
    return np.searchsorted(edges[1:-1], np.asarray(stress, dtype=np.float64), side="right")


class Split(NamedTuple):
    """Sorted row indices of the three sets."""

    train: np.ndarray
    validation: np.ndarray
    test: np.ndarray


def random_split(n: int, train_fraction: float, validation_fraction: float, seed: int) -> Split:
    """The paper's split: rows drawn at random."""
    perm = np.random.default_rng(seed).permutation(n)
    n_train = int(round(train_fraction * n))
    n_val = int(round(validation_fraction * n))
    parts = (perm[:n_train], perm[n_train : n_train + n_val], perm[n_train + n_val :])
    return Split(*(np.sort(p) for p in parts))


def geometry_groups(rows: pd.DataFrame, scale_free: bool = False) -> np.ndarray:
    """Integer id of each row's physical geometry (geometry keys without the mesh size);
    ``scale_free``: without the dermal thickness too (the geometries of one dimensionless
    wound, which a scale-invariant model cannot tell apart, are one group)."""
    from ..config.sweep import GEOMETRY_KEYS

    left_out = ("mesh_size_factor", "dermal_thickness_mm") if scale_free else ("mesh_size_factor",)
    keys = [k for k in GEOMETRY_KEYS if k not in left_out]
    # NaN is not equal to itself: turn the not-applicable factors into a sentinel first.
    frame = rows[keys].astype(object).where(rows[keys].notna(), "n/a").astype(str)
    return pd.MultiIndex.from_frame(frame).factorize()[0]


def geometry_split(
    groups: np.ndarray, train_fraction: float, validation_fraction: float, seed: int
) -> Split:
    """Whole groups to one set: groups in random order fill train, then validation, then test."""
    groups = np.asarray(groups)
    ids, inverse, sizes = np.unique(groups, return_inverse=True, return_counts=True)
    order = np.random.default_rng(seed).permutation(len(ids))
    before = np.cumsum(sizes[order]) - sizes[order]  # rows already placed when a group comes
    n = len(groups)
    dest = np.where(
        before < train_fraction * n,
        0,
        np.where(before < (train_fraction + validation_fraction) * n, 1, 2),
    )
    set_of_group = np.empty(len(ids), dtype=np.int64)
    set_of_group[order] = dest
    row_set = set_of_group[inverse]
    return Split(*(np.flatnonzero(row_set == k) for k in range(3)))

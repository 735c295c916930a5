"""Deterministic partition of a manifest into N shards, balanced by an estimated cost.

Jobs are assigned one by one, longest-first to the currently lightest shard (LPT), ties broken
by shard number and by ``job_index``, so the result depends only on the manifest and N: every
node of a cluster computes the same partition without talking to the others. A shard holds
jobs of many geometries, so the estimate's error for one geometry (a log-CPU sd of about 0.24)
averages out over a shard; a geometry's mesh is built by each shard that needs it (about
0.1 s against seconds per job) or read from the run's mesh cache.
"""

from __future__ import annotations

import heapq
import re
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..config.manifest import JobRow
from ..config.sweep import DERIVED, GEOMETRY_KEYS
from ..core.errors import WoundsweepError

# The manifest columns a geometry's cost estimate reads besides GEOMETRY_KEYS.
_SPEC_COLUMNS = (*DERIVED, "job_index")
# CPU per job ~ (size-law cells)^COST_EXPONENT x SHAPE_COST[shape] x (OFF_AXIS_COST when the
# Langer line is not along x or y): least squares on log CPU per job (189 P2 jobs of nine random
# shards of 486, 21 geometries): residual sd 0.33 per job, 0.24 for a geometry's mean. A
# wedge's stage 2 and contact stages take more Newton steps than a cylinder's of as many
# cells; off the axes a job keeps only the half-turn of its symmetry (half the unknowns in the
# Newton solves against a quarter; docs/model.md, "Newton's method"). Shapes not in the table
# (the fusiform excision) are not fitted: weight 1.
COST_EXPONENT = 0.59
SHAPE_COST = {"cylindrical": 1.0, "wedge": 1.55}
OFF_AXIS_COST = 1.28

__all__ = [
    "COST_EXPONENT",
    "OFF_AXIS_COST",
    "SHAPE_COST",
    "Shard",
    "estimate_cells",
    "estimate_cost",
    "parse_shard",
    "partition",
    "shard_jobs",
]


class Shard(NamedTuple):
    """Shard ``index`` of ``count`` (0-based, as in ``--shard i/N``)."""

    # Fields named like tuple.index and tuple.count (they shadow the methods, never called).
    index: int  # type: ignore[assignment]
    count: int  # type: ignore[assignment]

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"


def parse_shard(text: str) -> Shard:
    """Parse ``"i/N"`` (0 <= i < N); raises ``ValueError`` with a one-line reason."""
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
    if not m:
        raise ValueError(f"shard {text!r}: expected i/N, e.g. 0/4")
    i, n = int(m.group(1)), int(m.group(2))
    if n < 1 or i >= n:
        raise ValueError(f"shard {text!r}: need N >= 1 and 0 <= i < N")
    return Shard(i, n)


def _cells_estimate(row: JobRow) -> float:
    """The mesh size law's cell count of the row's geometry (`mesh.sizing.estimate_cells`) on
    its P1 mesh, whatever the sweep's element: the cost fit above is over these counts, and
    the partition depends on the manifest alone."""
    from ..config.geometry import GeometrySpec
    from ..mesh.sizing import estimate_cells

    try:
        spec = GeometrySpec.from_row(row, None, element_degree=1)
    except WoundsweepError:  # cannot be built: it will fail fast as mesh-failed
        return 1.0
    return estimate_cells(spec)


def estimate_cells(manifest: pd.DataFrame) -> np.ndarray:
    """Each job's mesh size law cell count (one per geometry): the law integrated over the
    patch cross-section on a coarse grid, times the patch length. Rounded to 3 significant
    digits, so that nodes whose libm differs in the last bit still compute the same
    partition."""
    cols = [c for c in manifest.columns if c in GEOMETRY_KEYS or c in _SPEC_COLUMNS]
    geo = manifest.drop_duplicates("geometry_id").set_index("geometry_id")[cols]
    est = {
        gid: float(f"{_cells_estimate(r):.3g}") for gid, r in zip(geo.index, geo.to_dict("records"))
    }
    return manifest["geometry_id"].map(est).to_numpy(dtype=float)


def estimate_cost(manifest: pd.DataFrame) -> np.ndarray:
    """Relative CPU cost of each job: ``estimate_cells ** COST_EXPONENT`` times its shape's
    ``SHAPE_COST`` and, for a Langer line off the x and y axes, ``OFF_AXIS_COST`` (3
    significant digits)."""
    weight = manifest["wound_shape"].map(SHAPE_COST).fillna(1.0).to_numpy(dtype=float)
    off_axis = np.mod(manifest["orientation_deg"].to_numpy(dtype=float), 90.0) != 0.0
    weight = weight * np.where(off_axis, OFF_AXIS_COST, 1.0)
    cost = estimate_cells(manifest) ** COST_EXPONENT * weight
    return np.array([float(f"{c:.3g}") for c in cost])


def partition(manifest: pd.DataFrame, count: int) -> list[np.ndarray]:
    """Split the manifest's ``job_index`` values into ``count`` disjoint shards covering all.

    Each shard's indices are returned sorted (manifest order, geometry-major).
    """
    if count < 1:
        raise ValueError("shard count must be >= 1")
    jobs = manifest["job_index"].to_numpy(np.int64)
    cost = estimate_cost(manifest)
    order = sorted(range(len(jobs)), key=lambda i: (-cost[i], jobs[i]))
    heap = [(0.0, s) for s in range(count)]  # (assigned cost, shard): lightest, then lowest index
    members: list[list[int]] = [[] for _ in range(count)]
    for i in order:
        load, s = heapq.heappop(heap)
        members[s].append(int(jobs[i]))
        heapq.heappush(heap, (load + float(cost[i]), s))
    return [np.array(sorted(m), dtype=np.int64) for m in members]


def shard_jobs(manifest: pd.DataFrame, shard: Shard) -> pd.DataFrame:
    """The manifest rows of one shard, in manifest order."""
    idx = partition(manifest, shard.count)[shard.index]
    return manifest[manifest["job_index"].isin(idx)].sort_values("job_index")

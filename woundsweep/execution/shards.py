"""Deterministic partition of a manifest into N shards, balanced by an estimated cost.

Jobs that share a geometry stay in one shard (they reuse its cached mesh) whenever there are
at least as many geometries as shards; otherwise jobs are spread one by one. Groups are
assigned longest-first to the currently lightest shard (LPT), ties broken by shard number and
by ``geometry_id``/``job_index``, so the result depends only on the manifest and N: every
node of a cluster computes the same partition without talking to the others.
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
# CPU per job ~ (size-law cells)^COST_EXPONENT x SHAPE_COST[shape]: least squares on the log
# of the mean CPU of each geometry's nine jobs (28 P2 geometries of the paper grid, 252 jobs of
# eleven random shards of 486): residual sd 0.31 in log CPU, against 0.47 for the cell
# estimate alone. A wedge's stage 2 and contact stages take more Newton steps than a
# cylinder's of as many cells. Shapes not in the table (the fusiform excision) are not
# fitted: weight 1.
COST_EXPONENT = 0.65
SHAPE_COST = {"cylindrical": 1.0, "wedge": 1.5}

__all__ = [
    "COST_EXPONENT",
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

    index: int
    count: int

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
    """The mesh size law's cell count of the row's geometry (`mesh.sizing.estimate_cells`)."""
    from ..config.geometry import GeometrySpec
    from ..mesh.sizing import estimate_cells

    try:
        spec = GeometrySpec.from_row(row)
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
    ``SHAPE_COST`` (3 significant digits)."""
    weight = manifest["wound_shape"].map(SHAPE_COST).fillna(1.0).to_numpy(dtype=float)
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
    if manifest["geometry_id"].nunique() >= count:
        keys = manifest["geometry_id"].to_numpy(str)
    else:
        keys = np.array([f"{j:012d}" for j in jobs])
    groups: dict[str, list[int]] = {}
    gcost: dict[str, float] = {}
    for key, j, c in zip(keys, jobs, cost):
        groups.setdefault(key, []).append(int(j))
        gcost[key] = gcost.get(key, 0.0) + float(c)
    order = sorted(groups, key=lambda k: (-gcost[k], k))
    heap = [(0.0, s) for s in range(count)]  # (assigned cost, shard): lightest, then lowest index
    members: list[list[int]] = [[] for _ in range(count)]
    for key in order:
        load, s = heapq.heappop(heap)
        members[s].extend(groups[key])
        heapq.heappush(heap, (load + gcost[key], s))
    return [np.array(sorted(m), dtype=np.int64) for m in members]


def shard_jobs(manifest: pd.DataFrame, shard: Shard) -> pd.DataFrame:
    """The manifest rows of one shard, in manifest order."""
    idx = partition(manifest, shard.count)[shard.index]
    return manifest[manifest["job_index"].isin(idx)].sort_values("job_index")

"""Shards: an exact, deterministic, balanced partition of the manifest."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from woundsweep.config.geometry import GeometrySpec
from woundsweep.execution.shards import (
    COST_EXPONENT,
    OFF_AXIS_COST,
    SHAPE_COST,
    Shard,
    estimate_cells,
    estimate_cost,
    parse_shard,
    partition,
    shard_jobs,
)
from woundsweep.mesh.build import build_mesh


def test_cost_estimate_ranks_real_meshes(paper: pd.DataFrame) -> None:
    """The estimate orders geometries as their real gmsh cell counts do."""
    geo = paper.drop_duplicates("geometry_id")
    sample = pd.concat(
        [
            geo[geo["mesh_size_factor"] == 0.3].sample(10, random_state=1),
            geo.sample(4, random_state=2),
        ]
    )
    # P1 meshes: the estimate counts their cells, whatever the sweep's element.
    cells = [
        build_mesh(GeometrySpec.from_row(r, None, 1)).info["cells"] for _, r in sample.iterrows()
    ]
    est = estimate_cells(sample)
    rho = pd.Series(est).corr(pd.Series(cells, dtype=float), method="spearman")
    assert rho > 0.8, (rho, list(zip(est, cells)))
    # Every job of a geometry gets its geometry's cell estimate.
    one = paper[paper["geometry_id"] == sample["geometry_id"].iloc[0]]
    assert len(one) == 9 and len(set(estimate_cells(one))) == 1


def test_cost_is_the_fitted_power_of_cells_times_the_weights(paper: pd.DataFrame) -> None:
    jobs = paper.sample(60, random_state=4)
    cells, cost = estimate_cells(jobs), estimate_cost(jobs)
    weight = jobs["wound_shape"].map(SHAPE_COST).to_numpy()
    weight = weight * np.where(jobs["orientation_deg"].to_numpy() == 45.0, OFF_AXIS_COST, 1.0)
    assert set(jobs["orientation_deg"]) == {0.0, 45.0, 90.0}
    np.testing.assert_allclose(cost, cells**COST_EXPONENT * weight, rtol=5e-3)
    # A wedge costs SHAPE_COST["wedge"] times a cylinder of as many estimated cells, a Langer
    # line off the axes OFF_AXIS_COST times one along them.
    assert SHAPE_COST["wedge"] > SHAPE_COST["cylindrical"] == 1.0
    assert OFF_AXIS_COST > 1.0


def test_finer_mesh_factor_costs_more(paper: pd.DataFrame) -> None:
    key = ["geometry_id", "skin_type", "orientation_deg"]
    df = paper.assign(cost=estimate_cost(paper)).drop(columns=key + ["job_id", "job_index"])
    others = [c for c in df.columns if c not in ("mesh_size_factor", "cost")]
    for _, g in df.groupby(others, dropna=False):
        g = g.drop_duplicates("mesh_size_factor").sort_values("mesh_size_factor")
        assert len(g) == 3
        assert np.all(np.diff(g["cost"].to_numpy()) > 0)


@pytest.mark.parametrize("n", [1, 2, 3, 7, 64, 1296, 1297, 11_664])
def test_partition_is_exact(paper: pd.DataFrame, n: int) -> None:
    shards = partition(paper, n)
    assert len(shards) == n
    allj = np.concatenate(shards)
    assert len(allj) == len(paper) == 11_664  # no job twice ...
    assert np.array_equal(np.sort(allj), np.arange(11_664))  # ... and none missing
    for s in shards:
        assert np.all(np.diff(s) > 0)  # each shard in manifest order
    if n == 11_664:
        assert all(len(s) == 1 for s in shards)


def test_paper_shards_mix_geometries(paper: pd.DataFrame) -> None:
    """At N = 486 a shard holds about 24 jobs of many geometries (so one geometry's error of
    the estimate does not decide a shard's time), and its estimated cost is the mean's within
    one job's cost."""
    shards = partition(paper, 486)
    geos = [paper["geometry_id"].to_numpy()[s] for s in shards]
    assert min(len(set(g)) for g in geos) >= 10
    cost = estimate_cost(paper)
    loads = np.array([cost[s].sum() for s in shards])
    assert loads.max() - loads.min() <= cost.max()


def test_more_shards_than_geometries_splits_jobs(demo_manifest: pd.DataFrame) -> None:
    shards = partition(demo_manifest, 20)  # 16 geometries, 32 jobs
    assert all(len(s) > 0 for s in shards)
    assert sorted(np.concatenate(shards).tolist()) == list(range(32))


@pytest.mark.parametrize("n", [2, 3, 8, 50])
def test_balanced_within_list_scheduling_bound(paper: pd.DataFrame, n: int) -> None:
    cost = estimate_cost(paper)
    loads = np.array([cost[s].sum() for s in partition(paper, n)])
    assert loads.sum() == pytest.approx(cost.sum())
    # Greedy lightest-shard assignment: no shard exceeds the mean by more than one job.
    assert loads.max() <= cost.sum() / n + cost.max() + 1e-9
    if n <= 8:  # with many jobs per shard, the spread is far below one job's cost
        assert loads.max() - loads.min() <= 0.1 * cost.max()


def test_partition_independent_of_row_order(paper: pd.DataFrame) -> None:
    shuffled = paper.sample(frac=1.0, random_state=3)
    for a, b in zip(partition(paper, 7), partition(shuffled, 7)):
        assert np.array_equal(a, b)


def test_shard_jobs_rows(demo_manifest: pd.DataFrame) -> None:
    parts = [shard_jobs(demo_manifest, Shard(i, 3)) for i in range(3)]
    assert sum(len(p) for p in parts) == 32
    assert set().union(*(set(p["job_id"]) for p in parts)) == set(demo_manifest["job_id"])
    assert all(p["job_index"].is_monotonic_increasing for p in parts)


@pytest.mark.parametrize(
    "text,expected", [("0/1", Shard(0, 1)), ("3/4", Shard(3, 4)), (" 2 / 10 ", Shard(2, 10))]
)
def test_parse_shard(text: str, expected: Shard) -> None:
    assert parse_shard(text) == expected
    assert str(expected) == text.replace(" ", "")


@pytest.mark.parametrize("text", ["4/4", "1/0", "-1/2", "a/b", "3", "1/2/3"])
def test_parse_shard_rejects(text: str) -> None:
    with pytest.raises(ValueError, match="shard"):
        parse_shard(text)

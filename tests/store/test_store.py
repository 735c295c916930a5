"""The result store: rows, fields, atomic replacement, solver-output validation, status counts.

Solver outputs here are HDF5 files written by the test in the format docs/design.md fixes for
`woundsweep solve --out` (tests/support/store_files.py; the runner tests use the real
solver). Damaged, stale and stray files are the subject of test_store_damage.py.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from cli_run import WS
from store_files import manifest, outcome, solver_file, store_converged

from woundsweep.config.manifest import load_run
from woundsweep.core.diagnostics import StageDiagnostics, StageReport
from woundsweep.core.errors import StoreError
from woundsweep.core.schema import FailureClass, StageResult
from woundsweep.execution.shards import estimate_cost
from woundsweep.execution.summary import busy_seconds, summarize
from woundsweep.store.reader import DIAGNOSTIC_FIELDS, STAGE_FIELDS, read_results, result_schema
from woundsweep.store.solverfile import SolverOutput, read_solver_file
from woundsweep.store.writer import Store


def test_converged_job_rows_and_fields(empty_run: Path) -> None:
    path = store_converged(empty_run, 0, fields="all")
    job = manifest(empty_run).iloc[0]
    df = pd.read_parquet(empty_run / "results")
    assert path.name == f"job-{job['job_id']}.parquet"
    assert df["stage"].tolist() == [1, 2, 3, 4, 5, 6]
    assert (df["status"] == "converged").all() and (df["failure_class"] == "converged").all()
    assert df["p99_von_mises_kPa"].tolist() == [10.0 * k for k in range(1, 7)]
    assert df["newton_iterations"].tolist() == [3 + k for k in range(1, 7)]
    assert df["wound_width_mm"].iloc[0] == job["wound_width_mm"]
    # Each diagnostic is a typed column, null where a stage has none.
    assert df["load_increments"].tolist() == list(range(1, 7))
    assert df["pin_reaction_max_mN"].isna().tolist() == [True] + [False] * 5
    assert df["pin_reaction_max_mN"].iloc[2] == 0.75 and df["contact_searches"].isna().all()
    # The solver file gave no element: the row carries the job's, from its solver settings.
    assert (df["element_degree"] == load_run(empty_run).sweep.solver.element_degree).all()
    assert df["dolfinx_version"].iloc[0] == "0.5.2"
    with h5py.File(empty_run / "fields" / df["fields_file"].iloc[0]) as f:
        assert sorted(f) == [f"stage_{k}" for k in range(1, 7)]
        d = f["stage_4/displacement_mm"]
        assert d.dtype == np.float32 and d.compression == "gzip" and d.fletcher32
        mesh_id = load_run(empty_run).geometry(job).mesh_id
        assert f.attrs["mesh_file"] == f"mesh-{mesh_id}.h5"
    with h5py.File(empty_run / "fields" / f"mesh-{mesh_id}.h5") as f:
        assert f.attrs["mesh_id"] == mesh_id and f.attrs["element_degree"] == 2
        assert f["mesh/points"].dtype == np.float64  # coordinates keep full precision
        assert f["mesh/cells"].shape == (90, 4)


def test_fields_final_and_none(empty_run: Path) -> None:
    store_converged(empty_run, 1, fields="final")
    store_converged(empty_run, 2, fields="none")
    df = pd.read_parquet(empty_run / "results").drop_duplicates("job_index").set_index("job_index")
    with h5py.File(empty_run / "fields" / df.loc[1, "fields_file"]) as f:
        assert list(f) == ["stage_6"]
    assert df.loc[2, "fields_file"] == ""
    assert not (empty_run / "fields" / f"{df.loc[2, 'job_id']}.h5").exists()


def test_mesh_stored_once_per_geometry(empty_run: Path) -> None:
    m = manifest(empty_run)
    same_geo = m.index[m["geometry_id"] == m["geometry_id"].iloc[0]].tolist()
    assert len(same_geo) >= 2
    for i in same_geo[:-1]:
        store_converged(empty_run, i)
    # A job whose mesh differs from the stored one keeps its own copy.
    store_converged(empty_run, same_geo[-1], mesh_seed=1)
    meshes = sorted(p.name for p in (empty_run / "fields").glob("mesh-*.h5"))
    assert meshes == [f"mesh-{load_run(empty_run).geometry(m.iloc[0]).mesh_id}.h5"]
    with h5py.File(empty_run / "fields" / f"{m['job_id'].iloc[same_geo[-1]]}.h5") as f:
        assert "mesh" in f and f.attrs["mesh_file"] == ""


def test_not_converged_job(empty_run: Path) -> None:
    job = manifest(empty_run).iloc[3]
    src = empty_run / "s.h5"
    solver_file(src, job, range(1, 7), fail_at=3)
    out = read_solver_file(src, job["job_id"], (1, 6))
    Store(empty_run).write_job(job.to_dict(), outcome("not-converged", out), (1, 6), "final", "0/1")
    df = pd.read_parquet(empty_run / "results")
    assert df["status"].tolist() == ["converged"] * 2 + ["diverged"] + ["not-run"] * 3
    assert (df["failed_stage"] == 3).all()
    assert df["p99_von_mises_kPa"].isna().tolist() == [False] * 3 + [True] * 3
    with h5py.File(empty_run / "fields" / df["fields_file"].iloc[0]) as f:
        assert list(f) == ["stage_3"]  # "final": the last stage that has fields


@pytest.mark.parametrize("cls", ["timeout", "out-of-memory", "crashed", "invalid", "mesh-failed"])
def test_failed_job_gets_not_run_rows(empty_run: Path, cls: str) -> None:
    job = manifest(empty_run).iloc[5]
    Store(empty_run).write_job(job.to_dict(), outcome(cls, attempts=3), (2, 4), "final", "1/2")
    df = pd.read_parquet(empty_run / "results")
    assert df["stage"].tolist() == [2, 3, 4]
    assert (df["status"] == "not-run").all() and (df["failure_class"] == cls).all()
    assert (df["attempts"] == 3).all() and (df["shard"] == "1/2").all()
    assert df["fields_file"].tolist() == [""] * 3
    assert df["failed_stage"].isna().all()


def test_rewrite_replaces_never_duplicates(empty_run: Path) -> None:
    job = manifest(empty_run).iloc[7]
    store = Store(empty_run)
    store.write_job(job.to_dict(), outcome("crashed"), (1, 6), "final", "0/1")
    store_converged(empty_run, 7)
    df = pd.read_parquet(empty_run / "results")
    assert len(df) == 6 and (df["failure_class"] == "converged").all()


def test_solver_output_validation(empty_run: Path) -> None:
    m = manifest(empty_run)
    src = empty_run / "s.h5"
    solver_file(src, m.iloc[0], range(1, 4))
    with pytest.raises(StoreError, match="is not"):
        read_solver_file(src, m["job_id"].iloc[1], (1, 3))
    with h5py.File(src, "a") as f:
        f.attrs["stage_results"] = "not json"
    with pytest.raises(StoreError, match="stage_results"):
        read_solver_file(src, m["job_id"].iloc[0], (1, 3))
    src.write_bytes(b"\x89HDF junk")
    with pytest.raises(StoreError, match="unreadable"):
        read_solver_file(src, m["job_id"].iloc[0], (1, 3))


def _writer(rd: str, i: int, n: int) -> None:
    for k in range(n):
        store_converged(Path(rd), i, fields="final" if k % 2 else "all", tag=f"-{os.getpid()}")


def test_concurrent_rewrites_never_expose_partial_files(empty_run: Path) -> None:
    store_converged(empty_run, 0)
    path = Store(empty_run).result_path(manifest(empty_run)["job_id"].iloc[0])
    ctx = mp.get_context("fork")
    writers = [ctx.Process(target=_writer, args=(str(empty_run), 0, 25)) for _ in range(2)]
    for w in writers:
        w.start()
    reads = 0
    while any(w.is_alive() for w in writers):
        t = pq.read_table(path)  # raises if a reader ever sees a partial file
        assert t.num_rows == 6
        reads += 1
    for w in writers:
        w.join()
        assert w.exitcode == 0
    assert reads > 5
    assert len(list((empty_run / "results").iterdir())) == 1  # one file, no leftovers
    assert sorted(p.name for p in (empty_run / "fields").iterdir() if p.name.startswith(".")) == []


def test_summarize_counts_and_estimates(empty_run: Path) -> None:
    m = manifest(empty_run)
    store = Store(empty_run)
    want = {
        0: "converged",
        1: "converged",
        2: "timeout",
        3: "not-converged",
        8: "crashed",
        9: "invalid",
    }
    for i, cls in want.items():
        job = m.iloc[i]
        if cls == "converged":
            store_converged(empty_run, i)
        elif cls == "not-converged":
            src = empty_run / "s.h5"
            solver_file(src, job, range(1, 7), fail_at=2)
            out = read_solver_file(src, job["job_id"], (1, 6))
            store.write_job(job.to_dict(), outcome(cls, out), (1, 6), "final", "0/1")
        else:
            store.write_job(job.to_dict(), outcome(cls, attempts=2), (1, 6), "final", "0/1")
    s = summarize(m, read_results(empty_run))
    assert s["jobs_total"] == 32 and s["jobs_done"] == 6 and s["jobs_pending"] == 26
    assert s["rows"] == 36
    expected = {c: sum(v == c for v in want.values()) for c in FailureClass}
    assert s["by_failure_class"] == expected
    assert s["not_converged_at_stage"] == {"2": 1}
    # Stage 1: jobs 0, 1, 3 converged; stage 2: job 3 diverged; failed jobs are all not-run.
    assert s["by_stage"]["1"]["converged"] == 3 and s["by_stage"]["1"]["not-run"] == 3
    assert s["by_stage"]["2"]["converged"] == 2 and s["by_stage"]["2"]["diverged"] == 1
    assert s["by_stage"]["6"]["not-run"] == 4
    assert s["attempts"] == 1 + 1 + 2 + 1 + 2 + 2
    assert s["cpu_time_used_s"] == pytest.approx(10.0 * s["attempts"])
    # CPU left: CPU used per unit of estimated cost, times the cost of the pending jobs.
    cost = pd.Series(estimate_cost(m))
    done = m.index.isin(list(want))
    expect_left = 10.0 * s["attempts"] / cost[done].sum() * cost[~done].sum()
    assert s["cpu_time_left_estimate_s"] == pytest.approx(expect_left)


def test_status_cli_json_matches_store(empty_run: Path) -> None:
    for i in range(3):
        store_converged(empty_run, i)
    job = manifest(empty_run).iloc[4]
    Store(empty_run).write_job(job.to_dict(), outcome("out-of-memory"), (1, 6), "final", "0/1")
    res = subprocess.run([*WS, "status", str(empty_run), "--json"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    s = json.loads(res.stdout)
    df = pd.read_parquet(empty_run / "results")
    jobs = df.drop_duplicates("job_id")
    assert s["jobs_done"] == len(jobs) == 4
    assert s["by_failure_class"]["converged"] == 3 and s["by_failure_class"]["out-of-memory"] == 1
    assert sum(sum(v.values()) for v in s["by_stage"].values()) == len(df) == 24
    text = subprocess.run([*WS, "status", str(empty_run)], capture_output=True, text=True).stdout
    assert "4 of 32 stored" in text


def test_results_readable_while_empty(empty_run: Path) -> None:
    df = read_results(empty_run)
    assert len(df) == 0 and "failure_class" in df.columns
    s = summarize(manifest(empty_run), df)
    assert s["jobs_done"] == 0 and s["cpu_time_left_estimate_s"] is None


def test_stage_field_types_pinned() -> None:
    """The StageResult columns: in its field order, counts as int64, the rest float64."""
    assert list(STAGE_FIELDS) == list(StageResult._fields[2:])
    ints = {k for k, t in STAGE_FIELDS.items() if t == pa.int64()}
    assert ints == {
        "newton_iterations",
        "n_penetrating",
        "closed",
        "interpenetrating",
        "dofs",
        "cells",
        "element_degree",
    }
    assert all(t == pa.float64() for k, t in STAGE_FIELDS.items() if k not in ints)


def test_diagnostic_columns_pinned() -> None:
    """One column per known diagnostic, in `StageDiagnostics` order: counts int64, the rest
    float64; no JSON column."""
    assert list(DIAGNOSTIC_FIELDS) == list(StageDiagnostics.__annotations__)
    ints = {k for k, t in DIAGNOSTIC_FIELDS.items() if t == pa.int64()}
    assert ints == {
        "load_increments",
        "load_cuts",
        "contact_searches",
        "closing_amplitude_solves",
        "contact_fade_points",
        "audit_inside_nodes",
    }
    assert all(t == pa.float64() for k, t in DIAGNOSTIC_FIELDS.items() if k not in ints)
    names = result_schema().names
    assert set(DIAGNOSTIC_FIELDS) <= set(names) and "stage_extra_json" not in names


def test_diagnostic_columns_round_trip_typed(empty_run: Path) -> None:
    """A stage's diagnostics come back from the store as their columns, with their kind;
    a diagnostic the store has no column for is refused, not dropped."""
    job = manifest(empty_run).iloc[4]
    diag = {"load_increments": 7, "load_reached": 1, "tie_force_mN": float("nan")}
    result = StageResult(1, "converged", newton_iterations=3, element_degree=2)
    out = SolverOutput(empty_run, {}, {1: StageReport(result, diag)})
    Store(empty_run).write_job(job.to_dict(), outcome("converged", out), (1, 1), "none", "0/1")
    table = pq.read_table(empty_run / "results" / f"job-{job['job_id']}.parquet")
    row = table.to_pylist()[0]
    assert row["load_increments"] == 7 and isinstance(row["load_increments"], int)
    assert row["load_reached"] == 1.0 and isinstance(row["load_reached"], float)
    assert row["tie_force_mN"] is None and row["load_cuts"] is None  # NaN and absent: null
    assert row["element_degree"] == 2
    bad = SolverOutput(empty_run, {}, {1: StageReport(result, {"future_mN": 1.0})})
    with pytest.raises(ValueError, match="future_mN"):
        Store(empty_run).write_job(job.to_dict(), outcome("converged", bad), (1, 1), "none", "0/1")


def test_busy_time_is_the_union_of_the_jobs_intervals() -> None:
    t = pd.Timestamp("2026-12-06T09:00:00", tz="UTC")
    s = pd.Timedelta(seconds=1)
    # Two overlapping jobs (0-10 s, 5-20 s), one inside them (6-8 s), a pause, then one more
    # (100-130 s) and one without a finish time: 20 + 30 s of running over a 130 s span.
    started = pd.Series([t, t + 5 * s, t + 6 * s, t + 100 * s, t + 40 * s])
    finished = pd.Series([t + 10 * s, t + 20 * s, t + 8 * s, t + 130 * s, pd.NaT])
    assert busy_seconds(started, finished) == 50.0
    assert busy_seconds(started[:0], finished[:0]) == 0.0

"""The result store: rows, fields, atomic replacement, validation, resume state, status counts.

Solver outputs here are HDF5 files written by the test in the format docs/design.md fixes for
`woundsweep solve --out` (the runner tests use the real solver).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from woundsweep.config.manifest import load_run
from woundsweep.core.errors import StoreError
from woundsweep.core.schema import FailureClass, StageResult
from woundsweep.execution.shards import estimate_cost
from woundsweep.execution.summary import summarize
from woundsweep.store.reader import STAGE_FIELDS, read_results
from woundsweep.store.solverfile import read_solver_file
from woundsweep.store.writer import AttemptOutcome, Store

ROOT = Path(__file__).resolve().parent.parent
WS = [sys.executable, "-m", "woundsweep"]


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("store") / "run"
    subprocess.run(
        [*WS, "generate", str(ROOT / "sweeps" / "demo.yaml"), "--out", str(rd)], check=True
    )
    return rd


@pytest.fixture
def run_dir(demo_run: Path, tmp_path: Path) -> Path:
    rd = tmp_path / "run"
    rd.mkdir()
    for name in ("manifest.parquet", "sweep.yaml"):
        (rd / name).write_bytes((demo_run / name).read_bytes())
    return rd


def _manifest(rd: Path) -> pd.DataFrame:
    return load_run(rd).manifest


def _solver_file(
    path: Path, job: pd.Series, stages: range, fail_at: int | None = None, mesh_seed: int = 0
) -> dict[int, dict[str, Any]]:
    """Write a solver output per docs/design.md; returns the stage results written."""
    rng = np.random.default_rng(int(job["job_index"]) + 100)
    mesh_rng = np.random.default_rng(mesh_seed)
    n, m = 40, 90
    results, ok = {}, True
    with h5py.File(path, "w") as f:
        for k, v in {
            "job_id": job["job_id"], "job_index": int(job["job_index"]),
            "geometry_id": job["geometry_id"], "woundsweep_version": "0.1.0",
            "dolfinx_version": "0.5.2", "units": "mm, kPa, mN, s",
        }.items():  # fmt: skip
            f.attrs[k] = v
        f["mesh/points"] = mesh_rng.random((n, 3))
        f["mesh/cells"] = mesh_rng.integers(0, n, (m, 4))
        f["mesh/cell_tags"] = np.where(np.arange(m) < 50, 1, 2).astype(np.int32)
        for k in stages:
            if not ok:
                results[k] = {"stage": k, "status": "not-run"}
                continue
            status = "diverged" if k == fail_at else "converged"
            ok = status == "converged"
            f[f"stage_{k}/displacement_mm"] = rng.random((n, 3))  # float64: store makes float32
            f[f"stage_{k}/von_mises_kPa"] = rng.random(m)
            results[k] = {
                "stage": k, "status": status, "newton_iterations": 3 + k, "time_s": 0.5 * k,
                "p99_von_mises_kPa": 10.0 * k, "p99_von_mises_nodal_kPa": 11.0 * k,
                "max_von_mises_kPa": 20.0 * k, "max_location_x_mm": 0.1, "max_location_y_mm": 0.2,
                "max_location_z_mm": -0.3, "closure_gap_mm": 0.01 * k, "min_J": 0.8,
                "n_penetrating": 0, "max_penetration_mm": 0.0, "contact_force_mN": 0.0,
                "residual_norm": 1e-9, "dofs": 3 * n, "cells": m, "future_field": k,
            }  # fmt: skip
        f.attrs["stage_results"] = json.dumps(list(results.values()))
    return results


def _outcome(cls: str, output: Any = None, attempts: int = 1, cpu: float = 10.0) -> AttemptOutcome:
    now = time.time()
    return AttemptOutcome(
        failure_class=cls,
        failure_detail="" if cls == "converged" else f"{cls} for the test",
        exit_code={"converged": 0, "not-converged": 3, "invalid": 2}.get(cls),
        attempts=attempts,
        wall_time_s=cpu + 1,
        cpu_time_s=cpu,
        total_wall_time_s=attempts * (cpu + 1),
        total_cpu_time_s=attempts * cpu,
        max_rss_MiB=300.0,
        started_at=now - cpu - 1,
        finished_at=now,
        output=output,
    )


def _store_converged(
    rd: Path, i: int, fields: str = "final", stages=(1, 6), tag: str = "", **kw: Any
) -> Path:
    job = _manifest(rd).iloc[i]
    src = rd / f"solver-{i}{tag}.h5"
    _solver_file(src, job, range(stages[0], stages[1] + 1), **kw)
    out = read_solver_file(src, job["job_id"], stages)
    return Store(rd).write_job(job.to_dict(), _outcome("converged", out), stages, fields, "0/1")


def test_converged_job_rows_and_fields(run_dir: Path) -> None:
    path = _store_converged(run_dir, 0, fields="all")
    job = _manifest(run_dir).iloc[0]
    df = pd.read_parquet(run_dir / "results")
    assert path.name == f"job-{job['job_id']}.parquet"
    assert df["stage"].tolist() == [1, 2, 3, 4, 5, 6]
    assert (df["status"] == "converged").all() and (df["failure_class"] == "converged").all()
    assert df["p99_von_mises_kPa"].tolist() == [10.0 * k for k in range(1, 7)]
    assert df["newton_iterations"].tolist() == [3 + k for k in range(1, 7)]
    assert df["wound_width_mm"].iloc[0] == job["wound_width_mm"]
    assert json.loads(df["stage_extra_json"].iloc[2]) == {"future_field": 3}
    assert df["dolfinx_version"].iloc[0] == "0.5.2"
    with h5py.File(run_dir / "fields" / df["fields_file"].iloc[0]) as f:
        assert sorted(f) == [f"stage_{k}" for k in range(1, 7)]
        d = f["stage_4/displacement_mm"]
        assert d.dtype == np.float32 and d.compression == "gzip" and d.fletcher32
        assert f.attrs["mesh_file"] == f"mesh-{job['geometry_id']}.h5"
    with h5py.File(run_dir / "fields" / f"mesh-{job['geometry_id']}.h5") as f:
        assert f["mesh/points"].dtype == np.float64  # coordinates keep full precision
        assert f["mesh/cells"].shape == (90, 4)


def test_fields_final_and_none(run_dir: Path) -> None:
    _store_converged(run_dir, 1, fields="final")
    _store_converged(run_dir, 2, fields="none")
    df = pd.read_parquet(run_dir / "results").drop_duplicates("job_index").set_index("job_index")
    with h5py.File(run_dir / "fields" / df.loc[1, "fields_file"]) as f:
        assert list(f) == ["stage_6"]
    assert df.loc[2, "fields_file"] == ""
    assert not (run_dir / "fields" / f"{df.loc[2, 'job_id']}.h5").exists()


def test_mesh_stored_once_per_geometry(run_dir: Path) -> None:
    m = _manifest(run_dir)
    same_geo = m.index[m["geometry_id"] == m["geometry_id"].iloc[0]].tolist()
    assert len(same_geo) >= 2
    for i in same_geo[:-1]:
        _store_converged(run_dir, i)
    # A job whose mesh differs from the stored one keeps its own copy.
    _store_converged(run_dir, same_geo[-1], mesh_seed=1)
    meshes = sorted(p.name for p in (run_dir / "fields").glob("mesh-*.h5"))
    assert meshes == [f"mesh-{m['geometry_id'].iloc[0]}.h5"]
    with h5py.File(run_dir / "fields" / f"{m['job_id'].iloc[same_geo[-1]]}.h5") as f:
        assert "mesh" in f and f.attrs["mesh_file"] == ""


def test_not_converged_job(run_dir: Path) -> None:
    job = _manifest(run_dir).iloc[3]
    src = run_dir / "s.h5"
    _solver_file(src, job, range(1, 7), fail_at=3)
    out = read_solver_file(src, job["job_id"], (1, 6))
    Store(run_dir).write_job(job.to_dict(), _outcome("not-converged", out), (1, 6), "final", "0/1")
    df = pd.read_parquet(run_dir / "results")
    assert df["status"].tolist() == ["converged"] * 2 + ["diverged"] + ["not-run"] * 3
    assert (df["failed_stage"] == 3).all()
    assert df["p99_von_mises_kPa"].isna().tolist() == [False] * 3 + [True] * 3
    with h5py.File(run_dir / "fields" / df["fields_file"].iloc[0]) as f:
        assert list(f) == ["stage_3"]  # "final": the last stage that has fields


@pytest.mark.parametrize("cls", ["timeout", "out-of-memory", "crashed", "invalid", "mesh-failed"])
def test_failed_job_gets_not_run_rows(run_dir: Path, cls: str) -> None:
    job = _manifest(run_dir).iloc[5]
    Store(run_dir).write_job(job.to_dict(), _outcome(cls, attempts=3), (2, 4), "final", "1/2")
    df = pd.read_parquet(run_dir / "results")
    assert df["stage"].tolist() == [2, 3, 4]
    assert (df["status"] == "not-run").all() and (df["failure_class"] == cls).all()
    assert (df["attempts"] == 3).all() and (df["shard"] == "1/2").all()
    assert df["fields_file"].tolist() == [""] * 3
    assert df["failed_stage"].isna().all()


def test_rewrite_replaces_never_duplicates(run_dir: Path) -> None:
    job = _manifest(run_dir).iloc[7]
    store = Store(run_dir)
    store.write_job(job.to_dict(), _outcome("crashed"), (1, 6), "final", "0/1")
    _store_converged(run_dir, 7)
    df = pd.read_parquet(run_dir / "results")
    assert len(df) == 6 and (df["failure_class"] == "converged").all()


def test_solver_output_validation(run_dir: Path) -> None:
    m = _manifest(run_dir)
    src = run_dir / "s.h5"
    _solver_file(src, m.iloc[0], range(1, 4))
    with pytest.raises(StoreError, match="is not"):
        read_solver_file(src, m["job_id"].iloc[1], (1, 3))
    with h5py.File(src, "a") as f:
        f.attrs["stage_results"] = "not json"
    with pytest.raises(StoreError, match="stage_results"):
        read_solver_file(src, m["job_id"].iloc[0], (1, 3))
    src.write_bytes(b"\x89HDF junk")
    with pytest.raises(StoreError, match="unreadable"):
        read_solver_file(src, m["job_id"].iloc[0], (1, 3))


def test_job_state_and_quarantine(run_dir: Path) -> None:
    m = _manifest(run_dir)
    store = Store(run_dir)
    jid = m["job_id"].iloc[0]
    assert store.job_state(jid, (1, 6)).state == "missing"
    _store_converged(run_dir, 0, stages=(1, 3))
    assert store.job_state(jid, (1, 3)) == ("done", "converged", "")
    assert store.job_state(jid, (2, 3)).state == "done"
    assert store.job_state(jid, (1, 6)).state == "stale"  # stages 4-6 now asked for
    _store_converged(run_dir, 0)
    # A one-bit flip in a data page that a plain read does not notice: the page checksums do.
    path = store.result_path(jid)
    orig, table = path.read_bytes(), pq.read_table(path).to_pandas()
    for off in range(4, len(orig)):
        data = bytearray(orig)
        data[off] ^= 0x01
        path.write_bytes(bytes(data))
        try:
            plain = pq.read_table(path).to_pandas()
        except Exception:  # noqa: BLE001 - loud failures are not what this looks for
            continue
        if not plain.equals(table):  # read without error, wrong values
            break
    else:
        pytest.fail("no silent single-bit corruption found")
    st = store.job_state(jid, (1, 6))
    assert st.state == "corrupt" and str(path) in st.reason
    moved = store.quarantine(jid)
    assert moved is not None and moved.parent.name == "corrupt" and not path.exists()
    assert store.job_state(jid, (1, 6)).state == "missing"


def test_truncated_fields_file_is_detected(run_dir: Path) -> None:
    _store_converged(run_dir, 1)
    store = Store(run_dir)
    jid = _manifest(run_dir)["job_id"].iloc[1]
    fpath = run_dir / "fields" / f"{jid}.h5"
    fpath.write_bytes(fpath.read_bytes()[:1000])
    st = store.job_state(jid, (1, 6))
    assert st.state == "damaged" and "fields" in st.reason


def test_truncated_result_fails_analysis_reads_and_status_counts_it(run_dir: Path) -> None:
    _store_converged(run_dir, 0)
    _store_converged(run_dir, 1)
    path = Store(run_dir).result_path(_manifest(run_dir)["job_id"].iloc[1])
    path.write_bytes(path.read_bytes()[:-30])
    with pytest.raises(StoreError, match="corrupt result file") as err:
        read_results(run_dir)
    assert str(path) in str(err.value) and "woundsweep run" in str(err.value)
    res = subprocess.run([*WS, "status", str(run_dir), "--json"], capture_output=True, text=True)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    s = json.loads(res.stdout)
    assert (s["jobs_done"], s["jobs_damaged"], s["jobs_pending"]) == (1, 1, 31)
    assert str(path) in s["damaged_example"]


def test_dataset_reader_ignores_temporaries(run_dir: Path) -> None:
    _store_converged(run_dir, 0)
    # What a writer killed mid-write leaves: a dot-named partial file beside the results.
    (run_dir / "results" / ".job-deadbeef.parquet.x1.tmp").write_bytes(b"PAR1 partial")
    assert len(pd.read_parquet(run_dir / "results")) == 6
    assert len(read_results(run_dir)) == 6


def test_clean_tmp_removes_only_dead_runners_files(run_dir: Path) -> None:
    store = Store(run_dir)
    store.ensure_dirs()
    dead = subprocess.Popen(["true"])
    dead.wait()
    mine = store.tmp_path("aaaa", 1)
    theirs = store.tmp_dir / f"bbbb~{store.host}~{dead.pid}~1.h5"
    other_host = store.tmp_dir / f"cccc~elsewhere.example~{dead.pid}~1.h5"
    for p in (mine, theirs, other_host):
        p.write_bytes(b"x")
    assert store.clean_tmp() == 1
    assert mine.exists() and not theirs.exists() and other_host.exists()


def _writer(rd: str, i: int, n: int) -> None:
    for k in range(n):
        _store_converged(Path(rd), i, fields="final" if k % 2 else "all", tag=f"-{os.getpid()}")


def test_concurrent_rewrites_never_expose_partial_files(run_dir: Path) -> None:
    _store_converged(run_dir, 0)
    path = Store(run_dir).result_path(_manifest(run_dir)["job_id"].iloc[0])
    ctx = mp.get_context("fork")
    writers = [ctx.Process(target=_writer, args=(str(run_dir), 0, 25)) for _ in range(2)]
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
    assert len(list((run_dir / "results").iterdir())) == 1  # one file, no leftovers
    assert sorted(p.name for p in (run_dir / "fields").iterdir() if p.name.startswith(".")) == []


def test_summarize_counts_and_estimates(run_dir: Path) -> None:
    m = _manifest(run_dir)
    store = Store(run_dir)
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
            _store_converged(run_dir, i)
        elif cls == "not-converged":
            src = run_dir / "s.h5"
            _solver_file(src, job, range(1, 7), fail_at=2)
            out = read_solver_file(src, job["job_id"], (1, 6))
            store.write_job(job.to_dict(), _outcome(cls, out), (1, 6), "final", "0/1")
        else:
            store.write_job(job.to_dict(), _outcome(cls, attempts=2), (1, 6), "final", "0/1")
    s = summarize(m, read_results(run_dir))
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


def test_status_cli_json_matches_store(run_dir: Path) -> None:
    for i in range(3):
        _store_converged(run_dir, i)
    job = _manifest(run_dir).iloc[4]
    Store(run_dir).write_job(job.to_dict(), _outcome("out-of-memory"), (1, 6), "final", "0/1")
    res = subprocess.run([*WS, "status", str(run_dir), "--json"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    s = json.loads(res.stdout)
    df = pd.read_parquet(run_dir / "results")
    jobs = df.drop_duplicates("job_id")
    assert s["jobs_done"] == len(jobs) == 4
    assert s["by_failure_class"]["converged"] == 3 and s["by_failure_class"]["out-of-memory"] == 1
    assert sum(sum(v.values()) for v in s["by_stage"].values()) == len(df) == 24
    text = subprocess.run([*WS, "status", str(run_dir)], capture_output=True, text=True).stdout
    assert "4 of 32 stored" in text


def test_results_readable_while_empty(run_dir: Path) -> None:
    df = read_results(run_dir)
    assert len(df) == 0 and "failure_class" in df.columns
    s = summarize(_manifest(run_dir), df)
    assert s["jobs_done"] == 0 and s["cpu_time_left_estimate_s"] is None


def test_stage_field_types_pinned() -> None:
    """The StageResult columns: in its field order, counts as int64, the rest float64."""
    assert list(STAGE_FIELDS) == list(StageResult._fields[2:])
    ints = {k for k, t in STAGE_FIELDS.items() if t == pa.int64()}
    assert ints == {"newton_iterations", "n_penetrating", "interpenetrating", "dofs", "cells"}
    assert all(t == pa.float64() for k, t in STAGE_FIELDS.items() if k not in ints)


def test_fingerprint_covers_what_determines_a_result(run_dir: Path) -> None:
    """Each material value of the job's own skin type, the subcutis, every stage and solver
    setting change the fingerprint; another skin type's values, the analysis settings and the
    sweep's name do not; the job id never does."""
    from woundsweep.config.sweep import parse_sweep
    from woundsweep.store.identity import result_fingerprint

    run = load_run(run_dir)
    job = run.manifest[run.manifest["skin_type"] == "stiff"].iloc[0]
    doc = {"grid": dict(run.sweep.grid), "shapes": dict(run.sweep.shapes)}
    base = result_fingerprint(parse_sweep(doc), job)
    assert len(base) == 64 and base == result_fingerprint(run.sweep, job)

    def fp(section: str, value: dict) -> str:
        return result_fingerprint(parse_sweep({**doc, section: value}), job)

    changed = [
        fp("materials", {"skin_types": {"stiff": {"c_kPa": 42.7}, "soft": {}}}),
        fp("materials", {"skin_types": {"stiff": {"mu_kPa": [35.6, 11.8, 11.9]}, "soft": {}}}),
        fp("materials", {"skin_types": {"stiff": {"tsf": 1.06}, "soft": {}}}),
        fp("materials", {"subcutis": {"K_kPa": 51}}),
        fp("stages", {"closure_zone": {"depth_fraction": 0.4}}),
        fp("stages", {"contact_penalty_GPa": [1, 5, 50]}),
        fp("stages", {"closure_zone": {"y_fraction": 0.5}}),
        fp("solver", {"quadrature_degree": 2}),
        fp("solver", {"rtol": 1e-9}),
    ]
    assert base not in changed and len(set(changed)) == len(changed)
    assert fp("materials", {"skin_types": {"stiff": {}, "soft": {"c_kPa": 99.0}}}) == base
    assert fp("analysis", {"max_depth": 3}) == base
    assert result_fingerprint(parse_sweep({**doc, "name": "other"}), job) == base
    other = run.manifest[run.manifest["skin_type"] == "soft"].iloc[0]
    assert result_fingerprint(run.sweep, other) != base


def test_fingerprint_covers_the_statistics_version(run_dir: Path, monkeypatch) -> None:
    """Results whose stress statistics were computed another way are stale."""
    from woundsweep.store import identity

    run = load_run(run_dir)
    job = run.manifest.iloc[0]
    base = identity.result_fingerprint(run.sweep, job)
    monkeypatch.setattr(identity, "STATISTICS_VERSION", identity.STATISTICS_VERSION + 1)
    assert identity.result_fingerprint(run.sweep, job) != base

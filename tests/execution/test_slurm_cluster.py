"""`woundsweep slurm` on a real one-node SLURM: arrays, follow-ups, failing jobs, the demo sweep.

The tests start a private one-node SLURM (tests/support/slurm_cluster.py: munged, slurmctld,
slurmd from Debian's slurm-wlm and munge) and are marked `system`: `make test-deps`
(scripts/test-deps.sh, run by `make test`) installs the packages; without them, or without
root, the tests are skipped with the reason. The scripts themselves and the command's
validation are the subject of test_slurm.py.
"""

from __future__ import annotations

import datetime
import json
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from cli_run import DEMO, ws
from slurm_cluster import ClusterError, SlurmCluster, start_cluster, unavailable_reason

from woundsweep.execution.shards import partition
from woundsweep.execution.slurm import (
    SCRIPT_NAMES,
    warmup_shard,
)

pytestmark = pytest.mark.system  # slurm-wlm and munge: scripts/test-deps.sh


@pytest.fixture(scope="module")
def cluster() -> Iterator[SlurmCluster]:
    reason = unavailable_reason()
    if reason:
        pytest.skip(f"no SLURM cluster: {reason}")
    # Not under pytest's tmp dir: munged wants every directory above its socket searchable
    # by all, and /tmp/pytest-of-<user> is private.
    root = Path(tempfile.mkdtemp(prefix="woundsweep-slurm-"))
    try:
        with start_cluster(root) as c:
            yield c
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _times(rec: dict[str, str]) -> tuple[str, str]:
    return rec["StartTime"], rec["EndTime"]  # ISO strings: compare as text


def test_cluster_runs_an_array_then_its_follow_up(cluster: SlurmCluster, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    tasks = cluster.run(
        "sbatch", "--parsable", "--array=0-2", f"--output={out}/t_%a.txt",
        "--wrap", "echo task=$SLURM_ARRAY_TASK_ID; sleep 1",
    ).split(";")[0].strip()  # fmt: skip
    follow = cluster.run(
        "sbatch", "--parsable", f"--dependency=afterany:{tasks}", f"--output={out}/f.txt",
        "--wrap", "echo follow",
    ).split(";")[0].strip()  # fmt: skip
    cluster.wait_until_empty(timeout=120, poll=0.5)
    for i in range(3):
        assert (out / f"t_{i}.txt").read_text().strip() == f"task={i}"
    recs = cluster.array_tasks(tasks)
    assert sorted(r["ArrayTaskId"] for r in recs) == ["0", "1", "2"]
    assert all(r["JobState"] == "COMPLETED" for r in recs)
    f = cluster.job(follow)
    assert f["JobState"] == "COMPLETED" and (out / "f.txt").read_text().strip() == "follow"
    assert f["StartTime"] >= max(r["EndTime"] for r in recs)


def test_generated_scripts_pass_sbatch_test_only(
    cluster: SlurmCluster, demo_run: Path, tmp_path: Path
) -> None:
    rd = tmp_path / "run"
    shutil.copytree(demo_run, rd)
    res = ws(
        "slurm", str(rd), "--shards", "3", "--time", "00:10:00", "--mem", "100M",
        "--partition", "debug", "--extra", "#SBATCH --comment=woundsweep-test",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    for name in SCRIPT_NAMES:
        # --test-only: slurmctld parses and schedules the script without running it.
        r = subprocess.run(
            ["sbatch", "--test-only", str(rd / "slurm" / name)],
            env=cluster.env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert r.returncode == 0 and "to start at" in r.stderr, (name, r.stderr)


def _submit(rd: Path, cluster: SlurmCluster, *extra: str, env: dict[str, str] | None = None):
    res = ws("slurm", str(rd), *extra, "--submit", env={**cluster.env, **(env or {})})
    assert res.returncode == 0, res.stderr + res.stdout
    rec = json.loads((rd / "slurm" / "jobs.json").read_text())["submissions"][-1]
    return rec["warmup_job_id"], rec["array_job_id"], rec["followup_job_id"]


def _wait(cluster: SlurmCluster, rd: Path, timeout: float) -> None:
    try:
        cluster.wait_until_empty(timeout=timeout)
    except ClusterError as err:
        logs = "\n".join(
            f"--- {p.name}\n{p.read_text()[-2000:]}"
            for p in sorted((rd / "slurm" / "logs").glob("*.log"))
        )
        raise AssertionError(f"{err}\n{logs}\n{cluster.logs()}") from None


def _check_chain(cluster: SlurmCluster, rd: Path, ids: tuple[str, str, str], shards: int) -> None:
    """Warm-up, then every array task, then the follow-up: all completed, all logged."""
    warm, array, follow = ids
    w = cluster.job(warm)
    tasks = cluster.array_tasks(array)
    f = cluster.job(follow)
    logs = rd / "slurm" / "logs"
    detail = f"{w}\n{tasks}\n{f}"
    assert w["JobState"] == "COMPLETED" and w["ExitCode"] == "0:0", detail
    assert sorted(int(t["ArrayTaskId"]) for t in tasks) == list(range(shards)), detail
    for t in tasks:
        assert t["JobState"] == "COMPLETED" and t["ExitCode"] == "0:0", detail
        assert t["StartTime"] >= w["EndTime"], detail  # afterok on the warm-up
        assert (logs / f"sweep-{array}_{t['ArrayTaskId']}.log").is_file()
    assert f["JobState"] == "COMPLETED" and f["ExitCode"] == "0:0", detail
    assert f["StartTime"] >= max(t["EndTime"] for t in tasks), detail
    assert (logs / f"warmup-{warm}.log").is_file()


def _store(rd: Path) -> pd.DataFrame:
    return pd.read_parquet(rd / "results")


def _runner_default_stages() -> range:
    """The stages `woundsweep run` runs when the scripts pass no --stages."""
    from woundsweep.commands.run import cmd as run_cmd
    from woundsweep.core.schema import parse_stage_range

    (text,) = [p.default for p in run_cmd.params if p.name == "stages_text"]
    a, b = parse_stage_range(text)
    return range(a, b + 1)


def _assert_every_job_once(rd: Path, stages: range | None = None) -> pd.DataFrame:
    stages = _runner_default_stages() if stages is None else stages
    man = pd.read_parquet(rd / "manifest.parquet")
    res = _store(rd)
    # One row per job and stage: no (job, stage) twice, and every job of the manifest present.
    assert not res.duplicated(["job_id", "stage"]).any()
    assert sorted(res["job_id"].unique()) == sorted(man["job_id"])
    per_job = res.groupby("job_id")["stage"].agg(list)
    assert all(sorted(s) == list(stages) for s in per_job)
    # Each job was stored by one runner only, i.e. one shard label per job.
    assert (res.groupby("job_id")["shard"].nunique() == 1).all()
    return res


@pytest.mark.slow
def test_slurm_chain_on_cluster_with_failing_jobs(
    cluster: SlurmCluster, demo_run: Path, tmp_path: Path
) -> None:
    """The whole SLURM path without DOLFINx: every job fails at once (test-only fault switch).

    `WOUNDSWEEP_FAULT=exit:4` makes `woundsweep solve` exit as if the mesh failed, so each
    job is stored with a failure class in a fraction of a second; sbatch passes the
    variable on to the tasks. Then two results are deleted and the sweep resubmitted: only
    those two jobs are redone.
    """
    rd = tmp_path / "run"
    shutil.copytree(demo_run, rd)
    fault = {"WOUNDSWEEP_FAULT": "exit:4"}
    ids = _submit(rd, cluster, "--shards", "3", "--time", "00:20:00", env=fault)
    _wait(cluster, rd, timeout=300)
    _check_chain(cluster, rd, ids, 3)
    res = _assert_every_job_once(rd)
    man = pd.read_parquet(rd / "manifest.parquet")
    warm = warmup_shard(man)
    (warm_job,) = partition(man, warm.count)[warm.index]
    by_shard = res.drop_duplicates("job_id").set_index("job_index")["shard"]
    assert by_shard[warm_job] == str(warm)  # stored by the warm-up job, not redone by the array
    assert set(by_shard.drop(warm_job)) <= {"0/3", "1/3", "2/3"}
    status = (rd / "slurm" / "logs" / f"followup-{ids[2]}.log").read_text()
    assert "32 of 32 stored" in status, status

    files = sorted((rd / "results").glob("job-*.parquet"))
    assert len(files) == 32
    gone, kept = files[:2], files[2:]
    stamps = {p: p.stat().st_mtime_ns for p in kept}
    for p in gone:
        p.unlink()
    ids2 = _submit(rd, cluster, "--shards", "3", "--time", "00:20:00", env=fault)
    _wait(cluster, rd, timeout=300)
    _check_chain(cluster, rd, ids2, 3)
    assert all(p.is_file() for p in gone)  # redone
    assert {p: p.stat().st_mtime_ns for p in kept} == stamps  # not rewritten
    _assert_every_job_once(rd)


@pytest.mark.fem
@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_demo_sweep_on_cluster(cluster: SlurmCluster, tmp_path: Path) -> None:
    """sweeps/demo.yaml (32 jobs) as an array of 3 shards on the real one-node cluster.

    The full demo sweep, not a subset: with a cold JIT cache it takes a few minutes here
    (the warm-up compiles, then 32 coarse jobs on 2 CPUs).
    """
    rd = tmp_path / "run"
    assert ws("generate", str(DEMO), "--out", str(rd)).returncode == 0
    stages = "1-6"
    t0 = time.monotonic()
    ids = _submit(rd, cluster, "--shards", "3", "--time", "01:00:00", "--stages", stages)
    _wait(cluster, rd, timeout=1500)
    print(f"demo sweep on SLURM, stages {stages}: {time.monotonic() - t0:.0f} s wall, 32 jobs")
    _check_chain(cluster, rd, ids, 3)
    a, b = map(int, stages.split("-"))
    res = _assert_every_job_once(rd, range(a, b + 1))
    # Every job reached the solver and ended there: nothing crashed, timed out or was
    # refused (a broken environment in the tasks shows up as one of those).
    classes = res.drop_duplicates("job_id")["failure_class"].value_counts()
    assert set(classes.index) <= {"converged", "not-converged", "mesh-failed"}, classes
    assert classes.get("converged", 0) > 0, classes
    # The forms were compiled into the shared cache the scripts point at, by the warm-up:
    # when its job went through every stage, no task compiled anything after it ended.
    modules = list((rd / "slurm" / "cache" / "fenics").glob("libffcx_*.so"))
    assert modules
    man = pd.read_parquet(rd / "manifest.parquet")
    warm = warmup_shard(man)
    (warm_job,) = partition(man, warm.count)[warm.index]
    warm_rows = res[res["job_index"] == warm_job]
    assert set(warm_rows["shard"]) == {str(warm)}
    if set(warm_rows["failure_class"]) == {"converged"}:
        end = datetime.datetime.fromisoformat(cluster.job(ids[0])["EndTime"]).timestamp()
        late = [p.name for p in modules if p.stat().st_mtime > end + 1]
        assert not late, f"compiled after the warm-up: {late}"
    status = (rd / "slurm" / "logs" / f"followup-{ids[2]}.log").read_text()
    assert "32 of 32 stored" in status, status

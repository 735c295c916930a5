"""`woundsweep slurm`: the scripts, their shell behaviour, validation, and real SLURM runs.

The reference scripts live in tests/data/slurm/ with the run directory and the interpreter
replaced by ``@RUN_DIR@`` and ``@PYTHON@``. When the format changes on purpose, regenerate
them and review the diff:

    WOUNDSWEEP_REGEN=1 .venv/bin/pytest tests/test_slurm.py -k reference

The cluster tests start a private one-node SLURM (tests/slurm_cluster.py: munged, slurmctld,
slurmd from Debian's slurm-wlm and munge, installed when missing) and are skipped, with the
reason, where that needs root or apt-get and they are not available.
"""

from __future__ import annotations

import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
import yaml
from cli_run import DEMO, ROOT, ws
from slurm_cluster import ClusterError, SlurmCluster, start_cluster, unavailable_reason

from woundsweep.config.manifest import expand
from woundsweep.config.sweep import load_sweep
from woundsweep.execution.shards import Shard, estimate_cost, partition
from woundsweep.execution.slurm import (
    SCRIPT_NAMES,
    SlurmOptions,
    mem_bytes,
    parse_mem,
    render,
    warmup_shard,
)

DATA = ROOT / "tests" / "data" / "slurm"
REGEN = os.environ.get("WOUNDSWEEP_REGEN") == "1"


def _fixed_options(run_dir: Path) -> SlurmOptions:
    return SlurmOptions(
        run_dir=run_dir,
        shards=4,
        python=sys.executable,
        cpus_per_task=8,
        time="12:00:00",
        mem="16G",
        partition="compute",
        account="proj42",
        extra=("#SBATCH --qos=normal",),
        analyze=True,
        stages="1-6",
        warmup=Shard(5, 32),
    )


# ---- the scripts ------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SCRIPT_NAMES)
def test_scripts_match_reference(tmp_path: Path, name: str) -> None:
    run_dir = tmp_path / "run"
    scripts = dict(zip(SCRIPT_NAMES, render(_fixed_options(run_dir))))
    text = scripts[name].replace(sys.executable, "@PYTHON@").replace(str(run_dir), "@RUN_DIR@")
    ref = DATA / name
    if REGEN:
        ref.parent.mkdir(parents=True, exist_ok=True)
        ref.write_text(text)
        pytest.skip(f"regenerated {ref} (WOUNDSWEEP_REGEN=1): review the diff")
    assert ref.is_file(), f"{ref} missing: regenerate with WOUNDSWEEP_REGEN=1"
    assert text == ref.read_text()


def test_render_depends_only_on_options(tmp_path: Path) -> None:
    opts = _fixed_options(tmp_path / "run")
    assert render(opts) == render(opts)
    other = render(SlurmOptions(**{**opts.__dict__, "shards": 7}))
    assert "#SBATCH --array=0-6\n" in other.sweep
    assert '--shard "${SLURM_ARRAY_TASK_ID}/7"' in other.sweep
    plain = render(SlurmOptions(run_dir=tmp_path / "run", shards=2, python=sys.executable))
    # Optional directives are absent, not empty, when not asked for.
    for opt in ("--time", "--mem", "--partition", "--account", "--qos"):
        assert f"#SBATCH {opt}" not in plain.sweep
    assert plain.warmup is None
    assert "analyze" not in plain.followup


def _stub_python(where: Path) -> Path:
    """An executable that logs its arguments and the environment the scripts set."""
    where.mkdir(parents=True)
    stub = where / "python"
    stub.write_text(
        "#!/bin/bash\n"
        'log="$(dirname "$0")/calls.jsonl"\n'
        '"' + sys.executable + '" -c "import json, os, sys; print(json.dumps({'
        "'argv': sys.argv[1:], 'cwd': os.getcwd(), "
        "'env': {k: os.environ.get(k) for k in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', "
        '\'XDG_CACHE_HOME\')}}))" "$@" >> "$log"\n'
    )
    stub.chmod(0o755)
    return stub


def _calls(stub: Path) -> list[dict]:
    log = stub.parent / "calls.jsonl"
    return [json.loads(ln) for ln in log.read_text().splitlines()] if log.exists() else []


def test_scripts_run_the_right_commands_in_bash(tmp_path: Path) -> None:
    # The interpreter path has a space: the scripts must quote it.
    stub = _stub_python(tmp_path / "py env")
    run_dir = tmp_path / "run"
    opts = SlurmOptions(
        run_dir=run_dir, shards=3, python=str(stub), cpus_per_task=4, mem="3G",
        stages="2-3", analyze=True, warmup=Shard(2, 9),
    )  # fmt: skip
    scripts = render(opts)
    env = {k: v for k, v in os.environ.items() if not k.startswith("SLURM_")}
    for name, text in zip(SCRIPT_NAMES, scripts):
        (tmp_path / name).write_text(text)

    def bash(name: str, **extra: str) -> None:
        res = subprocess.run(
            ["bash", str(tmp_path / name)], env={**env, **extra}, capture_output=True, text=True
        )
        assert res.returncode == 0, res.stderr

    bash("sweep.sbatch", SLURM_ARRAY_TASK_ID="2", SLURM_CPUS_PER_TASK="4")
    bash("sweep.sbatch", SLURM_ARRAY_TASK_ID="0")  # --cpus-per-task not exported: 1 worker
    bash("warmup.sbatch")
    bash("followup.sbatch")
    calls = _calls(stub)
    rd = str(run_dir)
    run = ["-m", "woundsweep", "run", rd]
    # Memory cap per job, GB: 90% of 3 GiB = 2.899 GB; over 4 workers 0.725 GB.
    assert [c["argv"] for c in calls] == [
        [*run, "--shard", "2/3", "--workers", "4", "--stages", "2-3", "--max-memory", "0.72"],
        [*run, "--shard", "0/3", "--workers", "1", "--stages", "2-3", "--max-memory", "0.72"],
        [*run, "--shard", "2/9", "--workers", "1", "--stages", "2-3", "--max-memory", "2.90"],
        ["-m", "woundsweep", "status", rd],
        ["-m", "woundsweep", "analyze", rd],
    ]
    cache = str(run_dir / "slurm" / "cache")
    for c in calls:
        assert c["env"] == {
            "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "XDG_CACHE_HOME": cache
        }  # fmt: skip


@pytest.mark.parametrize(
    ("text", "expected"),
    [("3500", 3500 * 2**20), ("4g", 4 * 2**30), ("512K", 512 * 2**10), ("1T", 2**40)],
)
def test_memory_sizes_use_slurm_units(text: str, expected: int) -> None:
    # SLURM: binary units, no suffix means megabytes.
    assert mem_bytes(parse_mem(text)) == expected


def test_followup_stops_before_analyze_when_status_fails(tmp_path: Path) -> None:
    stub = tmp_path / "python"
    stub.write_text('#!/bin/bash\necho "$3" >> "$(dirname "$0")/calls"\n[ "$3" != status ]\n')
    stub.chmod(0o755)
    opts = SlurmOptions(run_dir=tmp_path / "run", shards=1, python=str(stub), analyze=True)
    (tmp_path / "f.sh").write_text(render(opts).followup)
    res = subprocess.run(["bash", str(tmp_path / "f.sh")], capture_output=True, text=True)
    assert res.returncode != 0
    assert (tmp_path / "calls").read_text().split() == ["status"]


def test_warmup_shard_holds_only_the_cheapest_job(demo_run: Path) -> None:
    man = pd.read_parquet(demo_run / "manifest.parquet")
    w = warmup_shard(man)
    assert w.count == len(man) == 32
    (only,) = partition(man, w.count)[w.index]  # exactly one job
    cost = estimate_cost(man)
    assert cost[man["job_index"] == only][0] == cost.min()
    # A one-job sweep: the warm-up is the whole sweep.
    assert warmup_shard(man.iloc[:1].copy()) == Shard(0, 1)


def test_warmup_shard_on_a_sweep_with_one_job_per_geometry(tmp_path: Path) -> None:
    sweep = yaml.safe_load(DEMO.read_text())
    sweep["grid"].update(skin_type=["soft"], orientation_deg=[0])
    path = tmp_path / "one.yaml"
    path.write_text(yaml.safe_dump(sweep))
    man = expand(load_sweep(path))
    assert man["geometry_id"].nunique() == len(man) == 16
    w = warmup_shard(man)
    (only,) = partition(man, w.count)[w.index]
    cost = estimate_cost(man)
    assert cost[man["job_index"] == only][0] == cost.min()


# ---- the command ------------------------------------------------------------------------------
def test_command_writes_the_rendered_scripts(demo_run: Path, tmp_path: Path) -> None:
    rd = tmp_path / "run"
    shutil.copytree(demo_run, rd)
    res = ws(
        "slurm", str(rd), "--shards", "4", "--cpus-per-task", "8", "--time", "12:00:00",
        "--mem", "16G", "--partition", "compute", "--account", "proj42",
        "--extra", "--qos=normal", "--analyze", "--stages", " 1 - 6",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    man = pd.read_parquet(rd / "manifest.parquet")
    expected = render(SlurmOptions(**{**_fixed_options(rd).__dict__, "warmup": warmup_shard(man)}))
    for name, text in zip(SCRIPT_NAMES, expected):
        assert (rd / "slurm" / name).read_text() == text
        assert os.access(rd / "slurm" / name, os.X_OK)
    assert (rd / "slurm" / "logs").is_dir()  # SLURM does not create --output's directory
    assert not (rd / "slurm" / "jobs.json").exists()  # nothing submitted


BAD_OPTIONS = [
    (["--shards", "0"], "--shards 0: need at least 1"),
    (["--shards", "-2"], "--shards -2: need at least 1"),
    (["--shards", "33"], "more shards than the 32 jobs"),
    (["--shards", "2", "--cpus-per-task", "0"], "--cpus-per-task 0"),
    (["--shards", "2", "--time", "4h"], "--time '4h': expected HH:MM:SS"),
    (["--shards", "2", "--time", "01:61:00"], "--time '01:61:00'"),
    (["--shards", "2", "--time", "00:00:00"], "longer than zero"),
    (["--shards", "2", "--mem", "lots"], "--mem 'lots'"),
    (["--shards", "2", "--mem", "0G"], "--mem '0G'"),
    (["--shards", "2", "--extra", "qos=long"], "--extra 'qos=long'"),
    (["--shards", "2", "--extra", "#SBATCH --qos=a\n#SBATCH --x"], "no newlines"),
    (["--shards", "2", "--partition", "a b"], "--partition 'a b'"),
    (["--shards", "2", "--stages", "4-2"], "--stages '4-2'"),
    (["--shards", "2", "--stages", "1-7"], "--stages '1-7'"),
]


@pytest.mark.parametrize(("args", "message"), BAD_OPTIONS)
def test_bad_options_one_line_exit_2(demo_run: Path, args: list[str], message: str) -> None:
    res = ws("slurm", str(demo_run), *args)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("woundsweep: error: "), res.stderr
    assert message in lines[0]
    assert not (demo_run / "slurm").exists()  # nothing written on bad options


def test_not_a_run_dir_and_unsafe_paths(tmp_path: Path, demo_run: Path) -> None:
    res = ws("slurm", str(tmp_path / "nothing"), "--shards", "2")
    assert res.returncode == 2 and "not a run directory" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    spaced = tmp_path / "my run"
    shutil.copytree(demo_run, spaced)
    res = ws("slurm", str(spaced), "--shards", "2")
    assert res.returncode == 2 and "cannot hold a path with spaces" in res.stderr
    pct = tmp_path / "run%j"
    shutil.copytree(demo_run, pct)
    res = ws("slurm", str(pct), "--shards", "2")
    assert res.returncode == 2 and "'%'" in res.stderr


def _fake_sbatch(bin_dir: Path, fail_on: int | None = None) -> Path:
    """An sbatch that logs its arguments, prints ids 101, 102, ... and can fail on call k."""
    bin_dir.mkdir(parents=True, exist_ok=True)
    exe = bin_dir / "sbatch"
    fail = f'[ "$n" = {fail_on} ] && {{ echo "sbatch: error: Batch job submission failed: Invalid account" >&2; exit 1; }}\n'
    exe.write_text(
        "#!/bin/bash\n"
        'd="$(dirname "$0")"; n=$(( $(cat "$d/n" 2>/dev/null || echo 0) + 1 )); echo $n > "$d/n"\n'
        'echo "$*" >> "$d/args"\n' + (fail if fail_on else "") + 'echo "$((100 + n));wstest"\n'
    )
    exe.chmod(0o755)
    return exe


def _env_with_path(bin_dir: Path) -> dict[str, str]:
    # Only bin_dir and the basics on PATH: a real sbatch elsewhere must not be found.
    return {**os.environ, "PATH": f"{bin_dir}:/usr/bin:/bin"}


def test_submit_chains_dependencies_and_records_ids(demo_run: Path, tmp_path: Path) -> None:
    rd = tmp_path / "run"
    shutil.copytree(demo_run, rd)
    bin_dir = tmp_path / "bin"
    _fake_sbatch(bin_dir)
    env = _env_with_path(bin_dir)
    res = ws("slurm", str(rd), "--shards", "3", "--submit", env=env)
    assert res.returncode == 0, res.stderr
    s = rd / "slurm"
    assert (bin_dir / "args").read_text().splitlines() == [
        f"--parsable {s / 'warmup.sbatch'}",
        f"--parsable --dependency=afterok:101 {s / 'sweep.sbatch'}",
        f"--parsable --dependency=afterany:102 {s / 'followup.sbatch'}",
    ]
    for jid in ("101", "102", "103"):
        assert jid in res.stdout
    # A resubmission appends a second record; the first is kept.
    assert ws("slurm", str(rd), "--shards", "3", "--submit", env=env).returncode == 0
    recs = json.loads((s / "jobs.json").read_text())["submissions"]
    ids = [(r["warmup_job_id"], r["array_job_id"], r["followup_job_id"]) for r in recs]
    assert ids == [("101", "102", "103"), ("104", "105", "106")]
    assert recs[0]["shards"] == 3 and recs[0]["warmup_shard"].endswith("/32")


def test_submit_failure_names_submitted_jobs(demo_run: Path, tmp_path: Path) -> None:
    rd = tmp_path / "run"
    shutil.copytree(demo_run, rd)
    bin_dir = tmp_path / "bin"
    _fake_sbatch(bin_dir, fail_on=3)
    res = ws("slurm", str(rd), "--shards", "3", "--submit", env=_env_with_path(bin_dir))
    assert res.returncode == 2
    line = res.stderr.strip()
    assert len(line.splitlines()) == 1 and "Invalid account" in line
    assert "already submitted: 101, 102" in line
    (rec,) = json.loads((rd / "slurm" / "jobs.json").read_text())["submissions"]
    assert (rec["warmup_job_id"], rec["array_job_id"], rec["followup_job_id"]) == (
        "101", "102", None
    )  # fmt: skip


def test_submit_without_sbatch(demo_run: Path, tmp_path: Path) -> None:
    rd = tmp_path / "run"
    shutil.copytree(demo_run, rd)
    empty = tmp_path / "bin"
    empty.mkdir()
    # PATH is only an empty directory: the command runs by absolute path and needs no PATH.
    res = ws("slurm", str(rd), "--shards", "3", "--submit", env={**os.environ, "PATH": str(empty)})
    assert res.returncode == 2
    assert res.stderr.strip() == (
        "woundsweep: error: sbatch not found on PATH: run --submit on a SLURM login node"
    )
    assert (rd / "slurm" / "sweep.sbatch").is_file()  # the scripts are still written
    assert not (rd / "slurm" / "jobs.json").exists()


# ---- a real cluster -----------------------------------------------------------------------------
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

"""`woundsweep slurm`: the scripts, their shell behaviour, validation and submission.

The reference scripts live in tests/data/slurm/ with the run directory and the interpreter
replaced by ``@RUN_DIR@`` and ``@PYTHON@``. When the format changes on purpose, regenerate
them and review the diff:

    WOUNDSWEEP_REGEN=1 .venv/bin/pytest tests/execution/test_slurm.py -k reference

Runs on a real one-node SLURM are the subject of test_slurm_cluster.py.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml
from cli_run import DEMO, ROOT, ws

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

"""One sweep per run: `generate --force` is refused while a run holds the run directory (a lock
that dies with its holder), two runners of one shard share its jobs, and a sweep rewritten
behind a runner's back is refused by its jobs, so no result is stamped with settings it was
not computed with (the solver test reverts the sweep and compares with a clean run).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from cli_run import WS
from dir_snapshot import snapshot
from runner_sweep import SWEEP, make_run, solve_processes

from woundsweep.store.reader import read_results


def _runner(rd: Path, *args: str, fault: str = "") -> subprocess.Popen[str]:
    env = {**os.environ, "WOUNDSWEEP_FAULT": fault}
    return subprocess.Popen(
        [*WS, "run", str(rd), "--no-progress", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip


def _wait_for_log(rd: Path, text: str, timeout: float = 120) -> None:
    deadline = time.time() + timeout
    while time.time() < deadline:
        for p in (rd / "logs").glob("*.log") if (rd / "logs").is_dir() else []:
            if text in p.read_text(errors="replace"):
                return
        time.sleep(0.1)
    raise AssertionError(f"no log holds {text!r}")


def _generate(sweep: Path, rd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*WS, "generate", str(sweep), "--out", str(rd), "--force"], capture_output=True, text=True
    )


def test_generate_force_is_refused_while_a_run_holds_the_directory(
    empty_run: Path, tmp_path: Path
) -> None:
    doc = yaml.safe_load((empty_run / "sweep.yaml").read_text())
    doc["materials"] = {"skin_types": {"stiff": {"c_kPa": 50.0}}}
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(doc))
    proc = _runner(empty_run, "--no-warmup", "--workers", "1", fault="hang")
    _wait_for_log(empty_run, "injecting hang")
    kept = {n: (empty_run / n).read_bytes() for n in ("sweep.yaml", "manifest.parquet")}
    res = _generate(other, empty_run)
    lines = res.stderr.splitlines()
    assert res.returncode == 2 and len(lines) == 1 and "in progress" in lines[0], res.stderr
    assert {n: (empty_run / n).read_bytes() for n in kept} == kept
    proc.send_signal(signal.SIGKILL)  # the lock dies with its holder, even by kill -9
    proc.wait()
    res = _generate(other, empty_run)
    assert res.returncode == 0, res.stderr
    assert (empty_run / "sweep.yaml").read_bytes() != kept["sweep.yaml"]


def test_two_runners_of_one_shard_run_each_job_once(empty_run: Path) -> None:
    args = ("--no-warmup", "--workers", "1", "--shard", "0/8", "--timeout", "3", "--retries", "0")
    procs = [_runner(empty_run, *args, fault="hang") for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    logs = sorted((empty_run / "logs").glob("*.log"))
    assert len(logs) == 4
    for log in logs:  # one attempt per job: no job was run by both
        assert log.read_text().count("=== woundsweep run:") == 1, log.read_text()
    ran = [int(out.split(" run")[0].rsplit(", ", 1)[1]) for out, _ in outs]
    assert sum(ran) == 4 and all(r > 0 for r in ran), outs
    df = pd.read_parquet(empty_run / "results")
    assert df["job_id"].nunique() == 4 and set(df["failure_class"]) == {"timeout"}


@pytest.mark.fem
@pytest.mark.slow
def test_sweep_rewritten_during_a_run_then_reverted_serves_no_stale_result(
    tmp_path: Path,
) -> None:
    rd = make_run(tmp_path, "run")  # 9 cylinder jobs; shard 0/9 holds one
    original = (rd / "sweep.yaml").read_bytes()
    stiffer = json.loads(json.dumps(SWEEP))
    stiffer["shapes"] = {"cylindrical": SWEEP["shapes"]["cylindrical"]}
    stiffer["materials"] = {"subcutis": {"C10_kPa": 0.8}}  # every job's result depends on it
    other = tmp_path / "stiffer.yaml"
    other.write_text(yaml.safe_dump(stiffer))
    ref = make_run(tmp_path, "reference")
    shard = ("--shard", "0/9", "--stages", "1-1", "--no-warmup", "--workers", "1")
    assert subprocess.run([*WS, "run", str(ref), "--no-progress", *shard]).returncode == 0

    # The first attempt hangs until its timeout; meanwhile the sweep is changed twice.
    proc = _runner(rd, *shard, "--timeout", "8", "--retries", "1", fault="hang#1")
    _wait_for_log(rd, "injecting hang")
    before = snapshot(rd)
    res = _generate(other, rd)
    assert res.returncode == 2 and "in progress" in res.stderr, res.stderr
    assert snapshot(rd) == before
    (rd / "sweep.yaml").write_text(other.read_text())  # by hand, past generate's lock
    out, err = proc.communicate(timeout=600)
    lines = err.splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "changed while this run" in lines[0], err
    assert not list((rd / "results").iterdir())  # the job refused the new settings
    assert not solve_processes(rd)

    (rd / "sweep.yaml").write_bytes(original)  # the revert
    res = subprocess.run(
        [*WS, "run", str(rd), "--no-progress", *shard], capture_output=True, text=True
    )
    assert res.returncode == 0 and "1 run (1 converged)" in res.stdout, res.stdout + res.stderr
    got = read_results(rd).set_index("job_id")
    want = read_results(ref).set_index("job_id")
    assert list(got.index) == list(want.index)
    for col in (
        "result_fingerprint",
        "p99_von_mises_kPa",
        "max_von_mises_kPa",
        "newton_iterations",
    ):
        assert got[col].tolist() == want[col].tolist(), col

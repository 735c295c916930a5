"""How `woundsweep run` ends when the machine, not the job, fails: a full disk ends the run at
once with one line (no retry, nothing stored for the job), and Ctrl-C is one line too.

The jobs are real processes forked by the runner's fork server; their faults come from the
test-only switch WOUNDSWEEP_FAULT (``enospc``: HDF5's "No space left on device" on stderr,
then a segmentation fault, as a solve on a full disk ended).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

from cli_run import WS
from runner_sweep import solve_processes

from woundsweep.execution.classify import classify
from woundsweep.execution.process import Attempt, Job


def _default_sigint() -> None:
    # The runner starts as from a shell, with Ctrl-C's default action: a child inherits an
    # ignored SIGINT, and a process that starts with it ignored rightly keeps ignoring it.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _run(rd: Path, fault: str, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "WOUNDSWEEP_FAULT": fault}
    return subprocess.Popen(
        [*WS, "run", str(rd), "--no-progress", "--no-warmup", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        preexec_fn=_default_sigint,
    )  # fmt: skip


def test_full_disk_ends_the_run_with_one_line_and_no_retry(empty_run: Path) -> None:
    proc = _run(empty_run, "enospc", "--workers", "1", "--retries", "2")
    out, err = proc.communicate(timeout=300)
    lines = err.splitlines()
    assert proc.returncode == 2 and len(lines) == 1, err
    assert lines[0].startswith("woundsweep: error: ") and "No space left on device" in lines[0]
    assert "Traceback" not in err
    logs = list((empty_run / "logs").iterdir())
    assert len(logs) == 1  # the first job only, and one attempt of it
    assert logs[0].read_text().count("=== woundsweep run:") == 1
    assert not list((empty_run / "results").iterdir())
    assert not list((empty_run / "tmp").iterdir())
    assert not solve_processes(empty_run)


def test_a_signal_after_hdf5s_disk_error_is_the_disk_not_a_crash(tmp_path: Path) -> None:
    log = tmp_path / "job.log"
    log.write_text(
        "stage 1 ...\nHDF5-DIAG: Error detected\n  #001: file write failed: errno = 28, "
        "error message = 'No space left on device'\nFatal Python error: Segmentation fault\n"
    )
    job = Job({"job_index": 0, "job_id": "0" * 16, "geometry_id": "1" * 16})
    att = Attempt(job, None, tmp_path / "out.h5", 0, time.time(), time.time() + 10)
    segv = signal.SIGSEGV  # as os.wait reports a child killed by it
    got = classify(att, int(segv), (1, 6), None, log)
    assert got.disk_full == "No space left on device"
    log.write_text("stage 1 ...\nFatal Python error: Segmentation fault\n")
    got = classify(att, int(segv), (1, 6), None, log)
    assert got.disk_full == "" and got.failure_class == "crashed"  # a real crash: retried


def test_ctrl_c_is_one_line_and_kills_the_jobs(empty_run: Path) -> None:
    proc = _run(empty_run, "hang", "--workers", "2")
    deadline = time.time() + 120
    while time.time() < deadline:
        logs = list((empty_run / "logs").glob("*.log")) if (empty_run / "logs").exists() else []
        if logs and any("injecting hang" in p.read_text() for p in logs):
            break
        time.sleep(0.1)
    else:
        proc.kill()
        raise AssertionError("no job started")
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err == "woundsweep: interrupted\n", repr(err)
    time.sleep(0.5)
    assert not solve_processes(empty_run)
    assert not list((empty_run / "results").iterdir())

"""The fork server (woundsweep.execution.forkserver): every job attempt a fresh forked child of one
process that has the solver stack imported, with the isolation of a process of its own.

The server is real (DOLFINx, PETSc and MPI imported and initialised before it forks); the
children run `woundsweep solve` with faults from the test-only switch WOUNDSWEEP_FAULT, or a
real stage-1 solve that must equal the same solve in a fresh interpreter bit for bit.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from cli_run import WS
from runner_sweep import make_run, solve_processes

from woundsweep.execution.forkserver import ForkServer, JobRequest
from woundsweep.execution.jitlock import may_compile
from woundsweep.execution.process import JOB_NAME, SERVER_NAME, kill_group

pytestmark = pytest.mark.fem  # the server imports DOLFINx

ENV = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONFAULTHANDLER="1")


@pytest.fixture(scope="module")
def server() -> Iterator[ForkServer]:
    fs = ForkServer(ENV, "test-forkserver")
    yield fs
    fs.close()


def _wait(fs: ForkServer, pid: int, timeout: float = 120) -> tuple[int, object]:
    deadline = time.time() + timeout
    while time.time() < deadline:
        got, status, usage = fs.wait4(pid)
        if got:
            return status, usage
        time.sleep(0.01)
    raise AssertionError(f"child {pid} still running after {timeout} s")


def _spawn(fs: ForkServer, log: Path, fault: str = "", job: JobRequest | None = None) -> int:
    env = dict(ENV, WOUNDSWEEP_FAULT=fault) if fault else dict(ENV)
    job = job or JobRequest(str(log.parent), 0, (1, 1), str(log.with_suffix(".h5")))
    log.touch()  # as the runner's header line does
    return fs.spawn(job, env, log, None).pid


def _stat(pid: int) -> list[str]:
    text = Path(f"/proc/{pid}/stat").read_text()
    return text[text.rindex(")") + 2 :].split()  # state, ppid, pgrp, session, ...


def _gone(pid: int, timeout: float = 10) -> bool:
    """The process has ended (gone, or a zombie waiting for init)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            if _stat(pid)[0] == "Z":
                return True
        except (FileNotFoundError, ProcessLookupError):  # reaped before or while reading
            return True
        time.sleep(0.02)
    return False


def test_crash_and_kill_cost_one_child_and_the_server_survives(
    server: ForkServer, tmp_path: Path
) -> None:
    # A real SIGSEGV: PETSc's handler (installed when the server imported it) is gone in the
    # child, so the child dies of the signal, after faulthandler's traceback in its log.
    pid = _spawn(server, tmp_path / "segv.log", "segv")
    first = server.pid
    status, usage = _wait(server, pid)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGSEGV
    log = (tmp_path / "segv.log").read_text()
    assert "injecting segv" in log and "Fatal Python error: Segmentation fault" in log
    assert "faults.py" in log and "PETSC ERROR" not in log
    # An uncaught exception: exit 1 with the traceback; an exit status passes through.
    status, _ = _wait(server, _spawn(server, tmp_path / "fail.log", "fail"))
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 1
    assert "RuntimeError: WOUNDSWEEP_FAULT=fail" in (tmp_path / "fail.log").read_text()
    status, _ = _wait(server, _spawn(server, tmp_path / "exit.log", "exit:4"))
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 4
    # A hang: its own session and process group, a child of the server, killed with its group.
    log = tmp_path / "hang.log"
    pid = _spawn(server, log, "hang")
    deadline = time.time() + 60
    while "injecting hang" not in log.read_text() and time.time() < deadline:
        time.sleep(0.02)
    _, ppid, pgrp, session = _stat(pid)[:4]
    assert (int(ppid), int(pgrp), int(session)) == (server.pid, pid, pid)
    assert Path(f"/proc/{pid}/comm").read_text().strip() == JOB_NAME
    assert Path(f"/proc/{server.pid}/comm").read_text().strip() == SERVER_NAME
    assert server.wait4(pid) == (0, 0, None)  # still running
    kill_group(pid)
    status, usage = _wait(server, pid)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
    assert usage.ru_utime < 5  # its own CPU time, not the server's imports
    with pytest.raises(ChildProcessError):  # reported once
        server.wait4(pid)
    # The same server, alive, still forks working children.
    assert server.pid == first and server.proc.poll() is None
    status, _ = _wait(server, _spawn(server, tmp_path / "ok.log", "exit:0"))
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
    assert server.pid == first


def test_server_that_dies_takes_its_children_and_is_started_again(tmp_path: Path) -> None:
    fs = ForkServer(ENV)
    try:
        log = tmp_path / "hang.log"
        pid = _spawn(fs, log, "hang")
        old = fs.pid
        while "injecting hang" not in log.read_text():
            time.sleep(0.02)
        os.kill(old, signal.SIGKILL)
        status, _ = _wait(fs, pid)
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
        assert _gone(pid) and _gone(old)  # the child died with its server (PR_SET_PDEATHSIG)
        assert "fork server ended" in log.read_text()
        status, _ = _wait(fs, _spawn(fs, tmp_path / "ok.log", "exit:0"))
        assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
        assert fs.pid not in (None, old)
    finally:
        fs.close()


def test_jit_locks_ignore_the_server_but_not_its_children(
    server: ForkServer, tmp_path: Path
) -> None:
    """A stale FFCx lock on a local disk is one no DOLFINx process could be compiling: the
    server (DOLFINx loaded, never compiling) does not count, a forked job does."""
    log = tmp_path / "hang.log"
    pid = _spawn(server, log, "hang")
    while "injecting hang" not in log.read_text():
        time.sleep(0.02)
    try:
        assert may_compile(Path(f"/proc/{pid}"), b"libffcx_forms_x", any_dolfinx=True)
        assert not may_compile(Path(f"/proc/{server.pid}"), b"libffcx_forms_x", True)
        assert not may_compile(Path(f"/proc/{pid}"), b"libffcx_forms_x", any_dolfinx=False)
    finally:
        kill_group(pid)
        _wait(server, pid)


def _datasets(path: Path) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    with h5py.File(path) as f:
        f.visititems(
            lambda n, o: out.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None
        )
        rows = json.loads(f.attrs["stage_results"])
    timing = {"time_s", "assembly_time_s", "factor_time_s"}
    timing |= {k for k in rows[0] if k.startswith("contact_") and k.endswith("_time_s")}
    out["rows"] = [{k: v for k, v in r.items() if k not in timing} for r in rows]
    return out


def test_forked_solve_equals_a_fresh_interpreter(server: ForkServer, tmp_path: Path) -> None:
    """MPI and PETSc (MUMPS) work in a child forked after their initialisation: stage 1 of a
    45-degree job gives the same fields, bit for bit, and the same result rows."""
    rd = make_run(tmp_path, "eq")
    manifest = pd.read_parquet(rd / "manifest.parquet")
    job = int(manifest.loc[manifest["orientation_deg"] == 45, "job_index"].iloc[0])
    args = ["solve", str(rd), "--job", str(job), "--stages", "1-1", "--out"]
    fresh = subprocess.run(
        [*WS, *args, str(tmp_path / "fresh.h5")], capture_output=True, text=True, env=ENV
    )
    assert fresh.returncode == 0, fresh.stderr
    forked = JobRequest(str(rd), job, (1, 1), str(tmp_path / "forked.h5"))
    pid = _spawn(server, tmp_path / "forked.log", "", forked)
    status, _ = _wait(server, pid)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
    assert "wrote" in (tmp_path / "forked.log").read_text()
    a, b = _datasets(tmp_path / "fresh.h5"), _datasets(tmp_path / "forked.h5")
    assert sorted(a) == sorted(b) and "stage_1/displacement_mm" in a
    assert a.pop("rows") == b.pop("rows")
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key  # profiles: NaN off the body
    assert np.abs(a["stage_1/displacement_mm"]).max() > 0


def _stderr_lines(err: str) -> list[str]:
    """The runner's stderr lines, without the warning of Python >= 3.14's multiprocessing
    resource tracker about tqdm's lock (the CLI ends with os._exit; not the runner's own)."""
    lines = err.strip().splitlines()
    for i, line in enumerate(lines):
        if "resource_tracker: There appear to be" in line:
            del lines[i : i + 2]  # the warning and its "warnings.warn(" source line
            break
    return lines


def _runner(rd: Path, *args: str) -> subprocess.Popen:
    cmd = [*WS, "run", str(rd), "--no-progress", "--stages", "1-1", "--no-warmup", *args]
    env = dict(os.environ, WOUNDSWEEP_FAULT="hang")
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)


def _jobs_of(rd: Path, n: int, timeout: float = 120) -> list[int]:
    """Wait until ``n`` forked job processes of ``rd`` run; their pids."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        jobs = [p for p in solve_processes(rd) if Path(f"/proc/{p}/comm").exists()]
        jobs = [p for p in jobs if Path(f"/proc/{p}/comm").read_text().strip() == JOB_NAME]
        if len(jobs) >= n and all(
            "injecting hang" in p.read_text() for p in (rd / "logs").glob("*.log")
        ):
            return jobs
        time.sleep(0.05)
    raise AssertionError(f"fewer than {n} jobs of {rd} started")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_runner_stopped_takes_its_server_and_jobs(tmp_path: Path, sig: int) -> None:
    """SIGTERM (a batch time limit): exit 143 with one line, jobs killed, nothing stored;
    kill -9: the server and the jobs die with the runner (PR_SET_PDEATHSIG)."""
    rd = make_run(tmp_path, "stop")
    proc = _runner(rd, "--workers", "2")
    jobs = _jobs_of(rd, 2)
    assert len(solve_processes(rd)) == 3  # the server and two jobs
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    if sig == signal.SIGTERM:
        assert proc.returncode == 143
        assert _stderr_lines(err) == [
            "woundsweep: error: terminated by SIGTERM: running jobs killed; rerun to resume"
        ]
    else:
        assert proc.returncode == -signal.SIGKILL
    assert all(_gone(p) for p in jobs)
    deadline = time.time() + 10
    while solve_processes(rd) and time.time() < deadline:
        time.sleep(0.05)
    assert not solve_processes(rd)
    assert not list((rd / "results").glob("*.parquet"))


def test_attempt_killed_with_its_server_is_retried_by_a_new_server(tmp_path: Path) -> None:
    """The runner's server dies while attempt 1 hangs: that attempt ends `crashed` (killed by
    SIGKILL), a new server starts, and attempt 2 solves the job."""
    rd = make_run(tmp_path, "respawn")
    cmd = [*WS, "run", str(rd), "--no-progress", "--stages", "1-1", "--shard", "0/9"]
    env = dict(os.environ, WOUNDSWEEP_FAULT="hang#1")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    (job,) = _jobs_of(rd, 1)
    (first,) = [p for p in solve_processes(rd) if p != job]
    os.kill(first, signal.SIGKILL)
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    assert "1 run (1 converged), 2 attempts" in out
    assert _stderr_lines(err) == [
        "woundsweep run: the fork server ended (returncode -9); 1 running attempt(s) killed"
        " with it; the next attempt starts a new one"
    ]
    row = pd.read_parquet(rd / "results").iloc[0]
    assert (row["failure_class"], row["attempts"]) == ("converged", 2)
    log = next((rd / "logs").glob("*.log")).read_text()
    assert "fork server ended; this attempt was killed" in log
    assert "attempt 1 ended: crashed: killed by SIGKILL" in log
    assert "attempt 2 ended: converged" in log
    assert not solve_processes(rd)

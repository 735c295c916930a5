"""The runner with real processes: fault classes, retries, kill -9 and resume, concurrent shards.

Jobs are real `woundsweep solve` subprocesses; faults come from the test-only switch
WOUNDSWEEP_FAULT, which `solve` reads before doing anything else. Real solves run stage 1
only on a coarse one- or two-geometry sweep, to keep the time down.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import yaml
from cli_run import WS
from runner_sweep import SWEEP, make_run, solve_processes

from woundsweep.cli import COMMANDS
from woundsweep.config.manifest import load_run
from woundsweep.core.faults import FaultSpec, parse_faults
from woundsweep.execution.classify import stability_note
from woundsweep.execution.jitlock import JIT_TIMEOUT_RE, clear_stale_jit_locks, lock_state
from woundsweep.execution.shards import partition
from woundsweep.store.reader import read_results

needs_solve = pytest.mark.skipif(
    "solve" not in COMMANDS, reason="`woundsweep solve` is not registered in woundsweep/cli.py yet"
)


def _run(
    rd: Path, *args: str, env: dict | None = None, timeout: float = 900
) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*WS, "run", str(rd), "--no-progress", "--stages", "1-1", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
    )


def _assert_each_job_once(rd: Path, stages: int = 1) -> pd.DataFrame:
    manifest = load_run(rd).manifest
    df = pd.read_parquet(rd / "results")
    assert sorted(df["job_id"].unique()) == sorted(manifest["job_id"])
    assert (df.groupby("job_id").size() == stages).all()
    assert df.duplicated(["job_id", "stage"]).sum() == 0
    assert len(read_results(rd)) == len(df)  # every file passes validation
    for name in df["fields_file"].unique():
        if name:
            with h5py.File(rd / "fields" / name) as f:
                for key in json.loads(f.attrs["stored_stages"]):
                    assert np.isfinite(f[f"stage_{key}/von_mises_kPa"][()]).all()
    return df


# ---- the fault switch itself ----------------------------------------------------------
def test_stability_note_of_a_failed_stage() -> None:
    """The failure detail of a not-converged job says whether its last converged state was
    stable (stages.py records the lowest eigenvalue nearest zero of the tangent there)."""
    assert stability_note({"status": "max-iterations"}) == ""
    assert stability_note({"stability_min_eig_mN_per_mm": None}) == ""
    assert stability_note({"stability_min_eig_mN_per_mm": float("nan")}) == ""
    unstable = {"stability_min_eig_mN_per_mm": -0.10651, "stability_penalty_kPa": 50339.0}
    assert stability_note(unstable) == (
        "; last converged state unstable (lowest eigenvalue -0.107 mN/mm at k_V = 5.03e+04 kPa)"
    )
    stable = stability_note({"stability_min_eig_mN_per_mm": 0.0036, "stability_penalty_kPa": 947})
    assert stable.startswith("; last converged state stable (lowest eigenvalue 0.0036 mN/mm")


def test_parse_faults() -> None:
    assert parse_faults("hang") == [FaultSpec("hang", None, None, None)]
    assert parse_faults("exit:4@7, segv@2#1") == [
        FaultSpec("exit", 4, 7, None),
        FaultSpec("segv", None, 2, 1),
    ]
    spec = parse_faults("segv@2#1")[0]
    assert spec.matches(2, 1) and not spec.matches(2, 2) and not spec.matches(3, 1)
    for bad in ("explode", "exit", "hang:3", "exit:x", "segv@two"):
        with pytest.raises(ValueError, match="WOUNDSWEEP_FAULT"):
            parse_faults(bad)


@pytest.mark.parametrize(
    "fault,returncode",
    [("exit:5", 5), ("fail", 1), ("segv", -signal.SIGSEGV), ("exit:0@3", None), ("fail#2", None)],
)
def test_fault_switch_in_a_process(fault: str, returncode: int | None) -> None:
    code = "from woundsweep.core.faults import maybe_inject; maybe_inject(0); print('not injected')"
    res = subprocess.run(
        [sys.executable, "-c", code],
        env=dict(os.environ, WOUNDSWEEP_FAULT=fault, WOUNDSWEEP_ATTEMPT="1"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    if returncode is None:  # aimed at another job or attempt: nothing happens
        assert res.returncode == 0 and "not injected" in res.stdout
    else:
        assert res.returncode == returncode and "not injected" not in res.stdout


# ---- FFCx JIT locks (real FFCx, private cache) ------------------------------------------
_COMPILE = """
import sys, ufl
from ffcx.codegeneration.jit import compile_forms
try:  # basix >= 0.7 (DOLFINx >= 0.7): elements come from basix.ufl
    import basix.ufl
    el = basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,))
    mesh = ufl.Mesh(basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,)))
except ImportError:
    el = ufl.VectorElement("Lagrange", ufl.tetrahedron, 1)
    mesh = ufl.Mesh(el)
V = ufl.FunctionSpace(mesh, el)
u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
compile_forms([ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx], cache_dir=sys.argv[1], timeout=1)
print("compiled")
"""


@pytest.mark.fem
def test_stale_jit_lock_from_a_killed_compile_is_recovered(tmp_path: Path) -> None:
    cache = tmp_path / "fenics"
    # A compile killed with its process group (the C compiler too) right after taking the lock.
    proc = subprocess.Popen(
        [sys.executable, "-c", _COMPILE, str(cache)], start_new_session=True, stdout=subprocess.PIPE
    )
    deadline = time.time() + 60
    while not list(cache.glob("libffcx_forms_*.c")) and time.time() < deadline:
        time.sleep(0.002)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    locks = list(cache.glob("libffcx_forms_*.c"))
    assert len(locks) == 1 and not locks[0].with_suffix(".c.cached").exists()
    # FFCx itself waits for that lock and gives up: the message names the lock file.
    res = subprocess.run(
        [sys.executable, "-c", _COMPILE, str(cache)], capture_output=True, text=True
    )
    assert res.returncode != 0 and "TimeoutError" in res.stderr
    m = JIT_TIMEOUT_RE.search(res.stderr)
    assert m and Path(m.group(1)) == locks[0]
    time.sleep(1.1)
    assert lock_state(locks[0], stale_after_s=1.0) == "stale"
    assert clear_stale_jit_locks(cache, stale_after_s=1.0) == locks
    res = subprocess.run(
        [sys.executable, "-c", _COMPILE, str(cache)], capture_output=True, text=True
    )
    assert res.returncode == 0 and "compiled" in res.stdout
    assert locks[0].with_suffix(".c.cached").exists()
    assert lock_state(locks[0], stale_after_s=1.0) == "released"


# ---- the runner with real `woundsweep solve` jobs -----------------------------------------
@needs_solve
@pytest.mark.fem
@pytest.mark.slow
def test_each_fault_lands_in_its_class(tmp_path: Path) -> None:
    rd = make_run(tmp_path, "faults")  # 9 jobs, one geometry; job 0 warms up alone
    faults = "hang@1,segv@2,oom@3,fail@4,exit:2@5,exit:4@6,segv@7#1"
    res = _run(
        rd, "--workers", "2", "--timeout", "30", "--max-memory", "2", "--retries", "1",
        env=dict(os.environ, WOUNDSWEEP_FAULT=faults),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    jobs = pd.read_parquet(rd / "results").set_index("job_index").sort_index()
    expected = {
        0: ("converged", 1),
        1: ("timeout", 2),  # transient: retried once (--retries 1)
        2: ("crashed", 2),
        3: ("out-of-memory", 1),  # not retried
        4: ("crashed", 2),
        5: ("invalid", 1),
        6: ("mesh-failed", 1),
        7: ("converged", 2),  # crashed on attempt 1 only, then solved
        8: ("converged", 1),
    }
    got = {i: (r.failure_class, r.attempts) for i, r in jobs.iterrows()}
    assert got == expected
    assert "SIGSEGV" in jobs.loc[2, "failure_detail"]
    assert "cap" in jobs.loc[3, "failure_detail"]  # stopped by the runner's cap, not by itself
    assert jobs.loc[3, "max_rss_MiB"] > 1900
    assert "RuntimeError" in jobs.loc[4, "failure_detail"] and jobs.loc[4, "exit_code"] == 1
    assert jobs.loc[5, "exit_code"] == 2 and jobs.loc[6, "exit_code"] == 4
    assert jobs.loc[1, "total_wall_time_s"] >= 2 * 30
    for i in (0, 7, 8):
        assert jobs.loc[i, "status"] == "converged" and jobs.loc[i, "p99_von_mises_kPa"] > 0
        assert jobs.loc[i, "fields_file"]
    for i in range(1, 7):
        assert jobs.loc[i, "status"] == "not-run" and jobs.loc[i, "fields_file"] == ""
    log = (rd / "logs" / f"job-{jobs.loc[7, 'job_id']}.log").read_text()
    assert log.count("attempt 1 ended: crashed") == 1 and "attempt 2 ended: converged" in log
    assert not solve_processes(rd) and not list((rd / "tmp").iterdir())

    # Resume does nothing; --rerun-failed reruns exactly the six failed jobs (faults off now).
    res = _run(rd, "--workers", "2")
    assert res.returncode == 0 and "9 already done, 0 run" in res.stdout
    res = _run(rd, "--workers", "2", "--rerun-failed")
    assert res.returncode == 0 and "3 already done, 6 run" in res.stdout
    df = _assert_each_job_once(rd)
    assert (df["failure_class"] == "converged").all()


@needs_solve
@pytest.mark.fem
@pytest.mark.slow
def test_kill9_mid_shard_then_resume(tmp_path: Path) -> None:
    rd = make_run(tmp_path, "kill", shapes=("cylindrical", "wedge"))  # 18 jobs
    cmd = [*WS, "run", str(rd), "--no-progress", "--stages", "1-1", "--workers", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 600
    while len(list((rd / "results").glob("*.parquet"))) < 3 and time.time() < deadline:
        time.sleep(0.05)
    before = {p.name: p.stat().st_mtime_ns for p in (rd / "results").glob("*.parquet")}
    assert 3 <= len(before) < 18
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    time.sleep(0.5)
    assert not solve_processes(rd)  # the jobs died with their runner
    # Whatever the instant, the store is readable and holds whole jobs only.
    df = read_results(rd)
    assert (df.groupby("job_id").size() == 1).all()

    res = _run(rd, "--workers", "2")
    assert res.returncode == 0, res.stderr
    df = _assert_each_job_once(rd)
    assert (df["failure_class"] == "converged").all()
    # Jobs stored before the kill were not run again.
    for name, mtime in before.items():
        assert (rd / "results" / name).stat().st_mtime_ns == mtime
    assert not list((rd / "tmp").iterdir())  # the killed runner's temporaries were cleaned

    # A damaged result file: status counts it (naming it); a rerun redoes that job.
    victim = sorted((rd / "results").glob("*.parquet"))[4]
    victim.write_bytes(victim.read_bytes()[:-40])
    s = _status_json(rd)
    assert (s["jobs_done"], s["jobs_damaged"]) == (17, 1) and str(victim) in s["damaged_example"]
    res = _run(rd, "--workers", "1")
    assert res.returncode == 0 and "17 already done, 1 run" in res.stdout
    assert len(list((rd / "corrupt").iterdir())) == 1
    _assert_each_job_once(rd)

    # A fields file overwritten with random bytes of the same size: found, moved, redone.
    fields = sorted((rd / "fields").glob("[0-9a-f]*.h5"))[2]
    size = fields.stat().st_size
    fields.write_bytes(np.random.default_rng(0).integers(0, 256, size, dtype=np.uint8).tobytes())
    s = _status_json(rd)
    assert (s["jobs_done"], s["jobs_damaged"]) == (17, 1) and str(fields) in s["damaged_example"]
    res = _run(rd, "--workers", "1")
    assert res.returncode == 0 and "17 already done, 1 run (1 converged)" in res.stdout
    assert len(list((rd / "corrupt").glob(f"{fields.name}.*"))) == 1
    assert (_assert_each_job_once(rd)["failure_class"] == "converged").all()
    assert _status_json(rd)["jobs_damaged"] == 0


def _status_json(rd: Path) -> dict:
    res = subprocess.run([*WS, "status", str(rd), "--json"], capture_output=True, text=True)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    return json.loads(res.stdout)


@needs_solve
@pytest.mark.fem
@pytest.mark.slow
def test_materials_change_recomputes_the_stale_jobs_with_the_solver(tmp_path: Path) -> None:
    """generate --force with other stiff-skin values: only the stiff jobs are redone, and
    their stresses change; the job ids stay."""
    rd = make_run(tmp_path, "stale")
    assert _run(rd, "--workers", "2").returncode == 0
    before = read_results(rd).set_index("job_id")
    sweep = json.loads(json.dumps(SWEEP))
    sweep["shapes"] = {"cylindrical": SWEEP["shapes"]["cylindrical"]}
    sweep["materials"] = {"skin_types": {"stiff": {"c_kPa": 85.2}, "soft": {}, "normal": {}}}
    yml = tmp_path / "stiffer.yaml"
    yml.write_text(yaml.safe_dump(sweep))
    gen = subprocess.run(
        [*WS, "generate", str(yml), "--out", str(rd), "--force"], capture_output=True, text=True
    )
    assert gen.returncode == 0 and "stored results: 3 stale" in gen.stdout, gen.stderr
    s = _status_json(rd)
    assert (s["jobs_done"], s["jobs_stale"], s["jobs_pending"]) == (6, 3, 3)
    res = _run(rd, "--workers", "2")
    assert res.returncode == 0 and "6 already done, 3 run (3 converged)" in res.stdout
    after = read_results(rd).set_index("job_id")
    assert sorted(after.index) == sorted(before.index)
    stiff = after["skin_type"] == "stiff"
    p99 = "p99_von_mises_kPa"
    assert (after.loc[stiff, p99] != before.loc[after.index[stiff], p99]).all()
    assert (after.loc[~stiff, p99] == before.loc[after.index[~stiff], p99]).all()


@needs_solve
@pytest.mark.fem
@pytest.mark.slow
def test_two_shards_at_once_into_one_run_dir(tmp_path: Path) -> None:
    rd = make_run(tmp_path, "shards", shapes=("cylindrical", "wedge"))  # 18 jobs, 2 geometries
    cmd = [*WS, "run", str(rd), "--no-progress", "--stages", "1-1", "--workers", "1"]
    procs = [
        subprocess.Popen(
            [*cmd, "--shard", f"{i}/2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for i in range(2)
    ]
    outs = [p.communicate(timeout=1200) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    df = _assert_each_job_once(rd)
    manifest = load_run(rd).manifest
    jobs = df.drop_duplicates("job_id").set_index("job_index")
    for i, idx in enumerate(partition(manifest, 2)):
        assert (jobs.loc[idx, "shard"] == f"{i}/2").all()
    res = subprocess.run([*WS, "status", str(rd), "--json"], capture_output=True, text=True)
    s = json.loads(res.stdout)
    assert s["jobs_done"] == 18 and s["jobs_pending"] == 0 and s["rows"] == len(df)
    counts = jobs["failure_class"].value_counts().to_dict()
    assert {k: v for k, v in s["by_failure_class"].items() if v} == counts
    assert s["by_stage"]["1"]["converged"] == int((df["status"] == "converged").sum())
    assert s["cpu_time_used_s"] == pytest.approx(jobs["total_cpu_time_s"].sum())


@needs_solve
@pytest.mark.fem
@pytest.mark.slow
def test_job_killed_mid_compile_leaves_a_lock_the_next_run_recovers_from(tmp_path: Path) -> None:
    rd = make_run(tmp_path, "jit")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))  # a cold, private JIT cache
    cache = tmp_path / "cache" / "fenics"
    # Killed at the timeout while FFCx compiles: through a C compiler that first waits far
    # longer than the timeout, the kill lands inside the first compile however fast the
    # machine or the DOLFINx version compiles (the job starts within seconds).
    slow_cc = tmp_path / "slow-cc"
    slow_cc.write_text(f'#!/bin/sh\nsleep 600\nexec {shutil.which("gcc") or "cc"} "$@"\n')
    slow_cc.chmod(0o755)
    slow = dict(env, CC=str(slow_cc))
    res = _run(rd, "--shard", "0/9", "--timeout", "20", "--retries", "0", "--no-warmup", env=slow)
    assert res.returncode == 0, res.stderr
    first = pd.read_parquet(rd / "results")
    assert first["failure_class"].tolist() == ["timeout"]
    locks = [p for p in cache.glob("libffcx_*.c") if not p.with_suffix(".c.cached").exists()]
    assert len(locks) == 1  # FFCx would make every later job wait 900 s on it
    time.sleep(3)
    t0 = time.time()
    res = _run(rd, "--shard", "0/9", "--rerun-failed", "--jit-stale-after", "2", env=env)
    assert res.returncode == 0, res.stderr
    assert time.time() - t0 < 300
    assert pd.read_parquet(rd / "results")["failure_class"].tolist() == ["converged"]
    # The dead compile's lock was moved aside and the module compiled afresh.
    assert list(cache.glob(locks[0].stem + ".c.stale-*"))
    assert locks[0].with_suffix(".c.cached").exists()

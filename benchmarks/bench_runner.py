"""Runner overhead and throughput on sweeps/demo.yaml.

Prints:
- per-job overhead of the runner: a job whose solve exits at once (test-only fault switch
  ``exit:0``: the fork from the runner's fork server, classification, the store write of its
  rows), measured through the real runner; plus what a real job pays before its solve (the
  solver-stack imports and loading the run, in a forked child and in a fresh interpreter);
  against the median wall time of a real demo job;
- the store write alone for a real solver output (fields "final");
- jobs per hour with 1 and with 2 workers on the same jobs (a fresh RUN_DIR each, after one
  warm-up job so both start from a warm JIT cache).

    python benchmarks/bench_runner.py              # shard 0/4 of the demo (8 jobs)
    python benchmarks/bench_runner.py --shards 1   # the whole demo (32 jobs)
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
WS = [sys.executable, "-m", "woundsweep"]


def _generate(rd: Path) -> None:
    subprocess.run(
        [*WS, "generate", str(ROOT / "sweeps" / "demo.yaml"), "--out", str(rd)],
        check=True,
        stdout=subprocess.DEVNULL,
    )


def _run(rd: Path, *args: str, env: dict[str, str] | None = None) -> float:
    t0 = time.perf_counter()
    subprocess.run(
        [*WS, "run", str(rd), "--no-progress", *args],
        check=True,
        env=env,
        stdout=subprocess.DEVNULL,
    )
    return time.perf_counter() - t0


def _startup_cost(rd: Path, runs: int = 5) -> dict[str, float]:
    """Median wall time of `solve --job <missing>` minus that of an empty job (fault exit:0),
    forked by a fork server and as a fresh ``python -m woundsweep`` process."""
    from woundsweep.execution.forkserver import ForkServer, JobRequest

    env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONFAULTHANDLER="1")
    empty = dict(env, WOUNDSWEEP_FAULT="exit:0")
    request = JobRequest(str(rd), 1000000, (1, 1), str(rd / "bench-startup.h5"))
    missing = request.command()[3:]
    log = rd / "bench-startup.log"
    server = ForkServer(env)
    server.spawn(request, env, log, None)  # start it (untimed)

    def forked(job_env: dict[str, str]) -> float:
        t0 = time.perf_counter()
        pid = server.spawn(request, job_env, log, None).pid
        while not server.wait4(pid)[0]:
            time.sleep(0.001)
        return time.perf_counter() - t0

    def fresh(job_env: dict[str, str]) -> float:
        t0 = time.perf_counter()
        subprocess.run([*WS, *missing], env=job_env, capture_output=True, check=False)
        return time.perf_counter() - t0

    def median(fn: object, job_env: dict[str, str]) -> float:
        return sorted(fn(job_env) for _ in range(runs))[runs // 2]  # type: ignore[operator]

    try:
        return {
            "fork": median(forked, env) - median(forked, empty),
            "fresh": median(fresh, env) - median(fresh, empty),
        }
    finally:
        server.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shards", type=int, default=4, help="run shard 0 of this many (default 4)")
    ap.add_argument("--stages", default="1-3", help="the stages each job runs")
    args = ap.parse_args()
    shard = f"0/{args.shards}"
    print(f"load average before (cores: {os.cpu_count()}): {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory(prefix="bench-runner-") as tmp:
        tmp_path = Path(tmp)

        # 1. Pure runner overhead: every job exits 0 at once (then is classified "crashed":
        #    no output), through the real runner with one worker, on 8 and on 32 jobs: the
        #    difference per job leaves out what a runner pays once (its start, the fork
        #    server's start, the scan of the store).
        env = dict(os.environ, WOUNDSWEEP_FAULT="exit:0")
        walls, counts = [], []
        for name, part in (("overhead8", "0/4"), ("overhead32", "0/1")):
            rd = tmp_path / name
            _generate(rd)
            walls.append(
                _run(
                    rd, "--shard", part, "--workers", "1", "--retries", "0", "--no-warmup", env=env
                )
            )
            df = pd.read_parquet(rd / "results").drop_duplicates("job_id")
            counts.append(len(df))
        per_job = (walls[1] - walls[0]) / (counts[1] - counts[0])
        startup = walls[0] - counts[0] * per_job
        sub = df["job_wall_time_s"].median()
        print(
            f"runner overhead: {counts[0]} / {counts[1]} empty jobs in {walls[0]:.1f} / "
            f"{walls[1]:.1f} s: {per_job:.3f} s/job (fork, CLI, exit, as the runner measured it:"
            f" {sub:.3f} s; the rest: polling, classification, store write); once per runner"
            f" (start, fork server, store scan): {startup:.1f} s"
        )

        # What a real job pays beyond an empty one before its solve starts: the solver-stack
        # imports and loading the run (`solve --job <not in the manifest>` exits 2 right
        # after them), in a child of the fork server and, for reference, in a fresh
        # interpreter (each job's process before the fork server).
        imports = _startup_cost(rd)
        print(
            f"  job start beyond an empty job (imports, loading the run): forked child"
            f" {imports['fork']:.3f} s/job; fresh interpreter {imports['fresh']:.2f} s/job"
        )
        print(
            f"  runner overhead per job (empty job + job start): "
            f"{per_job + imports['fork']:.3f} s (target <= 0.2 s)"
        )
        imports = imports["fork"]

        # 2. Warm the JIT cache with one real job, untimed.
        warm = tmp_path / "warm"
        _generate(warm)
        _run(warm, "--shard", f"0/{32}", "--workers", "1", "--stages", args.stages)

        # 3. Throughput with 1 and 2 workers on the same jobs.
        rates = {}
        for k in (1, 2):
            rd = tmp_path / f"k{k}"
            _generate(rd)
            wall = _run(rd, "--shard", shard, "--workers", str(k), "--stages", args.stages)
            df = pd.read_parquet(rd / "results")
            jobs = df.drop_duplicates("job_id")
            rates[k] = len(jobs) / wall * 3600
            solve = jobs["job_wall_time_s"].median()
            stage_time = df.groupby("job_id")["time_s"].sum().median()
            classes = jobs["failure_class"].value_counts().to_dict()
            print(
                f"{k} worker(s): {len(jobs)} jobs in {wall:.0f} s = {rates[k]:.0f} jobs/h; "
                f"median job wall {solve:.1f} s (of which Newton stages {stage_time:.1f} s); {classes}"
            )
            if k == 1:
                over = per_job + imports
                print(
                    f"  overhead (empty job + imports) / median job: {over:.2f} / {solve:.1f} s = "
                    f"{100 * over / solve:.1f}% (target < 10%)"
                )
                from woundsweep.config.manifest import load_run
                from woundsweep.store.solverfile import read_solver_file
                from woundsweep.store.writer import AttemptOutcome, Store

                # Store write alone, for one real result re-solved to a scratch file.
                run = load_run(rd)
                row = run.manifest.iloc[int(jobs["job_index"].iloc[0])]
                out = tmp_path / "one.h5"
                subprocess.run(
                    [*WS, "solve", str(rd), "--job", str(int(row["job_index"])), "--stages",
                     args.stages, "--out", str(out)],
                    stdout=subprocess.DEVNULL, check=False,
                )  # fmt: skip
                if out.exists():
                    a, b = (int(x) for x in args.stages.split("-"))
                    so = read_solver_file(out, row["job_id"], (a, b))
                    oc = AttemptOutcome(
                        "converged", "", 0, 1, 1.0, 1.0, 1.0, 1.0, None, 0.0, 1.0, so
                    )
                    scratch = tmp_path / "scratch"
                    scratch.mkdir()
                    t0 = time.perf_counter()
                    for _ in range(5):
                        Store(scratch, run.sweep).write_job(
                            row.to_dict(), oc, (a, b), "final", "0/1"
                        )
                    print(
                        f"  store write (rows + final fields + mesh): {(time.perf_counter() - t0) / 5 * 1000:.0f} ms/job"
                    )
        print(f"speedup 2 vs 1 worker: {rates[2] / rates[1]:.2f}x (target >= 1.7x)")
        print(f"load average now (cores: {os.cpu_count()}): {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

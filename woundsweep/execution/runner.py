"""`woundsweep run`: every job in its own process, with a timeout, a memory cap and retries.

One runner process drives a shard. It keeps up to K jobs running, each as
``woundsweep solve RUN_DIR --job N --stages A-B --out TMP.h5`` in its own process group,
forked by the runner's fork server (`woundsweep.execution.forkserver`, `woundsweep.execution.process`),
and polls them from a single thread (no threads: ``preexec_fn`` is only safe without them).
A job is killed with its whole process group when it exceeds the wall-clock timeout or the
memory cap. The cap is enforced two ways: the
resident set of the job's process tree is polled and the group killed above ``--max-memory``
(so the runner knows it was memory and says so); ``RLIMIT_AS`` is set at twice the cap plus
1 GiB as a backstop against allocations faster than the poll (address space runs well above
RSS: importing DOLFINx alone maps ~0.5 GB). An ended attempt gets its failure class from
`woundsweep.execution.classify`; the transient ones are retried (``--retries``).

Warm-up: FFCx compiles each form once per machine (~50 s for the Fung Jacobian) and processes
that need a form being compiled wait on its lock for only 10 s (`woundsweep.execution.jitlock`).
So the runner starts with one job alone (the cheapest of the shard) and fans out to K workers
once a job has been through the solver (converged or not), or after three tries. Jobs started
while the cache may still be cold get ``warmup_extra_s`` more time.

Which jobs run, and in which order, is planned by `woundsweep.execution.planning`.
"""

from __future__ import annotations

import errno
import os
import signal
import socket
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, NamedTuple

from ..config.manifest import JobRow, Run, load_run
from ..core.errors import StoreError, WoundsweepError
from ..core.faults import ATTEMPT_ENV
from ..core.fsutil import NotRegularFile, open_regular
from ..core.layout import RunLayout
from ..core.runlock import claim, hold_run, release
from ..core.schema import ExitCode, FailureClass, ResultState
from ..store import AttemptOutcome, Store
from .classify import TRANSIENT_CLASSES, classify
from .forkserver import ForkServer, JobRequest
from .jitlock import break_lock, clear_stale_jit_locks, jit_cache_dir, lock_state
from .planning import ShardPlan, mtime_ns, plan_shard
from .process import Attempt, Job, kill_group, tree_rss
from .shards import Shard

__all__ = ["RunOptions", "RunSummary", "Terminated", "run_shard"]

WARMUP_MAX_JOBS = 3


@dataclass(frozen=True)
class RunOptions:
    """Settings of one ``woundsweep run``."""

    shard: Shard = Shard(0, 1)
    workers: int = 1
    timeout_s: float = 1800.0
    max_memory_bytes: int | None = None
    retries: int = 2
    rerun_failed: bool = False
    stages: tuple[int, int] = (1, 6)
    fields: str = "final"
    warmup: bool = True
    warmup_extra_s: float = 900.0
    jit_stale_after_s: float = 600.0
    progress: bool | None = None  # None: only on a terminal
    poll_s: float = 0.05


class RunSummary(NamedTuple):
    """What one ``run_shard`` did."""

    jobs: int
    skipped: int
    ran: int
    by_class: dict[str, int]
    attempts: int
    wall_time_s: float


def _append(log: Path) -> Any:
    """The job's log opened for appending; only a regular file in ``logs/`` (a link or a
    named pipe there is refused: StoreError naming it)."""
    try:
        fd = open_regular(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
    except NotRegularFile as err:
        raise StoreError(f"{log}: {err.strerror} (move it away)") from None
    fh = os.fdopen(fd, "ab")
    fh.seek(0, os.SEEK_END)
    return fh


class _Runner:
    def __init__(self, store: Store, opts: RunOptions) -> None:
        self.run_dir = store.run_dir
        self.opts = opts
        self.store = store  # its sweep stamps the results and is the one each job must have
        self.claims: dict[str, int] = {}  # job_id -> the claim on its log (`core.runlock`)
        self.running: dict[int, Attempt] = {}
        self.by_class: dict[str, int] = {}
        self.attempts = 0
        self.warming = opts.warmup
        self.warmup_tries = 0
        self.cache_dir = jit_cache_dir()
        self.host = socket.gethostname()
        self.env = dict(os.environ)
        self.env["PYTHONUNBUFFERED"] = "1"
        self.env["PYTHONFAULTHANDLER"] = "1"  # a segfault leaves a Python traceback in the log
        if opts.workers > 1:  # K processes on K cores: threads inside each would oversubscribe
            for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
                self.env[var] = "1"
        self.server = ForkServer(self.env, str(self.run_dir))  # forks the attempts' processes

    # -- starting ------------------------------------------------------------------------
    def start(self, job: Job) -> None:
        job.attempts += 1
        self.attempts += 1
        out = self.store.tmp_path(job.job_id, job.attempts)
        log = self.store.log_path(job.job_id)
        a, b = self.opts.stages
        stamp = self.store.fingerprint(job.row)
        request = JobRequest(str(self.run_dir), int(job.index), (a, b), str(out), stamp)
        cmd = request.command()
        env = dict(self.env)
        env[ATTEMPT_ENV] = str(job.attempts)
        limit = self.opts.timeout_s + (self.opts.warmup_extra_s if self.warming else 0.0)
        with _append(log) as fh:
            offset = fh.tell()
            stamp = time.strftime("%Y-%m-%dT%H:%M:%S%z")
            fh.write(
                f"=== woundsweep run: job {job.index} ({job.job_id}) attempt {job.attempts} "
                f"on {self.host} at {stamp}, shard {self.opts.shard}, timeout {limit:.0f} s\n"
                f"=== {' '.join(cmd)}\n".encode()
            )
            fh.flush()
            as_limit = None
            if self.opts.max_memory_bytes is not None:
                as_limit = 2 * self.opts.max_memory_bytes + 2**30
        proc = self.server.spawn(request, env, log, as_limit)
        now = time.time()
        self.running[proc.pid] = Attempt(job, proc, out, offset, now, now + limit)

    # -- polling -------------------------------------------------------------------------
    def poll(self) -> list[tuple[Attempt, int, Any]]:
        """Reap finished attempts; kill those over time or memory. Returns the finished ones."""
        done = []
        now = time.time()
        for pid, att in list(self.running.items()):
            try:
                wpid, status, usage = self.server.wait4(pid)
            except ChildProcessError:
                wpid, status, usage = pid, 0, None
            if wpid == pid:
                att.proc.returncode = status  # reaped here; keep Popen from waiting again
                kill_group(pid)  # strays left in the group
                del self.running[pid]
                done.append((att, status, usage))
                continue
            if att.killed_for:
                continue
            if now > att.deadline:
                att.killed_for = "timeout"
                kill_group(pid)
                continue
            if self.opts.max_memory_bytes is not None:
                rss = tree_rss(pid)
                att.max_rss = max(att.max_rss, rss)
                if rss > self.opts.max_memory_bytes:
                    att.killed_for = "memory"
                    kill_group(pid)
        return done

    # -- claims (two runners of one shard share its jobs) --------------------------------
    def claim(self, job: Job) -> bool | None:
        """True: this runner holds the job's claim; False: another runner does (try later);
        None: another runner stored the job since this one scanned the shard (skip it)."""
        if job.job_id in self.claims:
            return True
        if time.time() < job.next_claim_check:
            return False
        fd = claim(self.store.log_path(job.job_id))
        if fd is None:
            job.next_claim_check = time.time() + 1.0
            return False
        self.claims[job.job_id] = fd
        if mtime_ns(self.store.result_path(job.job_id)) != job.seen_mtime_ns:
            self.unclaim(job)
            return None
        return True

    def unclaim(self, job: Job) -> None:
        fd = self.claims.pop(job.job_id, None)
        if fd is not None:
            release(fd)

    def kill_all(self) -> None:
        for pid, att in list(self.running.items()):
            kill_group(pid)
            self.server.wait(pid)
            att.proc.returncode = -9
            att.out.unlink(missing_ok=True)
        self.running.clear()

    # -- finishing -----------------------------------------------------------------------
    def finish(self, att: Attempt, status: int, usage: Any) -> AttemptOutcome | None:
        """Classify; returns the outcome to store, or None when the job is retried."""
        job = att.job
        if os.WIFEXITED(status) and os.WEXITSTATUS(status) == ExitCode.SWEEP_CHANGED:
            att.out.unlink(missing_ok=True)
            raise StoreError(
                f"{self.store.layout.sweep} changed while this run was in progress (job "
                f"{job.index} refused it; nothing stored for it): rerun `woundsweep run` to go on "
                "with the sweep there now"
            )
        end = time.time()
        wall = end - att.started
        cpu = (usage.ru_utime + usage.ru_stime) if usage is not None else 0.0
        job.total_wall_s += wall
        job.total_cpu_s += cpu
        if usage is not None:
            att.max_rss = max(att.max_rss, usage.ru_maxrss * 1024)  # ru_maxrss is in KiB
        log = self.store.log_path(job.job_id)
        cls = classify(att, status, self.opts.stages, self.opts.max_memory_bytes, log)
        if cls.disk_full:
            att.out.unlink(missing_ok=True)
            raise StoreError(
                f"{self.run_dir}: cannot write the store ({cls.disk_full}): job {job.index} "
                f"stopped, nothing stored for it; free space and rerun (see {log})"
            )
        with _append(log) as fh:
            fh.write(
                f"=== attempt {job.attempts} ended: {cls.failure_class}"
                f"{': ' + cls.detail if cls.detail else ''} ({wall:.1f} s wall, {cpu:.1f} s cpu)\n".encode()
            )
        if self.warming:
            self.warmup_tries += 1
            if (
                cls.failure_class in (FailureClass.CONVERGED, FailureClass.NOT_CONVERGED)
                or self.warmup_tries >= WARMUP_MAX_JOBS
            ):
                self.warming = False
        if cls.failure_class in TRANSIENT_CLASSES and job.attempts <= self.opts.retries:
            att.out.unlink(missing_ok=True)
            job.wait_for_lock = att.extra.get("jit_lock")
            return None
        code = os.WEXITSTATUS(status) if os.WIFEXITED(status) and not att.killed_for else None
        return AttemptOutcome(
            failure_class=cls.failure_class,
            failure_detail=cls.detail,
            exit_code=code,
            attempts=job.attempts,
            wall_time_s=wall,
            cpu_time_s=cpu,
            total_wall_time_s=job.total_wall_s,
            total_cpu_time_s=job.total_cpu_s,
            max_rss_MiB=att.max_rss / 2**20 if att.max_rss else None,
            started_at=att.started,
            finished_at=end,
            output=cls.output,
        )

    def ready(self, job: Job) -> bool:
        """A job retried after a JIT-lock timeout waits until that lock is released or stale."""
        lock = job.wait_for_lock
        if lock is None:
            return True
        if time.time() < job.next_lock_check:
            return False
        job.next_lock_check = time.time() + 2.0  # the check scans /proc: not every poll
        state = lock_state(lock, self.opts.jit_stale_after_s)
        if state == ResultState.STALE:
            break_lock(lock)
        if state != "held":
            job.wait_for_lock = None
            return True
        return False


def _store(store: Store, row: JobRow, outcome: AttemptOutcome, opts: RunOptions) -> None:
    """Write the job; output that validated but cannot be stored makes it ``crashed``."""
    try:
        store.write_job(row, outcome, opts.stages, opts.fields, str(opts.shard))
        return
    except OSError as err:
        if err.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG):
            raise StoreError(f"{store.run_dir}: cannot write the store ({err.strerror})") from None
        detail = f"output could not be stored: {err}"
    except (KeyError, ValueError, TypeError) as err:
        detail = f"output could not be stored: {type(err).__name__}: {err}"
    bad = outcome._replace(
        failure_class=FailureClass.CRASHED, failure_detail=detail[:500], output=None
    )
    store.write_job(row, bad, opts.stages, opts.fields, str(opts.shard))


class Terminated(WoundsweepError):
    """SIGTERM (e.g. a batch system's time limit): running jobs were killed, the store is whole."""

    exit_code = 143


def _on_sigterm(signum: int, frame: FrameType | None) -> None:
    raise Terminated("terminated by SIGTERM: running jobs killed; rerun to resume")


def _run_files(run_dir: Path) -> tuple[tuple[int, int, int] | None, ...]:
    """Identity (inode, size, mtime; None if missing) of the run's sweep and manifest files:
    `generate` replaces them by a rename, so a rewrite changes it."""
    layout = RunLayout(run_dir)
    out: list[tuple[int, int, int] | None] = []
    for path in (layout.sweep, layout.manifest):
        try:
            st = path.stat()
        except FileNotFoundError:
            out.append(None)
        else:
            out.append((st.st_ino, st.st_size, st.st_mtime_ns))
    return tuple(out)


def run_shard(run_dir: str | Path, opts: RunOptions) -> RunSummary:
    """Run every job of ``opts.shard`` that is not already complete in the store.

    The run directory is held (`core.runlock`) for the whole run, so its sweep cannot be
    rewritten meanwhile; each job is claimed before it starts, so runners of one shard share it.
    """
    t0 = time.time()
    seen = _run_files(Path(run_dir))
    run = load_run(run_dir)  # checked before anything is made or locked in the directory
    if opts.shard.count > len(run.manifest):  # before any per-shard state is built
        raise StoreError(
            f"--shard {opts.shard}: more shards than the {len(run.manifest)} jobs of {run_dir}"
        )
    store = Store(run.run_dir)
    store.ensure_dirs()
    lock = hold_run(store.run_dir, exclusive=False)
    try:
        # Every result is stamped with the sweep as it is under the lock: read again only if
        # `generate` rewrote the run before the lock was taken.
        if _run_files(run.run_dir) != seen:
            run = load_run(run.run_dir)
        return _run_held(run, opts, t0)
    finally:
        release(lock)


class _Loop:
    """The runner's loop: starts queued jobs up to the worker limit, stores finished ones."""

    def __init__(self, runner: _Runner, plan: ShardPlan, bar: Any) -> None:
        self.runner = runner
        self.bar = bar
        self.queue: deque[Job] = deque(plan.todo)
        self.skipped = plan.skipped
        self.failed = 0

    def run(self) -> None:
        r = self.runner
        while self.queue or r.running:
            self.start_ready()
            finished = r.poll()
            for att, status, usage in finished:
                self.settle(att, status, usage)
            if not finished:  # else start the next jobs at once
                r.server.wait_any(r.opts.poll_s)

    def start_ready(self) -> None:
        """Start queued jobs up to the limit (one while warming up); a job that waits (on a
        JIT lock or another runner's claim) goes to the back of the queue."""
        r = self.runner
        limit = 1 if r.warming else r.opts.workers
        for _ in range(len(self.queue)):
            if len(r.running) >= limit:
                break
            job = self.queue.popleft()
            claimed = r.claim(job) if r.ready(job) else False
            if claimed:
                r.start(job)
            elif claimed is None:  # stored by another runner of the shard meanwhile
                self.skipped += 1
                self.bar.update(1)
            else:
                self.queue.append(job)

    def settle(self, att: Attempt, status: int, usage: Any) -> None:
        """Store an ended attempt's outcome, or queue its job again for a retry."""
        r = self.runner
        outcome = r.finish(att, status, usage)
        if outcome is None:
            self.queue.append(att.job)
            return
        try:
            _store(r.store, att.job.row, outcome, r.opts)
        finally:
            att.out.unlink(missing_ok=True)
            r.unclaim(att.job)
        r.by_class[outcome.failure_class] = r.by_class.get(outcome.failure_class, 0) + 1
        if outcome.failure_class != FailureClass.CONVERGED:
            self.failed += 1
        self.bar.set_postfix(failed=self.failed, running=len(r.running), refresh=False)
        self.bar.update(1)


def _progress_bar(plan: ShardPlan, opts: RunOptions) -> Any:
    from tqdm import tqdm

    tqdm.monitor_interval = 0  # no monitor thread: the runner forks with preexec_fn
    return tqdm(
        total=plan.jobs,
        initial=plan.skipped,
        unit="job",
        desc=f"shard {opts.shard}",
        disable=None if opts.progress is None else not opts.progress,
        smoothing=0.1,
    )


def _run_held(run: Run, opts: RunOptions, t0: float) -> RunSummary:
    """`run_shard` with the run directory held; ``t0`` its start."""
    store = Store(run.run_dir, run.sweep)
    store.clean_tmp()
    clear_stale_jit_locks(jit_cache_dir(), opts.jit_stale_after_s)
    plan = plan_shard(
        store,
        run.manifest,
        opts.shard,
        stages=opts.stages,
        rerun_failed=opts.rerun_failed,
        warmup=opts.warmup,
    )
    runner = _Runner(store, opts)
    loop = _Loop(runner, plan, _progress_bar(plan, opts))
    old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        loop.run()
    except BaseException:
        runner.kill_all()
        raise
    finally:
        signal.signal(signal.SIGTERM, old_term)
        runner.server.close()
        loop.bar.close()
        for fd in runner.claims.values():
            release(fd)
    return RunSummary(
        jobs=plan.jobs,
        skipped=loop.skipped,
        ran=sum(runner.by_class.values()),
        by_class=runner.by_class,
        attempts=runner.attempts,
        wall_time_s=time.time() - t0,
    )

"""`woundsweep run`: every job in its own subprocess, with a timeout, a memory cap and retries.

One runner process drives a shard. It keeps up to K jobs running, each as
``python -m woundsweep solve RUN_DIR --job N --stages A-B --out TMP.h5`` in a new session
(its own process group), and polls them from a single thread (no threads: ``preexec_fn`` is
only safe without them). A job is killed with its whole process group when it exceeds the
wall-clock timeout or the memory cap. The cap is enforced two ways: the resident set of the
job's process tree is polled and the group killed above ``--max-memory`` (so the runner knows
it was memory and says so); ``RLIMIT_AS`` is set at twice the cap plus 1 GiB as a backstop
against allocations faster than the poll (address space runs well above RSS: importing
DOLFINx alone maps ~0.5 GB). Children get ``PR_SET_PDEATHSIG`` = SIGKILL, so a runner killed
with ``kill -9`` takes its jobs with it.

Failure classes (see ``store.FAILURE_CLASSES``), from the solver's exit status (0 converged,
3 a stage not converged, 2 invalid input, 4 mesh failed) and what the runner saw: killed for
time -> ``timeout``; killed for memory, or a ``MemoryError``/``bad_alloc`` in the log when a cap
is set -> ``out-of-memory``; a signal, any other exit status, or exit 0/3 without a valid
output file -> ``crashed``. Only ``timeout`` and ``crashed`` are retried (``--retries``).

Warm-up: FFCx compiles each form once per machine (~50 s for the Fung Jacobian) and processes
that need a form being compiled wait on its lock for only 10 s. So the runner starts with one
job alone (the cheapest of the shard) and fans out to K workers once a job has been through
the solver (converged or not), or after three tries. Jobs started while the cache may still
be cold get ``warmup_extra_s`` more time.

FFCx 0.5 JIT locks: ``get_cached_module`` creates ``<cache_dir>/libffcx_{forms,elements,
expressions}_<hash>.c`` with O_EXCL as the lock and writes ``<same>.c.cached`` when done;
others poll for ``.c.cached`` once a second for ``timeout`` (10) seconds, then raise
``TimeoutError("JIT compilation timed out ... remove <file>.c")``. A compile killed mid-way
leaves the ``.c`` without ``.c.cached`` forever. The cache dir is ``$XDG_CACHE_HOME/fenics``
(default ``~/.cache/fenics``) unless the solver passes ``cache_dir``. The runner (1) renames
stale locks (older than ``--jit-stale-after`` and not being compiled by a process on this
host) at start, and (2) when a job crashes on that TimeoutError, takes the lock path from the
message and retries the job only after that lock is released, or removes it once stale.
"""

from __future__ import annotations

import ctypes
import errno
import math
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import pandas as pd

from .errors import StoreError, WoundsweepError
from .faults import ATTEMPT_ENV
from .grid import load_run
from .shards import Shard, estimate_cost, shard_jobs
from .store import (
    TRANSIENT_CLASSES,
    JobOutcome,
    SolverOutput,
    Store,
    read_solver_output,
)

__all__ = [
    "RunOptions",
    "RunSummary",
    "Terminated",
    "clear_stale_jit_locks",
    "jit_cache_dir",
    "pending_jit_locks",
    "run_shard",
    "stability_note",
]

EXIT_CONVERGED, EXIT_INVALID, EXIT_NOT_CONVERGED, EXIT_MESH_FAILED = 0, 2, 3, 4
WARMUP_MAX_JOBS = 3
_PR_SET_PDEATHSIG = 1
_PAGE = os.sysconf("SC_PAGE_SIZE")
_JIT_TIMEOUT_RE = re.compile(r"JIT compilation timed out.*?remove (\S+\.c)\)", re.S)
_OOM_RE = re.compile(r"MemoryError|std::bad_alloc|Out of memory|Cannot allocate memory")
_LIBC = ctypes.CDLL(None, use_errno=True)  # resolved now, not in the forked child


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


@dataclass
class _Job:
    row: dict[str, Any]
    attempts: int = 0
    total_wall_s: float = 0.0
    total_cpu_s: float = 0.0
    wait_for_lock: Path | None = None
    next_lock_check: float = 0.0

    @property
    def index(self) -> int:
        return int(self.row["job_index"])

    @property
    def job_id(self) -> str:
        return str(self.row["job_id"])


@dataclass
class _Attempt:
    job: _Job
    proc: subprocess.Popen[bytes]
    out: Path
    log_offset: int
    started: float
    deadline: float
    killed_for: str = ""
    max_rss: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


# ---- FFCx JIT cache locks ---------------------------------------------------------------
def jit_cache_dir() -> Path:
    """Where DOLFINx 0.5 puts its FFCx JIT cache by default."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fenics"


def pending_jit_locks(cache_dir: Path) -> list[Path]:
    """FFCx lock files (``libffcx_*.c``) whose module has no ``.c.cached`` marker yet."""
    if not cache_dir.is_dir():
        return []
    return sorted(
        p for p in cache_dir.glob("libffcx_*.c") if not p.with_suffix(".c.cached").exists()
    )


_SHARED_FS = (
    "nfs",
    "lustre",
    "gpfs",
    "beegfs",
    "cifs",
    "smb",
    "ceph",
    "gluster",
    "panfs",
    "sshfs",
    "9p",
)


def _is_local_fs(path: Path) -> bool:
    """Is ``path`` on a filesystem no other host can write (per /proc/self/mountinfo)?"""
    target = str(path.resolve())
    best, fstype = "", ""
    try:
        with open("/proc/self/mountinfo") as fh:
            for line in fh:
                left, _, right = line.partition(" - ")
                mnt = left.split()[4]
                if (target == mnt or target.startswith(mnt.rstrip("/") + "/")) and len(mnt) >= len(
                    best
                ):
                    best, fstype = mnt, right.split()[0]
    except (OSError, IndexError):
        return False
    return bool(fstype) and not any(t in fstype for t in _SHARED_FS)


def _compiling_here(lock: Path, any_dolfinx: bool = False) -> bool:
    """Could a process on this host be compiling the module of ``lock``?

    A C compiler whose command line names the module, or (``any_dolfinx``) any process with
    DOLFINx loaded: FFCx generates code in the Python process before the compiler runs.
    """
    stem = lock.stem.encode()
    me = os.getpid()
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == me:
            continue
        try:
            if stem in (d / "cmdline").read_bytes():
                return True
            if any_dolfinx and b"libdolfinx" in (d / "maps").read_bytes():
                return True
        except OSError:
            continue
    return False


def _lock_state(lock: Path, stale_after_s: float) -> str:
    """``released`` (done or gone), ``stale`` or ``held``.

    Stale: older than ``stale_after_s`` with no compiler on this host working on it; or, on a
    local filesystem, with no process on this host that has DOLFINx loaded at all.
    """
    if lock.with_suffix(".c.cached").exists():
        return "released"
    try:
        age = time.time() - lock.stat().st_mtime
    except FileNotFoundError:
        return "released"
    if age > stale_after_s and not _compiling_here(lock):
        return "stale"
    if _is_local_fs(lock.parent) and not _compiling_here(lock, any_dolfinx=True):
        return "stale"
    return "held"


def _break_lock(lock: Path) -> bool:
    # FFCx itself renames a failed compile's lock to .c.failed; do the same, so the next
    # process's O_EXCL open succeeds and compiles afresh.
    try:
        os.replace(lock, lock.with_suffix(f".c.stale-{int(time.time())}"))
        return True
    except FileNotFoundError:
        return False


def clear_stale_jit_locks(cache_dir: Path, stale_after_s: float) -> list[Path]:
    """Rename every stale FFCx lock in ``cache_dir``; returns the ones removed."""
    return [
        p
        for p in pending_jit_locks(cache_dir)
        if _lock_state(p, stale_after_s) == "stale" and _break_lock(p)
    ]


# ---- one subprocess ---------------------------------------------------------------------
def _preexec(as_limit: int | None) -> Any:
    def fn() -> None:
        if as_limit is not None:
            resource.setrlimit(resource.RLIMIT_AS, (as_limit, as_limit))
        _LIBC.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)

    return fn


def _tree_rss(pid: int) -> int:
    """Resident bytes of ``pid`` and its descendants (via /proc/PID/task/*/children)."""
    total, stack, seen = 0, [pid], set()
    while stack:
        p = stack.pop()
        if p in seen:
            continue
        seen.add(p)
        try:
            with open(f"/proc/{p}/statm") as fh:
                total += int(fh.read().split()[1]) * _PAGE
            for t in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{t}/children") as fh:
                    stack.extend(int(c) for c in fh.read().split())
        except (OSError, ValueError, IndexError):
            continue
    return total


def _kill_group(pid: int) -> None:
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _log_tail(path: Path, offset: int, limit: int = 65536) -> str:
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            end = fh.tell()
            fh.seek(max(offset, end - limit))
            return fh.read().decode(errors="replace")
    except OSError:
        return ""


def _signal_name(num: int) -> str:
    try:
        return signal.Signals(num).name
    except ValueError:
        return f"signal {num}"


def stability_note(stage: Mapping[str, Any]) -> str:
    """'; last converged state stable|unstable (...)' from a failed stage's stability extras
    (stages.py: the lowest eigenvalue nearest zero of its tangent), or '' without them."""
    eig, k_V = stage.get("stability_min_eig_mN_per_mm"), stage.get("stability_penalty_kPa")
    if eig is None or not math.isfinite(float(eig)):
        return ""
    kind = "unstable" if float(eig) < 0.0 else "stable"
    at = f" at k_V = {float(k_V):.3g} kPa" if k_V is not None else ""
    return f"; last converged state {kind} (lowest eigenvalue {float(eig):.3g} mN/mm{at})"


class _Classified(NamedTuple):
    failure_class: str
    detail: str
    output: SolverOutput | None


def _classify(att: _Attempt, status: int, opts: RunOptions, log: Path) -> _Classified:
    """Turn an ended attempt into a failure class (module docstring has the rules)."""
    job = att.job
    if att.killed_for == "timeout":
        limit = att.deadline - att.started
        return _Classified("timeout", f"killed after {limit:.0f} s wall-clock limit", None)
    if att.killed_for == "memory":
        cap = (opts.max_memory_bytes or 0) / 2**20
        return _Classified(
            "out-of-memory",
            f"killed: resident memory {att.max_rss / 2**20:.0f} MiB above the {cap:.0f} MiB cap",
            None,
        )
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        return _Classified("crashed", f"killed by {_signal_name(sig)}", None)
    code = os.WEXITSTATUS(status)
    tail = _log_tail(log, att.log_offset)
    if code in (EXIT_CONVERGED, EXIT_NOT_CONVERGED):
        if not att.out.exists():
            return _Classified("crashed", f"exit {code} but no output file", None)
        try:
            out = read_solver_output(att.out, job.job_id, opts.stages)
        except StoreError as err:
            return _Classified("crashed", f"exit {code} without a valid output: {err}", None)
        missing = [k for k in range(opts.stages[0], opts.stages[1] + 1) if k not in out.stages]
        bad = [k for k in sorted(out.stages) if out.stages[k].get("status") != "converged"]
        if code == EXIT_CONVERGED and missing:
            return _Classified("crashed", f"exit 0 but no result for stages {missing}", None)
        if bad or code == EXIT_NOT_CONVERGED:
            what = "exit 3"
            if bad:
                first = out.stages[bad[0]]
                what = f"stage {bad[0]} {first['status']}{stability_note(first)}"
            return _Classified("not-converged", what, out)
        return _Classified("converged", "", out)
    last = next((ln for ln in reversed(tail.strip().splitlines()) if ln.strip()), "")[:300]
    if code == EXIT_INVALID:
        return _Classified("invalid", f"exit 2: {last}", None)
    if code == EXIT_MESH_FAILED:
        return _Classified("mesh-failed", f"exit 4: {last}", None)
    if opts.max_memory_bytes is not None and _OOM_RE.search(tail):
        return _Classified(
            "out-of-memory", f"exit {code}: allocation failed under the cap: {last}", None
        )
    m = _JIT_TIMEOUT_RE.search(tail)
    if m:
        att.extra["jit_lock"] = Path(m.group(1))
    return _Classified("crashed", f"exit {code}: {last}", None)


class _Runner:
    def __init__(self, run_dir: Path, opts: RunOptions) -> None:
        self.run_dir = run_dir
        self.opts = opts
        self.store = Store(run_dir)
        self.running: dict[int, _Attempt] = {}
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

    # -- starting ------------------------------------------------------------------------
    def start(self, job: _Job) -> None:
        job.attempts += 1
        self.attempts += 1
        out = self.store.tmp_path(job.job_id, job.attempts)
        log = self.store.log_path(job.job_id)
        a, b = self.opts.stages
        cmd = [
            sys.executable, "-m", "woundsweep", "solve", str(self.run_dir),
            "--job", str(job.index), "--stages", f"{a}-{b}", "--out", str(out),
        ]  # fmt: skip
        env = dict(self.env)
        env[ATTEMPT_ENV] = str(job.attempts)
        limit = self.opts.timeout_s + (self.opts.warmup_extra_s if self.warming else 0.0)
        with open(log, "ab") as fh:
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
            proc = subprocess.Popen(
                cmd,
                stdin=subprocess.DEVNULL,
                stdout=fh,
                stderr=subprocess.STDOUT,
                env=env,
                start_new_session=True,
                preexec_fn=_preexec(as_limit),
                close_fds=True,
            )
        now = time.time()
        self.running[proc.pid] = _Attempt(job, proc, out, offset, now, now + limit)

    # -- polling -------------------------------------------------------------------------
    def poll(self) -> list[tuple[_Attempt, int, Any]]:
        """Reap finished attempts; kill those over time or memory. Returns the finished ones."""
        done = []
        now = time.time()
        for pid, att in list(self.running.items()):
            try:
                wpid, status, usage = os.wait4(pid, os.WNOHANG)
            except ChildProcessError:
                wpid, status, usage = pid, 0, None
            if wpid == pid:
                att.proc.returncode = status  # reaped here; keep Popen from waiting again
                _kill_group(pid)  # strays left in the group
                del self.running[pid]
                done.append((att, status, usage))
                continue
            if att.killed_for:
                continue
            if now > att.deadline:
                att.killed_for = "timeout"
                _kill_group(pid)
                continue
            if self.opts.max_memory_bytes is not None:
                rss = _tree_rss(pid)
                att.max_rss = max(att.max_rss, rss)
                if rss > self.opts.max_memory_bytes:
                    att.killed_for = "memory"
                    _kill_group(pid)
        return done

    def kill_all(self) -> None:
        for pid, att in list(self.running.items()):
            _kill_group(pid)
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:
                pass
            att.proc.returncode = -9
            att.out.unlink(missing_ok=True)
        self.running.clear()

    # -- finishing -----------------------------------------------------------------------
    def finish(self, att: _Attempt, status: int, usage: Any) -> JobOutcome | None:
        """Classify; returns the outcome to store, or None when the job is retried."""
        job = att.job
        end = time.time()
        wall = end - att.started
        cpu = (usage.ru_utime + usage.ru_stime) if usage is not None else 0.0
        job.total_wall_s += wall
        job.total_cpu_s += cpu
        if usage is not None:
            att.max_rss = max(att.max_rss, usage.ru_maxrss * 1024)  # ru_maxrss is in KiB
        cls = _classify(att, status, self.opts, self.store.log_path(job.job_id))
        with open(self.store.log_path(job.job_id), "ab") as fh:
            fh.write(
                f"=== attempt {job.attempts} ended: {cls.failure_class}"
                f"{': ' + cls.detail if cls.detail else ''} ({wall:.1f} s wall, {cpu:.1f} s cpu)\n".encode()
            )
        if self.warming:
            self.warmup_tries += 1
            if (
                cls.failure_class in ("converged", "not-converged")
                or self.warmup_tries >= WARMUP_MAX_JOBS
            ):
                self.warming = False
        if cls.failure_class in TRANSIENT_CLASSES and job.attempts <= self.opts.retries:
            att.out.unlink(missing_ok=True)
            job.wait_for_lock = att.extra.get("jit_lock")
            return None
        code = os.WEXITSTATUS(status) if os.WIFEXITED(status) and not att.killed_for else None
        return JobOutcome(
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

    def ready(self, job: _Job) -> bool:
        """A job retried after a JIT-lock timeout waits until that lock is released or stale."""
        lock = job.wait_for_lock
        if lock is None:
            return True
        if time.time() < job.next_lock_check:
            return False
        job.next_lock_check = time.time() + 2.0  # the check scans /proc: not every poll
        state = _lock_state(lock, self.opts.jit_stale_after_s)
        if state == "stale":
            _break_lock(lock)
        if state != "held":
            job.wait_for_lock = None
            return True
        return False


def _store(store: Store, row: dict[str, Any], outcome: JobOutcome, opts: RunOptions) -> None:
    """Write the job; output that validated but cannot be stored makes it ``crashed``."""
    try:
        store.write_job(row, outcome, opts.stages, opts.fields, str(opts.shard))
        return
    except OSError as err:
        if err.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS):
            raise StoreError(f"{store.run_dir}: cannot write the store ({err.strerror})") from None
        detail = f"output could not be stored: {err}"
    except (KeyError, ValueError, TypeError) as err:
        detail = f"output could not be stored: {type(err).__name__}: {err}"
    bad = outcome._replace(failure_class="crashed", failure_detail=detail[:500], output=None)
    store.write_job(row, bad, opts.stages, opts.fields, str(opts.shard))


def _order(jobs: pd.DataFrame, warmup: bool) -> list[dict[str, Any]]:
    """Manifest order, except that the cheapest job goes first to warm the JIT cache."""
    rows = jobs.to_dict("records")
    if warmup and rows:
        cost = estimate_cost(jobs)
        first = int(cost.argmin())
        rows.insert(0, rows.pop(first))
    return rows


class Terminated(WoundsweepError):
    """SIGTERM (e.g. a batch system's time limit): running jobs were killed, the store is whole."""

    exit_code = 143


def _on_sigterm(signum: int, frame: Any) -> None:
    raise Terminated("terminated by SIGTERM: running jobs killed; rerun to resume")


def run_shard(run_dir: str | Path, opts: RunOptions) -> RunSummary:
    """Run every job of ``opts.shard`` that is not already complete in the store."""
    from tqdm import tqdm

    t0 = time.time()
    run = load_run(run_dir)
    run_dir = run.run_dir
    store = Store(run_dir)
    store.ensure_dirs()
    store.clean_tmp()
    clear_stale_jit_locks(jit_cache_dir(), opts.jit_stale_after_s)
    shard = shard_jobs(run.manifest, opts.shard)
    todo, skipped = [], 0
    for row in _order(shard, opts.warmup):
        st = store.job_state(str(row["job_id"]), opts.stages)
        if st.state == "corrupt":
            moved = store.quarantine(str(row["job_id"]))
            print(f"woundsweep run: {st.reason}; moved to {moved}, rerunning", file=sys.stderr)
        elif st.state == "done" and not (opts.rerun_failed and st.failure_class != "converged"):
            skipped += 1
            continue
        todo.append(_Job(row))

    runner = _Runner(run_dir, opts)
    queue: deque[_Job] = deque(todo)
    failed = 0
    tqdm.monitor_interval = 0  # no monitor thread: the runner forks with preexec_fn
    bar = tqdm(
        total=len(shard),
        initial=skipped,
        unit="job",
        desc=f"shard {opts.shard}",
        disable=None if opts.progress is None else not opts.progress,
        smoothing=0.1,
    )
    old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        while queue or runner.running:
            limit = 1 if runner.warming else opts.workers
            for _ in range(len(queue)):
                if len(runner.running) >= limit:
                    break
                job = queue.popleft()
                if runner.ready(job):
                    runner.start(job)
                else:
                    queue.append(job)
            for att, status, usage in runner.poll():
                outcome = runner.finish(att, status, usage)
                if outcome is None:
                    queue.append(att.job)
                    continue
                try:
                    _store(store, att.job.row, outcome, opts)
                finally:
                    att.out.unlink(missing_ok=True)
                runner.by_class[outcome.failure_class] = (
                    runner.by_class.get(outcome.failure_class, 0) + 1
                )
                if outcome.failure_class != "converged":
                    failed += 1
                bar.set_postfix(failed=failed, running=len(runner.running), refresh=False)
                bar.update(1)
            time.sleep(opts.poll_s)
    except BaseException:
        runner.kill_all()
        raise
    finally:
        signal.signal(signal.SIGTERM, old_term)
        bar.close()
    return RunSummary(
        jobs=len(shard),
        skipped=skipped,
        ran=sum(runner.by_class.values()),
        by_class=runner.by_class,
        attempts=runner.attempts,
        wall_time_s=time.time() - t0,
    )

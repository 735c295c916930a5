"""Child process control for the runner: one job attempt per process group.

A job runs in a new session (its own process group) so that it is killed with everything it
started. `preexec` sets, in the child, ``RLIMIT_AS`` (a backstop to the runner's resident
memory poll, `tree_rss`, against allocations faster than the poll) and
``PR_SET_PDEATHSIG`` = SIGKILL, so a runner killed with ``kill -9`` takes its fork server
with it, and the fork server its jobs (`woundsweep.execution.forkserver` forks them).
"""

from __future__ import annotations

import ctypes
import os
import resource
import signal
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.fsutil import open_regular

if TYPE_CHECKING:
    from ..config.manifest import JobRow

__all__ = [
    "JOB_NAME",
    "SERVER_NAME",
    "Attempt",
    "Child",
    "Job",
    "kill_group",
    "log_tail",
    "preexec",
    "set_process_name",
    "signal_name",
    "tree_rss",
]

# /proc/PID/comm of the fork server (`woundsweep.execution.forkserver`) and of the job processes
# it forks: what ps shows, and how `jitlock` tells the server, which never compiles, apart.
SERVER_NAME = "ws-forkserver"
JOB_NAME = "ws-job"
_PR_SET_PDEATHSIG = 1
_PR_SET_NAME = 15
_PAGE = os.sysconf("SC_PAGE_SIZE")
_LIBC = ctypes.CDLL(None, use_errno=True)  # resolved now, not in the forked child


@dataclass
class Job:
    """A job of the shard and what its attempts so far have cost."""

    row: JobRow
    attempts: int = 0
    total_wall_s: float = 0.0
    total_cpu_s: float = 0.0
    wait_for_lock: Path | None = None
    next_lock_check: float = 0.0
    seen_mtime_ns: int | None = None  # its result file's when the shard was scanned (or none)
    next_claim_check: float = 0.0

    @property
    def index(self) -> int:
        return int(self.row["job_index"])

    @property
    def job_id(self) -> str:
        return str(self.row["job_id"])


@dataclass
class Child:
    """A job attempt's process (the leader of its group) and, once reaped, its wait status."""

    pid: int
    returncode: int | None = None


@dataclass
class Attempt:
    """One running (or just ended) attempt of a job: its process and what the runner saw."""

    job: Job
    proc: Child
    out: Path
    log_offset: int
    started: float
    deadline: float
    killed_for: str = ""
    max_rss: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


def preexec(as_limit: int | None) -> Callable[[], None]:
    """The child's ``preexec_fn``: address-space limit (if any) and death signal."""

    def fn() -> None:
        if as_limit is not None:
            resource.setrlimit(resource.RLIMIT_AS, (as_limit, as_limit))
        _LIBC.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)

    return fn


def set_process_name(name: str) -> None:
    """Set this process's ``/proc/PID/comm`` (what ps and top show; at most 15 bytes)."""
    _LIBC.prctl(_PR_SET_NAME, ctypes.c_char_p(name.encode()[:15]), 0, 0, 0)


def tree_rss(pid: int) -> int:
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


def kill_group(pid: int) -> None:
    """SIGKILL the process group ``pid`` leads (nothing if it is gone)."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def log_tail(path: Path, offset: int, limit: int = 65536) -> str:
    """The log from ``offset`` (an attempt's start) on, at most its last ``limit`` bytes."""
    try:
        with os.fdopen(open_regular(path), "rb") as fh:  # a named pipe cannot hang the runner
            fh.seek(0, os.SEEK_END)
            end = fh.tell()
            fh.seek(max(offset, end - limit))
            return fh.read().decode(errors="replace")
    except OSError:
        return ""


def signal_name(num: int) -> str:
    """``SIGSEGV`` for 11, ``signal N`` for a number without a name."""
    try:
        return signal.Signals(num).name
    except ValueError:
        return f"signal {num}"

"""Locks on a run directory that die with their holder (``flock``).

``RUN_DIR/run.lock``: every `woundsweep run` holds it shared for its whole life; `generate`
takes it exclusive before it rewrites the run's sweep and manifest, so it is refused while a
run is in progress, and a run does not start while a generate writes. A job's claim is an
exclusive lock on its log file, held by the runner from the job's first attempt until its
result is stored: two runners of one shard each run the jobs the other has not claimed. The
kernel releases a lock when its holder dies (kill -9 included), so nothing stale is left.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from .errors import StoreError
from .fsutil import NotRegularFile, open_regular
from .layout import RunLayout

__all__ = ["claim", "hold_run", "release"]


def _lock(path: Path, mode: int, create: bool) -> int | None:
    """An open descriptor of ``path`` locked with ``mode`` (non-blocking), or None if another
    process holds a conflicting lock (or, without ``create``, the file does not exist).
    StoreError when ``path`` is not a regular file (a link, a named pipe: `open_regular`)."""
    flags = os.O_RDWR | (os.O_CREAT if create else 0)
    try:
        fd = open_regular(path, flags, 0o644)
    except FileNotFoundError:
        if create:
            raise
        return None
    except NotRegularFile as err:
        raise StoreError(f"{path}: {err.strerror} (move it away)") from None
    try:
        fcntl.flock(fd, mode | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def hold_run(run_dir: Path, *, exclusive: bool) -> int:
    """Lock ``RUN_DIR/run.lock`` (shared for a runner, exclusive for a rewrite of the run);
    returns the descriptor to `release`. StoreError when the other kind holds it."""
    mode = fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH
    fd = _lock(RunLayout(run_dir).lock, mode, create=True)
    if fd is None:
        what = "a `woundsweep run` is in progress" if exclusive else "`generate` is rewriting it"
        raise StoreError(f"{run_dir}: {what} (try again when it has finished)")
    return fd


def claim(path: Path) -> int | None:
    """An exclusive claim on ``path`` (created if missing), or None if another process holds
    it; the descriptor goes to `release`."""
    return _lock(path, fcntl.LOCK_EX, create=True)


def release(fd: int) -> None:
    """Release a lock from `hold_run` or `claim`."""
    os.close(fd)

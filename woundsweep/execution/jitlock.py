"""FFCx JIT cache locks: finding stale ones and waiting on held ones.

FFCx 0.5's ``get_cached_module`` creates ``<cache_dir>/libffcx_{forms,elements,expressions}_
<hash>.c`` with O_EXCL as the lock and writes ``<same>.c.cached`` when done; other processes
poll for ``.c.cached`` once a second for ``timeout`` (10) seconds, then raise
``TimeoutError("JIT compilation timed out ... remove <file>.c")``. A compile killed mid-way
leaves the ``.c`` without ``.c.cached`` forever. The cache dir is ``$XDG_CACHE_HOME/fenics``
(default ``~/.cache/fenics``) unless the solver passes ``cache_dir``.

The runner (1) renames stale locks at start (`clear_stale_jit_locks`), and (2) when a job
crashes on that TimeoutError (`JIT_TIMEOUT_RE` finds the lock in its log), retries it only
once `lock_state` says the lock is released, breaking it once stale.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

from .process import SERVER_NAME

__all__ = [
    "JIT_TIMEOUT_RE",
    "break_lock",
    "clear_stale_jit_locks",
    "jit_cache_dir",
    "lock_state",
    "may_compile",
    "pending_jit_locks",
]

JIT_TIMEOUT_RE = re.compile(r"JIT compilation timed out.*?remove (\S+\.c)\)", re.S)

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


def may_compile(proc: Path, stem: bytes, any_dolfinx: bool) -> bool:
    """Could process ``proc`` (its /proc directory) be compiling the module ``stem``?

    A C compiler whose command line names the module, or (``any_dolfinx``) any process with
    DOLFINx loaded: FFCx generates code in the Python process before the compiler runs. A
    runner's fork server has DOLFINx loaded but never compiles, so it does not count.
    """
    try:
        if stem in (proc / "cmdline").read_bytes():
            return True
        return (
            any_dolfinx
            and (proc / "comm").read_text().strip() != SERVER_NAME
            and b"libdolfinx" in (proc / "maps").read_bytes()
        )
    except OSError:
        return False


def _compiling_here(lock: Path, any_dolfinx: bool = False) -> bool:
    """Could a process on this host be compiling the module of ``lock`` (`may_compile`)?"""
    me = str(os.getpid())
    return any(
        may_compile(d, lock.stem.encode(), any_dolfinx)
        for d in Path("/proc").iterdir()
        if d.name.isdigit() and d.name != me
    )


def lock_state(lock: Path, stale_after_s: float) -> str:
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


def break_lock(lock: Path) -> bool:
    """Rename a stale lock aside; False if it is gone already.

    FFCx itself renames a failed compile's lock to ``.c.failed``; this does the same, so the
    next process's O_EXCL open succeeds and compiles afresh.
    """
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
        if lock_state(p, stale_after_s) == "stale" and break_lock(p)
    ]

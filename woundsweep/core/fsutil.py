"""Atomic file writes (readers see the old file or the complete new one, never a partial one)
and bounded reads of small input text files."""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

__all__ = [
    "NotRegularFile",
    "atomic_write",
    "atomic_write_bytes",
    "check_output_dir",
    "check_output_file",
    "open_regular",
    "read_small_text",
    "read_tail",
]


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write(path: str | Path, write: Callable[[str], object]) -> None:
    """Call ``write(tmp_path)`` (its return value is ignored), fsync the result, then ``os.replace`` it onto ``path``.

    The temporary file sits in the same directory (same filesystem, so the rename is atomic)
    and starts with a dot, so dataset readers such as pyarrow ignore it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are meant to be shared
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(err, OSError) and not err.filename and err.errno:
            # a write that failed (a full disk, past `ulimit -f`) names the file it was for
            raise OSError(err.errno, err.strerror or str(err), str(path)) from None
        raise
    try:  # make the rename itself durable
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Atomically write ``data`` to ``path``."""

    def _write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)

    atomic_write(path, _write)


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


class NotRegularFile(OSError):
    """A path where a regular file is expected holds something else (a named pipe, a device,
    a directory, a symbolic link): ``filename`` names it, ``strerror`` says what it is."""


def open_regular(path: str | Path, flags: int = os.O_RDONLY, mode: int = 0o644) -> int:
    """A descriptor of ``path`` opened as a regular file (``flags`` as for `os.open`).

    The open neither follows a symbolic link in the last component (``O_NOFOLLOW``: a link
    inside a run directory cannot lead a write or a read outside it) nor blocks (a named pipe
    without a writer cannot hang the caller); the descriptor is checked with ``fstat`` and is
    blocking again when returned. `NotRegularFile` (an `OSError` naming the path) otherwise;
    other `OSError`s (a missing file, say) as `os.open` raises them.
    """
    nonblock = os.O_NONBLOCK | os.O_NOFOLLOW | os.O_CLOEXEC | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(path, flags | nonblock, mode)
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise NotRegularFile(
                errno.ELOOP, "a symbolic link, not a regular file", str(path)
            ) from None
        if err.errno in (errno.ENXIO, errno.EISDIR):  # a FIFO without reader; a directory
            what = "a directory" if err.errno == errno.EISDIR else "a named pipe"
            raise NotRegularFile(err.errno, f"{what}, not a regular file", str(path)) from None
        raise
    st_mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(st_mode):
        os.close(fd)
        raise NotRegularFile(errno.EINVAL, f"{_kind(st_mode)}, not a regular file", str(path))
    os.set_blocking(fd, True)
    return fd


def read_tail(path: str | Path, limit: int) -> tuple[int, bytes]:
    """The size of the regular file ``path`` and its last ``limit`` bytes (`open_regular`)."""
    with os.fdopen(open_regular(path), "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size > limit:
            fh.seek(size - limit)
        return size, fh.read(limit)


def read_small_text(path: str | Path, max_bytes: int, expected: str = "a text file") -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes``; ``ValueError`` otherwise.

    The file is opened without blocking (a named pipe with no writer cannot hang the caller)
    and checked with ``fstat`` before anything is read; at most ``max_bytes + 1`` bytes are
    read. Binary data (NUL bytes), UTF-16/32 and invalid UTF-8 are refused. The message of
    the ``ValueError`` is one line naming the problem (the caller adds the file name).
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except OSError as err:
        raise ValueError(f"cannot read file ({err.strerror})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise ValueError(f"{_kind(mode)}, not {expected}")
        with os.fdopen(os.dup(fd), "rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as err:
        if err.errno == errno.EISDIR:
            raise ValueError(f"a directory, not {expected}") from None
        raise ValueError(f"cannot read file ({err.strerror})") from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise ValueError(f"larger than {max_bytes} bytes, not {expected}")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise ValueError(f"UTF-16/32 encoded; expected {expected} in UTF-8")
    if b"\0" in data:
        raise ValueError(f"binary data (NUL bytes), not {expected}")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise ValueError(f"not UTF-8 (byte {err.start}); expected {expected} in UTF-8") from None


def check_output_file(path: str | Path) -> None:
    """``ValueError`` (one line) unless ``path`` can be written as a file: it is not a
    directory, and its nearest existing ancestor is a writable directory (missing parents are
    created by the writer). Checked before long work, so it fails at once, not at the end."""
    p = Path(os.path.abspath(path))
    if p.is_dir():
        raise ValueError(f"{p}: is a directory, not a file")
    parent = p.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{p}: {parent} is not a directory")
    try:  # a real write: permission bits do not show a read-only mount, /proc, or root
        with tempfile.TemporaryFile(prefix=".woundsweep-check.", dir=parent):
            pass
    except OSError as err:
        raise ValueError(f"{p}: cannot write in {parent} ({err.strerror})") from None


def check_output_dir(path: str | Path) -> None:
    """``ValueError`` (one line) unless ``path`` can be an output directory: it is one, or
    it is missing (it is created, with its missing parents) below a writable directory; a
    path or parent that is a file is named."""
    p = Path(os.path.abspath(path))
    if p.exists() and not p.is_dir():
        raise ValueError(f"{p}: is a file, not a directory")
    parent = p
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{p}: {parent} is not a directory")
    try:
        with tempfile.TemporaryFile(prefix=".woundsweep-check.", dir=parent):
            pass
    except OSError as err:
        raise ValueError(f"{p}: cannot write in {parent} ({err.strerror})") from None

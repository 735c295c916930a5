"""The read cache of a run's store, and the compact joining of result rows.

``RUN_DIR/.read-cache.wsc`` (a dot name beside ``results/``, which stays the store's
alone) holds the rows and footer record of every result file a
reader has checked in full (`reader.read_checked`), each under the file's name and
`reader.cache_key` (size, mtime_ns, ctime_ns, inode, from the ``fstat`` of the very file
read). A later reader takes a file's rows from the cache while its `os.stat` gives the same
key, and reads and checks it again otherwise; files no longer in ``results/`` drop out. The
fields and mesh files, the fingerprint and the manifest are checked on every read as without
the cache. What the cache trusts: a file whose bytes change while its size, times and inode
stay (damage below the filesystem) is not checked again; ``trust=False`` (``status
--verify``) reads every file and writes the cache anew.

The file: a magic line, the sha256 of the rest, the length and JSON of the index (result
format, one ``[name, key, rows, footer record]`` per file) and a Parquet table of the rows
in the index's order. A cache that is unreadable, damaged or of another format or result
format is ignored (and replaced), never an error. It is written with
`fsutil.atomic_write_bytes`, so racing readers and writers see one whole cache or another.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any, NamedTuple

import pyarrow as pa
import pyarrow.parquet as pq

from ..core.fsutil import atomic_write_bytes, open_regular
from ..core.layout import RESULT_NAME
from ..core.versions import RESULT_FORMAT_VERSION
from .reader import read_checked, result_schema

__all__ = ["MAX_CACHE_BYTES", "READ_CACHE_NAME", "ReadCache", "Rows"]

READ_CACHE_NAME = ".read-cache.wsc"

_MAGIC = b"woundsweep read cache 1\n"
_SCHEMA = result_schema()
# Far above the whole paper grid's cache (tens of MB); a larger file is not read.
MAX_CACHE_BYTES = 1 << 31
# A result file's own table carries buffers far larger than its few rows: joined every
# this many files into one compact table, so the reader never holds thousands of them.
_BATCH = 256


class Rows:
    """Result tables appended in order and joined into compact tables in batches."""

    def __init__(self) -> None:
        self._joined: list[pa.Table] = []
        self._pending: list[pa.Table] = []

    def append(self, table: pa.Table) -> None:
        self._pending.append(table)
        if len(self._pending) >= _BATCH:
            self._join()

    def _join(self) -> None:
        if self._pending:
            self._joined.append(pa.concat_tables(self._pending).combine_chunks())
            self._pending = []

    def table(self) -> pa.Table:
        """All rows appended, in order (the result schema's empty table if none)."""
        self._join()
        return pa.concat_tables(self._joined) if self._joined else _SCHEMA.empty_table()


class _Entry(NamedTuple):
    key: tuple[int, ...]
    start: int
    rows: int
    meta: dict[str, Any]


class ReadCache:
    """The cache of run directory ``run_dir`` as one reader uses it: `read`, then `save`."""

    def __init__(self, run_dir: Path, *, trust: bool = True) -> None:
        self.path = run_dir / READ_CACHE_NAME
        self._table, self._old = _load(self.path) if trust else (None, {})
        self._index: list[list[Any]] = []
        self._rows = Rows()
        self._changed = not trust  # a verifying read writes its own cache

    def read(self, job_id: str, path: Path) -> tuple[dict[str, Any], pa.Table | None]:
        """`reader.read_checked` of result file ``path`` (footer record and table), from the
        cache while the file's key is the cached one."""
        hit = self._old.get(path.name)
        if hit is not None and self._table is not None:
            try:
                key = _key(path)
            except OSError:
                key = None
            if key == hit.key:
                table = self._table.slice(hit.start, hit.rows)
                self._keep(path.name, hit.key, hit.meta, table)
                return dict(hit.meta), table
        meta, table, key = read_checked(path, job_id)
        if table is not None:
            self._keep(path.name, key, dict(meta), table)
            self._changed = True
        return meta, table

    def _keep(self, name: str, key: tuple[int, ...], meta: dict, table: pa.Table) -> None:
        self._index.append([name, list(key), table.num_rows, meta])
        self._rows.append(table)

    def save(self) -> None:
        """Write the cache of the files read, if it differs from the one loaded (a run
        directory that cannot be written gets none)."""
        if not self._changed and len(self._index) == len(self._old):
            return
        if not self._index and not self._old:
            return  # nothing stored: nothing to add to the run directory
        index = json.dumps({"result_format": RESULT_FORMAT_VERSION, "files": self._index})
        buf = pa.BufferOutputStream()
        pq.write_table(self._rows.table(), buf, compression="zstd")
        body = len(index).to_bytes(8, "big") + index.encode() + buf.getvalue().to_pybytes()
        try:
            atomic_write_bytes(self.path, _MAGIC + hashlib.sha256(body).digest() + body)
        except OSError:
            pass  # a store one may read but not write: read without a cache


def _key(path: Path) -> tuple[int, ...]:
    from .reader import cache_key

    return cache_key(os.stat(path))


def _load(path: Path) -> tuple[pa.Table | None, dict[str, _Entry]]:
    """The cached table and entries by file name; none for a cache that fails any check."""
    try:
        fd = open_regular(path)  # no link followed, no pipe waited on
    except OSError:
        return None, {}
    try:
        with os.fdopen(fd, "rb") as fh:
            if os.fstat(fh.fileno()).st_size > MAX_CACHE_BYTES:
                return None, {}
            data = fh.read()
        return _parse(data)
    except Exception:  # noqa: BLE001 - a damaged cache of any kind is ignored and rebuilt
        return None, {}


def _parse(data: bytes) -> tuple[pa.Table | None, dict[str, _Entry]]:
    head = len(_MAGIC)
    body = data[head + 32 :]
    if data[:head] != _MAGIC or hashlib.sha256(body).digest() != data[head : head + 32]:
        return None, {}
    size = int.from_bytes(body[:8], "big")
    index = json.loads(body[8 : 8 + size])
    if index["result_format"] != RESULT_FORMAT_VERSION:
        return None, {}
    table = pq.read_table(pa.BufferReader(body[8 + size :]))
    if not table.schema.remove_metadata().equals(_SCHEMA):
        return None, {}
    entries: dict[str, _Entry] = {}
    start = 0
    for name, key, rows, meta in index["files"]:
        if not (RESULT_NAME.fullmatch(name) and isinstance(meta, dict) and rows >= 0):
            return None, {}
        entries[name] = _Entry(tuple(int(k) for k in key), start, int(rows), meta)
        start += int(rows)
    if start != table.num_rows:
        return None, {}
    return table.replace_schema_metadata(None), entries

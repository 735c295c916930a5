"""A run's scalar results as one compact Parquet table that travels.

A sweep longer than a sitting is charted in parts: after each part, `pack` merges the run's
stored results into one table kept where the next machine finds it (the repository); there,
`unpack` writes them back into a fresh run directory of the same sweep, and ``woundsweep run``
skips those jobs (they are stored results like any other). The table holds result rows only:
every column of the result schema (`reader.result_schema`), the fields columns emptied
(``fields`` = "none"), sorted by job index and stage, zstd-compressed with page checksums. Its
footer record (key ``woundsweep.packed``) holds the packed format, the result format, the
sweep's name, the counts and a sha256 of the values; a table that fails any check is refused.

Identity: a job's rows carry its fingerprint (`identity.result_fingerprint`). `unpack` writes
only jobs of the run's manifest whose fingerprint is the run's (another sweep's or another
setting's rows are counted and left out) and never replaces a job the store already holds.
`pack` replaces a job's rows only when the run computed it anew (another fingerprint or
finishing time), so packing the same run twice changes nothing.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from ..config.manifest import load_run
from ..core.errors import StoreError
from ..core.fsutil import atomic_write
from ..core.schema import ResultState
from ..core.versions import RESULT_FORMAT_VERSION
from .identity import fingerprints
from .reader import check_result, read_parquet_file, result_files, result_schema, scan_store
from .writer import Store

__all__ = [
    "PACKED_FORMAT",
    "PACKED_KEY",
    "PackCounts",
    "UnpackCounts",
    "pack",
    "read_packed",
    "unpack",
]

PACKED_KEY = b"woundsweep.packed"
PACKED_FORMAT = 1
# The result columns that name a job's fields and mesh files: a packed row has none.
_FIELD_COLUMNS = ("fields_file", "mesh_file", "fields_file_sha256", "mesh_file_sha256")


class PackCounts(NamedTuple):
    """What `pack` did: jobs added to the table, replaced in it, already in it; its size."""

    added: int
    replaced: int
    unchanged: int
    jobs: int
    rows: int
    bytes: int


class UnpackCounts(NamedTuple):
    """What `unpack` did with the table's jobs: written to the store, already stored there,
    left out (computed with other settings, or not in the run's manifest)."""

    written: int
    present: int
    other_settings: int
    not_in_manifest: int
    jobs: int


def _digest(table: pa.Table) -> str:
    """sha256 of the table's values, column by column (independent of how Arrow chunks them:
    numbers as their null mask and bytes, timestamps as integers, strings as text)."""
    h = hashlib.sha256()
    for name in table.column_names:
        col = table.column(name).combine_chunks()
        if pa.types.is_timestamp(col.type):
            col = col.cast(pa.int64())
        h.update(name.encode() + b"\0" + str(col.type).encode() + b"\0")
        if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            h.update(col.is_null().to_numpy(zero_copy_only=False).tobytes())
            h.update(col.fill_null(0).to_numpy(zero_copy_only=False).tobytes())
        else:
            h.update(json.dumps(col.to_pylist()).encode())
    return h.hexdigest()


def _strip_fields(table: pa.Table) -> pa.Table:
    """The rows without their fields: file names "", checksums null, ``fields`` "none"."""
    n = table.num_rows
    for name in (*_FIELD_COLUMNS, "fields"):
        i = table.schema.get_field_index(name)
        if name == "fields":
            col = pa.array(["none"] * n, pa.string())
        elif name.endswith("sha256"):
            col = pa.nulls(n, pa.string())
        else:
            col = pa.array([""] * n, pa.string())
        table = table.set_column(i, name, col)
    return table


def _sorted(table: pa.Table) -> pa.Table:
    return table.sort_by([("job_index", "ascending"), ("stage", "ascending")])


def read_packed(path: str | Path) -> tuple[pa.Table, dict[str, Any]]:
    """A packed table and its footer record, checked: page checksums, footer, result format,
    columns and the values' sha256. `StoreError` (one line, naming ``path``) otherwise."""
    path = Path(path)
    if not path.is_file():
        raise StoreError(f"{path}: no packed results table there")
    try:
        table = read_parquet_file(path, page_checksum_verification=True)
        meta = json.loads((table.schema.metadata or {})[PACKED_KEY])
        if not isinstance(meta, dict) or meta.get("packed_format") != PACKED_FORMAT:
            raise ValueError
    except Exception:  # noqa: BLE001 - pyarrow raises many types for a damaged or foreign file
        raise StoreError(f"{path}: not a packed results table of woundsweep (or damaged)") from None
    if meta.get("result_format") != RESULT_FORMAT_VERSION:
        raise StoreError(
            f"{path}: packed in result format {meta.get('result_format')!r}, this woundsweep"
            f" stores format {RESULT_FORMAT_VERSION}: its jobs must be computed again"
        )
    table = table.replace_schema_metadata(None)
    if not table.schema.equals(result_schema()):
        raise StoreError(f"{path}: its columns differ from the result schema (damaged)")
    if meta.get("sha256") != _digest(table):
        raise StoreError(f"{path}: damaged (the values' sha256 differs from its footer's)")
    return table, meta


def _write_packed(path: Path, table: pa.Table, sweep: str) -> int:
    jobs = len(pc.unique(table.column("job_id"))) if table.num_rows else 0
    meta = {
        "packed_format": PACKED_FORMAT,
        "result_format": RESULT_FORMAT_VERSION,
        "sweep": sweep,
        "jobs": jobs,
        "rows": table.num_rows,
        "sha256": _digest(table),
    }
    table = table.replace_schema_metadata({PACKED_KEY: json.dumps(meta).encode()})

    def write(tmp: str) -> None:
        sink = pa.BufferOutputStream()
        floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
        pq.write_table(
            table,
            sink,
            compression="zstd",
            compression_level=9,
            use_byte_stream_split=floats,  # float bytes grouped by significance: ~10 % smaller
            use_dictionary=[n for n in table.column_names if n not in floats],
            write_page_checksum=True,
        )
        with open(tmp, "wb") as fh:
            fh.write(memoryview(sink.getvalue()))

    atomic_write(path, write)
    return jobs


def _job_keys(table: pa.Table) -> dict[str, tuple[Any, ...]]:
    """job id -> what identifies its computation: fingerprint, finishing time, attempts."""
    cols = [
        table.column(c).to_pylist()
        for c in ("job_id", "result_fingerprint", "finished_at_utc", "attempts")
    ]
    return {jid: (fp, str(t), a) for jid, fp, t, a in zip(*cols)}


def pack(run_dir: str | Path, path: str | Path) -> PackCounts:
    """Merge the finished results of ``run_dir`` into the packed table ``path`` (made if
    missing), atomically. Only results the store counts done go in (validated, current)."""
    path = Path(path)
    run = load_run(run_dir)
    scan = scan_store(run.run_dir, run=run, verify_files=False)
    schema = result_schema()
    done = scan.rows if scan.rows is not None else schema.empty_table()  # the done rows
    new = _strip_fields(done) if done.num_rows else schema.empty_table()
    old = read_packed(path)[0] if path.exists() else schema.empty_table()
    old_keys, new_keys = _job_keys(old), _job_keys(new)
    taken = {j for j, k in new_keys.items() if old_keys.get(j) != k}
    replaced = sum(j in old_keys for j in taken)
    mask = pc.invert(pc.is_in(old.column("job_id"), value_set=pa.array(sorted(taken), pa.string())))
    merged = _sorted(
        pa.concat_tables(
            [
                old.filter(mask),
                new.filter(
                    pc.is_in(new.column("job_id"), value_set=pa.array(sorted(taken), pa.string()))
                ),
            ]
        )
    )
    jobs = _write_packed(path, merged, run.sweep.name)
    return PackCounts(
        added=len(taken) - replaced,
        replaced=replaced,
        unchanged=len(new_keys) - len(taken),
        jobs=jobs,
        rows=merged.num_rows,
        bytes=path.stat().st_size,
    )


def _job_meta(rows: pa.Table, jid: str, path: Path) -> dict[str, Any]:
    """The footer record of one job's packed rows, after checking they form one result."""
    one = {
        c: set(rows.column(c).to_pylist())
        for c in ("job_index", "failure_class", "result_fingerprint", "stages_requested")
    }
    stages = rows.column("stage").to_pylist()
    try:
        lo, hi = (int(s) for s in next(iter(one["stages_requested"])).split("-"))
    except (ValueError, TypeError, AttributeError):
        lo, hi = 0, -1
    if any(len(v) != 1 for v in one.values()) or stages != list(range(lo, hi + 1)):
        raise StoreError(f"{path}: job {jid}'s rows do not form one result (damaged)")
    return {
        "format": RESULT_FORMAT_VERSION,
        "job_id": jid,
        "job_index": int(next(iter(one["job_index"]))),
        "stages": [lo, hi],
        "failure_class": next(iter(one["failure_class"])),
        "fields_file": "",
        "fields_bytes": 0,
        "fields_sha256": None,
        "mesh_file": "",
        "mesh_sha256": None,
        "fingerprint": next(iter(one["result_fingerprint"])),
    }


def unpack(
    path: str | Path,
    run_dir: str | Path,
    progress: Callable[[int], None] | None = None,
) -> UnpackCounts:
    """Write the jobs of packed table ``path`` into the store of ``run_dir`` as results
    without fields; ``progress(n)`` is called after each job."""
    path = Path(path)
    table, _ = read_packed(path)
    run = load_run(run_dir)
    expected = fingerprints(run.sweep, run.manifest)
    store = Store(run.run_dir, run.sweep)
    stored, _ = result_files(run.run_dir)
    table = table.sort_by([("job_id", "ascending"), ("stage", "ascending")])
    ids = table.column("job_id").to_pylist()
    counts = dict(written=0, present=0, other_settings=0, not_in_manifest=0)
    start = 0
    while start < len(ids):
        jid = ids[start]
        end = start + 1
        while end < len(ids) and ids[end] == jid:
            end += 1
        rows = table.slice(start, end - start)
        start = end
        meta = _job_meta(rows, jid, path)
        if jid not in expected:
            counts["not_in_manifest"] += 1
        elif meta["fingerprint"] != expected[jid]:
            counts["other_settings"] += 1
        elif jid in stored and (
            check_result(stored[jid], jid, run.run_dir, expected[jid]).state == ResultState.DONE
        ):
            counts["present"] += 1
        else:
            store.commit_rows(rows, meta)
            counts["written"] += 1
        if progress is not None:
            progress(1)
    return UnpackCounts(**counts, jobs=sum(counts.values()))

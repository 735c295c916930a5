"""The result files' Arrow schema, their validation, and the validated reader of a run's rows.

Every result file has the schema `result_schema` (fixed, so the files always form one
dataset): the manifest columns, ``stage``, ``status``, the failure columns, the `StageResult`
fields (`STAGE_FIELDS`), one column per stage diagnostic (`DIAGNOSTIC_FIELDS`) and the job's
bookkeeping, including its `identity` fingerprint and
the checksums of its fields and mesh files. Its footer record (key ``woundsweep``) holds the
format version, the job id, the stages, the failure class, the fingerprint, the fields file
with its size and sha256, the mesh file's sha256, and a sha256 of the rows' values, since page
CRCs miss some damage (e.g. in page headers). `check_result` sorts a stored file into done,
stale, corrupt or damaged; `read_results` returns the current rows of a run and
`rows_element_degree` the element they were computed with.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..config.manifest import Run, load_run
from ..config.sweep import MANIFEST_COLUMNS
from ..core.diagnostics import DIAGNOSTIC_KINDS
from ..core.errors import StoreError
from ..core.layout import FIELDS_NAME, MESH_NAME, RESULT_NAME, RunLayout
from ..core.schema import ResultState, stage_field_kinds
from ..core.versions import RESULT_FORMAT_VERSION
from .identity import file_sha256, fingerprints

if TYPE_CHECKING:
    from .readcache import ReadCache

__all__ = [
    "DIAGNOSTIC_FIELDS",
    "META_KEY",
    "RESULT_NAME",
    "STAGE_FIELDS",
    "FIELDS_NAME",
    "MESH_NAME",
    "FilesDamaged",
    "ResultCheck",
    "StoreScan",
    "check_files",
    "cache_key",
    "check_result",
    "content_digest",
    "read_checked",
    "read_footer",
    "read_results",
    "result_files",
    "read_parquet_file",
    "result_schema",
    "rows_element_degree",
    "scan_results",
    "scan_store",
    "stale_reason",
    "store_file_names",
    "validate_result_file",
]

# The `StageResult` fields besides ``stage`` and ``status``, in its order, as Arrow types.
STAGE_FIELDS: dict[str, pa.DataType] = {
    name: pa.int64() if kind is int else pa.float64() for name, kind in stage_field_kinds().items()
}
# The stage diagnostics (`core.diagnostics`), one column each, null where a stage has none.
DIAGNOSTIC_FIELDS: dict[str, pa.DataType] = {
    name: pa.int64() if kind is int else pa.float64() for name, kind in DIAGNOSTIC_KINDS.items()
}
_MANIFEST_STRINGS = ("job_id", "geometry_id", "wound_shape", "skin_type")
_JOB_FIELDS: dict[str, pa.DataType] = {
    "exit_code": pa.int64(),
    "attempts": pa.int64(),
    "job_wall_time_s": pa.float64(),
    "job_cpu_time_s": pa.float64(),
    "total_wall_time_s": pa.float64(),
    "total_cpu_time_s": pa.float64(),
    "max_rss_MiB": pa.float64(),
    "started_at_utc": pa.timestamp("ms", tz="UTC"),
    "finished_at_utc": pa.timestamp("ms", tz="UTC"),
    "host": pa.string(),
    "shard": pa.string(),
    "stages_requested": pa.string(),
    "fields": pa.string(),
    "fields_file": pa.string(),
    "mesh_file": pa.string(),
    "woundsweep_version": pa.string(),
    "dolfinx_version": pa.string(),
    "python_version": pa.string(),
    "jit_time_s": pa.float64(),  # the solver's form-compile (or cache load) time, if it says
    "result_fingerprint": pa.string(),  # `identity.result_fingerprint` of the job's inputs
    "fields_file_sha256": pa.string(),
    "mesh_file_sha256": pa.string(),
}
META_KEY = b"woundsweep"


class FilesDamaged(StoreError):
    """A result whose fields or mesh file is missing or differs from its recorded checksum."""


def content_digest(table: pa.Table) -> str:
    """sha256 of the table's values (canonical JSON of the rows, keys sorted), kept in the
    footer record."""
    # Rows built column by column with their keys already in order: the same text as
    # ``json.dumps(table.to_pylist(), sort_keys=True)`` at a fraction of its cost.
    names = sorted(table.column_names)
    columns = [_json_values(table.column(n)) for n in names]
    rows = [dict(zip(names, values)) for values in zip(*columns)]
    return hashlib.sha256(json.dumps(rows, default=str).encode()).hexdigest()


def _json_values(col: pa.ChunkedArray) -> list[Any]:
    """The column's values for `content_digest`: timestamps as ``str`` of their datetime
    (what ``default=str`` makes of them), each distinct one converted once (slow in Python)."""
    if not pa.types.is_timestamp(col.type):
        return col.to_pylist()
    distinct = col.unique()
    text = {
        i: None if d is None else str(d)
        for i, d in zip(distinct.cast(pa.int64()).to_pylist(), distinct.to_pylist())
    }
    return [text[i] for i in col.cast(pa.int64()).to_pylist()]


def result_schema() -> pa.Schema:
    """The Arrow schema of every result file."""
    fields = []
    for name in MANIFEST_COLUMNS:
        if name == "job_index":
            fields.append(pa.field(name, pa.int64()))
        elif name in _MANIFEST_STRINGS:
            fields.append(pa.field(name, pa.string()))
        else:
            fields.append(pa.field(name, pa.float64()))
    fields += [
        pa.field("stage", pa.int64()),
        pa.field("status", pa.string()),
        pa.field("failure_class", pa.string()),
        pa.field("failed_stage", pa.int64()),
        pa.field("failure_detail", pa.string()),
    ]
    fields += [pa.field(k, t) for k, t in STAGE_FIELDS.items()]
    fields += [pa.field(k, t) for k, t in DIAGNOSTIC_FIELDS.items()]
    fields += [pa.field(k, t) for k, t in _JOB_FIELDS.items()]
    return pa.schema(fields)


_SCHEMA = result_schema()


def read_parquet_file(path: str | Path, **kwargs: Any) -> pa.Table:
    """One Parquet file as a table. `pq.read_table` reads ``x=y`` parts of the path as hive
    partitions and adds their columns, so a store under ``/data/exp=1`` would not match its
    schema; a `ParquetFile` is the file alone, whatever the path."""
    # Opened by Python, not by path: pyarrow encodes a path as UTF-8 whatever the filesystem
    # encoding, so a non-ASCII path under a C locale would not open.
    with open(path, "rb") as fh, pq.ParquetFile(fh, **kwargs) as pf:
        return pf.read()


def store_file_names(meta: Mapping[str, Any], job_id: str | None = None) -> tuple[str, str]:
    """The fields and mesh file names of footer ``meta``: "" or a plain name of the store's
    pattern (the job's own fields file); StoreError for anything else (a path, ``..``)."""
    names = []
    for key, pattern in (("fields_file", FIELDS_NAME), ("mesh_file", MESH_NAME)):
        name = meta.get(key) or ""
        if not isinstance(name, str) or (name and not pattern.fullmatch(name)):
            raise StoreError(f"its footer's {key} {name!r} is not a file name of the store")
        names.append(name)
    if job_id is not None and names[0] and names[0] != f"{job_id}.h5":
        raise StoreError(f"its footer's fields_file {names[0]!r} is not job {job_id}'s")
    return names[0], names[1]


def read_footer(path: Path) -> dict[str, Any] | None:
    """The footer record alone (cheap: the Parquet footer), or None if it cannot be read."""
    try:
        with open(path, "rb") as fh:  # by Python: a non-UTF-8 path opens (read_parquet_file)
            raw = (pq.read_schema(fh).metadata or {}).get(META_KEY)
        meta = json.loads(raw)  # type: ignore[arg-type]  # None raises TypeError: caught below
    except Exception:  # noqa: BLE001 - damaged files are the full validator's to name
        return None
    return meta if isinstance(meta, dict) else None


def stale_reason(meta: Mapping[str, Any], fingerprint: str | None = None) -> str:
    """Why the result with footer record ``meta`` is stale: written in another result format,
    or computed with other settings than ``fingerprint`` (if given); "" if it is neither."""
    if meta.get("format") != RESULT_FORMAT_VERSION:
        return f"written in result format {meta.get('format')!r}"
    if fingerprint is not None and meta.get("fingerprint") != fingerprint:
        return "computed with other settings (fingerprint differs)"
    return ""


def read_checked(
    path: Path, job_id: str | None, *, skip_stale: bool = True
) -> tuple[dict[str, Any], pa.Table | None, tuple[int, ...]]:
    """Open a result file once and check it: its footer record, its table (None when the
    footer names another result format and ``skip_stale``: stale, its rows not read) and
    its `cache_key`.

    Page checksums, schema, footer record, content checksum, job id, stages and file names
    are checked on the bytes read; a failure is a `StoreError` naming the file as corrupt.
    """
    if not path.is_file():  # a named pipe would block the reader
        raise StoreError(f"{path}: corrupt result file (not a regular file)")
    try:
        # Opened by Python, not by path (see read_parquet_file); the footer is parsed once.
        with open(path, "rb") as fh:
            key = cache_key(os.fstat(fh.fileno()))  # of the very file whose bytes are read
            data = fh.read()  # one read: a small file parsed from memory reads faster
        with pq.ParquetFile(pa.BufferReader(data), page_checksum_verification=True) as pf:
            meta = _footer_record(pf.schema_arrow.metadata)
            if skip_stale and meta is not None and stale_reason(meta):
                return meta, None, key  # another result format: stale, not read further
            table = pf.read(use_threads=False)  # threads cost more than a few rows take
    except Exception as err:  # pyarrow raises OSError, ArrowInvalid, ... for damaged files
        raise StoreError(f"{path}: corrupt result file ({type(err).__name__})") from None
    if not table.schema.remove_metadata().equals(_SCHEMA):
        raise StoreError(f"{path}: corrupt result file (columns differ from the result schema)")
    try:
        lo, hi = (int(s) for s in meta["stages"])  # type: ignore[index]
        if not isinstance(meta.get("sha256"), str):  # type: ignore[union-attr]
            raise TypeError
    except (TypeError, ValueError, KeyError, AttributeError):
        raise StoreError(
            f"{path}: corrupt result file (no valid woundsweep footer record)"
        ) from None
    assert meta is not None  # for mypy: a None record raised TypeError above
    if meta["sha256"] != content_digest(table):
        raise StoreError(f"{path}: corrupt result file (content checksum mismatch)")
    if job_id is not None and meta.get("job_id") != job_id:
        raise StoreError(f"{path}: holds job {meta.get('job_id')!r}, not {job_id!r}")
    found = table.column("stage").to_pylist()
    if found != list(range(lo, hi + 1)):
        raise StoreError(f"{path}: expected stages {lo}-{hi}, found {found}")
    try:
        names = store_file_names(meta, meta.get("job_id"))
    except StoreError as err:
        raise StoreError(f"{path}: corrupt result file ({err})") from None
    for key_name, name in zip(("fields_file", "mesh_file"), names):
        if set(table.column(key_name).to_pylist()) - {name}:
            raise StoreError(f"{path}: corrupt result file ({key_name} differs from its footer's)")
    return meta, table.replace_schema_metadata(None), key


def cache_key(st: os.stat_result) -> tuple[int, ...]:
    """What identifies a result file's bytes to the read cache: size, mtime_ns, ctime_ns
    and inode (a write through the filesystem changes one of them)."""
    return (st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)


def _footer_record(metadata: Mapping[bytes, bytes] | None) -> dict[str, Any] | None:
    try:
        meta = json.loads((metadata or {})[META_KEY])
    except (KeyError, TypeError, ValueError):
        return None
    return meta if isinstance(meta, dict) else None


def validate_result_file(
    path: Path,
    job_id: str | None,
    run_dir: Path,
    *,
    verify_files: bool = False,
    memo: dict | None = None,
) -> dict[str, Any]:
    """Read a whole result file with page checksums; returns its footer record.

    Raises `StoreError` for a damaged Parquet file and `FilesDamaged` when its fields or mesh
    file is missing, has another size, or (``verify_files``) another sha256 than recorded.
    The record's ``_table`` holds the file's table.
    """
    meta, table, _ = read_checked(path, job_id, skip_stale=False)
    assert table is not None  # for mypy: read whatever its format
    check_files(path, meta, run_dir, verify=verify_files, memo=memo)
    meta["_table"] = table
    return meta


def check_files(
    path: Path, meta: dict[str, Any], run_dir: Path, *, verify: bool, memo: dict | None = None
) -> None:
    """`FilesDamaged` unless the fields and mesh files of result ``path`` (footer ``meta``)
    exist with the recorded size and, with ``verify``, the recorded sha256."""
    ff, mf = store_file_names(meta)  # validated with the footer: plain names only
    fields_dir = RunLayout(run_dir).fields_dir
    if ff:
        fpath = fields_dir / ff
        if not fpath.is_file() or fpath.stat().st_size != meta.get("fields_bytes"):
            raise FilesDamaged(f"{path}: its fields file {fpath} is missing or truncated")
        if verify and file_sha256(fpath, memo) != meta.get("fields_sha256"):
            raise FilesDamaged(f"{path}: its fields file {fpath} is damaged (sha256 differs)")
    if mf:
        mpath = fields_dir / mf
        if not mpath.is_file():
            raise FilesDamaged(f"{path}: its mesh file {mpath} is missing")
        if verify and file_sha256(mpath, memo) != meta.get("mesh_sha256"):
            raise FilesDamaged(f"{path}: its mesh file {mpath} is damaged (sha256 differs)")


class ResultCheck(NamedTuple):
    """One stored result's `ResultState` (never ``missing``), why, and its footer."""

    state: ResultState
    reason: str = ""
    meta: dict[str, Any] | None = None


def check_result(
    path: Path,
    job_id: str,
    run_dir: Path,
    fingerprint: str | None,
    *,
    verify_files: bool = True,
    memo: dict | None = None,
    cache: ReadCache | None = None,
) -> ResultCheck:
    """Sort one result file: corrupt (the Parquet file), stale (another result format or
    another fingerprint than ``fingerprint``), damaged (its fields or mesh file), or done.
    A done result's record holds its rows as ``_table``; ``cache`` is the read cache to
    take the Parquet file's checked rows from (`readcache`), if any."""
    try:
        meta, table = cache.read(job_id, path) if cache else read_checked(path, job_id)[:2]
    except StoreError as err:
        return ResultCheck(ResultState.CORRUPT, str(err))
    if table is None:  # another result format: its rows were not read
        return ResultCheck(ResultState.STALE, stale_reason(meta))
    try:  # the Parquet file is whole: are its fields and mesh files?
        check_files(path, meta, run_dir, verify=False)
    except FilesDamaged as err:
        return ResultCheck(ResultState.DAMAGED, str(err), meta)
    if reason := stale_reason(meta, fingerprint):
        return ResultCheck(ResultState.STALE, reason, meta)
    if verify_files:
        try:
            check_files(path, meta, run_dir, verify=True, memo=memo)
        except FilesDamaged as err:
            return ResultCheck(ResultState.DAMAGED, str(err), meta)
    meta["_table"] = table
    return ResultCheck(ResultState.DONE, "", meta)


def result_files(run_dir: Path) -> tuple[dict[str, Path], list[Path]]:
    """The store's result files by job id, and the stray files of ``results/`` (ignored)."""
    results_dir = RunLayout(run_dir).results_dir
    found: dict[str, Path] = {}
    stray: list[Path] = []
    if results_dir.is_dir():
        for p in sorted(results_dir.iterdir()):
            m = RESULT_NAME.fullmatch(p.name)
            if m and p.is_file():
                found[m.group(1)] = p
            elif not p.name.startswith("."):  # dot files are writers' temporaries
                stray.append(p)
    return found, stray


class StoreScan(NamedTuple):
    """What `scan_store` found: checks of manifest jobs, orphans, stray files, and the rows
    of the done results in job order (their checks' records hold no ``_table``)."""

    checks: dict[str, ResultCheck]
    orphans: list[str]
    stray: list[Path]
    rows: pa.Table | None = None

    def count(self, state: ResultState) -> int:
        return sum(c.state == state for c in self.checks.values())


def scan_store(
    run_dir: str | Path,
    *,
    verify_files: bool = True,
    run: Run | None = None,
    use_cache: bool = True,
) -> StoreScan:
    """Check every result file of the run's manifest jobs (checksums of the fields and mesh
    files too, unless ``verify_files`` is false); moves nothing. ``run`` is the run directory
    already loaded (`load_run`), if the caller has it. With ``use_cache`` the Parquet files
    unchanged since the read cache recorded them are taken from it; without, every one is read
    and checked (and the cache written anew)."""
    from .readcache import ReadCache, Rows

    rd = Path(run_dir)
    run = run if run is not None else load_run(rd)
    expected = fingerprints(run.sweep, run.manifest)
    files, stray = result_files(rd)
    memo: dict = {}
    cache = ReadCache(rd, trust=use_cache)
    rows = Rows()
    checks = {}
    for jid, p in files.items():
        if jid not in expected:
            continue
        c = check_result(
            p, jid, rd, expected[jid], verify_files=verify_files, memo=memo, cache=cache
        )
        if c.meta is not None and "_table" in c.meta:
            rows.append(c.meta.pop("_table"))  # joined as read: no table per file kept
        checks[jid] = c
    cache.save()
    orphans = [jid for jid in files if jid not in expected]
    return StoreScan(checks, orphans, stray, rows.table())


def read_results(
    run_dir: str | Path, job_ids: Iterable[str] | None = None, *, run: Run | None = None
) -> pd.DataFrame:
    """The current result rows of a run, one per job and stage (an empty frame if none).

    Every file is validated (page checksums, footer record, schema, fields file size); a bad
    one raises ``StoreError`` naming it, on one line, with the fix. Results of manifest jobs
    computed with other settings (stale) are left out; so are stray files in ``results/``.
    Jobs not in the manifest (orphans of an earlier sweep) are returned: callers filter them.
    ``run`` is the run directory already loaded (`load_run`), if the caller has it; without
    it the directory's sweep and manifest are read, if it has them. A read of every job
    takes unchanged files from the read cache (`readcache`) and updates it.
    """
    from .readcache import ReadCache, Rows

    run_dir = Path(run_dir)
    files, _ = result_files(run_dir)
    expected: Mapping[str, str] = {}
    if run is None and RunLayout(run_dir).is_run():
        run = load_run(run_dir)
    if run is not None:
        expected = fingerprints(run.sweep, run.manifest)
    cache = None
    if job_ids is not None:  # a few jobs: read them, no cache to load
        wanted = set(job_ids)
        files = {j: p for j, p in files.items() if j in wanted}
    else:
        cache = ReadCache(run_dir)
    rows = Rows()
    for jid, p in files.items():
        try:
            meta, table = cache.read(jid, p) if cache else read_checked(p, jid)[:2]
            if table is None:
                continue  # another result format: stale (or an orphan that cannot be read)
            check_files(p, meta, run_dir, verify=False)
        except StoreError as err:
            raise StoreError(
                f"{err}; rerun `woundsweep run {run_dir}` (it moves the file aside and redoes the job)"
            ) from None
        if stale_reason(meta, expected.get(jid)):
            continue
        rows.append(table)
    if cache is not None:
        cache.save()
    return rows.table().to_pandas()


def scan_results(scan: StoreScan) -> pd.DataFrame:
    """The rows of the results a scan found done (what `woundsweep status` counts)."""
    if scan.rows is not None:
        return scan.rows.to_pandas()
    tables = [
        c.meta["_table"] for c in scan.checks.values() if c.state == ResultState.DONE and c.meta
    ]
    if not tables:
        return _SCHEMA.empty_table().to_pandas()
    return pa.concat_tables([t.replace_schema_metadata(None) for t in tables]).to_pandas()


def rows_element_degree(rows: pd.DataFrame) -> int | None:
    """The element degree of result ``rows`` (None without rows); StoreError if they mix
    elements."""
    degrees = sorted({int(d) for d in rows["element_degree"].dropna()})
    if len(degrees) > 1:
        raise StoreError(f"the result rows mix element degrees {degrees}")
    return degrees[0] if degrees else None

"""The result files' Arrow schema, their validation, and the validated reader of a run's rows.

Every result file has the schema `result_schema` (fixed, so the files always form one
dataset): the manifest columns, ``stage``, ``status``, the failure columns, the `StageResult`
fields (`STAGE_FIELDS`) and the job's bookkeeping. Its footer record (key ``woundsweep``)
holds the job id, the stages, the failure class, the fields file and its size, and a sha256
of the rows' values, since page CRCs miss some damage (e.g. in page headers).
`read_results` checks all of it for every file it reads.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import StoreError
from ..schema import FailureClass, StageStatus, stage_field_kinds
from .grid import MANIFEST_COLUMNS
from .shards import estimate_cost

__all__ = [
    "FORMAT_VERSION",
    "META_KEY",
    "STAGE_FIELDS",
    "content_digest",
    "read_results",
    "result_schema",
    "summarize",
    "validate_result_file",
]

# The `StageResult` fields besides ``stage`` and ``status``, in its order, as Arrow types.
STAGE_FIELDS: dict[str, pa.DataType] = {
    name: pa.int64() if kind is int else pa.float64() for name, kind in stage_field_kinds().items()
}
_MANIFEST_STRINGS = ("job_id", "geometry_id", "wound_shape", "skin_type")
_JOB_FIELDS: dict[str, pa.DataType] = {
    "stage_extra_json": pa.string(),  # StageResult keys this version does not know, kept
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
}
META_KEY = b"woundsweep"
FORMAT_VERSION = 1


def content_digest(table: pa.Table) -> str:
    """sha256 of the table's values (canonical JSON), kept in the footer record."""
    text = json.dumps(table.to_pylist(), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


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
    fields += [pa.field(k, t) for k, t in _JOB_FIELDS.items()]
    return pa.schema(fields)


def validate_result_file(path: Path, job_id: str | None, run_dir: Path) -> dict[str, Any]:
    """Read a whole result file with page checksums; returns its footer record.

    The record's ``_table`` holds the file's table.
    """
    try:
        table = pq.read_table(path, page_checksum_verification=True)
    except Exception as err:  # pyarrow raises OSError, ArrowInvalid, ... for damaged files
        raise StoreError(f"{path}: corrupt result file ({type(err).__name__})") from None
    if not table.schema.remove_metadata().equals(result_schema()):
        raise StoreError(f"{path}: corrupt result file (columns differ from the result schema)")
    raw = (table.schema.metadata or {}).get(META_KEY)
    try:
        meta = json.loads(raw)
        lo, hi = (int(s) for s in meta["stages"])
        if not isinstance(meta.get("sha256"), str):
            raise TypeError
    except (TypeError, ValueError, KeyError, AttributeError):
        raise StoreError(
            f"{path}: corrupt result file (no valid woundsweep footer record)"
        ) from None
    if meta["sha256"] != content_digest(table):
        raise StoreError(f"{path}: corrupt result file (content checksum mismatch)")
    if job_id is not None and meta.get("job_id") != job_id:
        raise StoreError(f"{path}: holds job {meta.get('job_id')!r}, not {job_id!r}")
    found = table.column("stage").to_pylist()
    if found != list(range(lo, hi + 1)):
        raise StoreError(f"{path}: expected stages {lo}-{hi}, found {found}")
    ff = meta.get("fields_file") or ""
    if ff:
        fpath = run_dir / "fields" / ff
        if not fpath.exists() or fpath.stat().st_size != meta.get("fields_bytes"):
            raise StoreError(f"{path}: its fields file {fpath} is missing or truncated")
    mf = meta.get("mesh_file") or ""
    if mf and not (run_dir / "fields" / mf).exists():
        raise StoreError(f"{path}: its mesh file fields/{mf} is missing")
    meta["_table"] = table
    return meta


def read_results(run_dir: str | Path, job_ids: Iterable[str] | None = None) -> pd.DataFrame:
    """All result rows of a run, one per job and stage (empty frame with the columns if none).

    Every file is validated (page checksums, footer record, schema, fields file size); a bad
    one raises ``StoreError`` naming it, on one line, with the fix.
    """
    run_dir = Path(run_dir)
    results_dir = run_dir / "results"
    files = sorted(results_dir.glob("job-*.parquet")) if results_dir.is_dir() else []
    if job_ids is not None:
        wanted = set(job_ids)
        files = [p for p in files if p.name[4:-8] in wanted]
    tables = []
    for p in files:
        try:
            meta = validate_result_file(p, p.name[4:-8], run_dir)
        except StoreError as err:
            raise StoreError(
                f"{err}; rerun `woundsweep run {run_dir}` (it moves the file aside and redoes the job)"
            ) from None
        tables.append(meta["_table"].replace_schema_metadata(None))
    if not tables:
        return result_schema().empty_table().to_pandas()
    return pa.concat_tables(tables).to_pandas()


def summarize(manifest: pd.DataFrame, results: pd.DataFrame) -> dict[str, Any]:
    """Counts and times for ``woundsweep status`` (jobs of the manifest only)."""
    in_manifest = results["job_id"].isin(set(manifest["job_id"]))
    orphans = int(results.loc[~in_manifest, "job_id"].nunique())
    rows = results[in_manifest]
    jobs = rows.drop_duplicates("job_id")
    done_ids = set(jobs["job_id"])
    pending = manifest[~manifest["job_id"].isin(done_ids)]
    by_class = {c.value: int((jobs["failure_class"] == c.value).sum()) for c in FailureClass}
    by_stage: dict[str, dict[str, int]] = {}
    for stage, g in rows.groupby("stage", sort=True):
        counts = g["status"].value_counts()
        by_stage[str(int(stage))] = {s.value: int(counts.get(s.value, 0)) for s in StageStatus}
    not_converged_at = {
        str(int(k)): int(v)
        for k, v in jobs["failed_stage"].dropna().value_counts().sort_index().items()
    }
    cpu_used = float(jobs["total_cpu_time_s"].sum()) if len(jobs) else 0.0
    span = None
    if len(jobs):
        t0 = jobs["started_at_utc"].min()
        t1 = jobs["finished_at_utc"].max()
        span = max((t1 - t0).total_seconds(), 0.0)
    throughput = len(jobs) / span * 3600.0 if span else None
    cpu_left = None
    if len(jobs) and cpu_used > 0:
        cost = pd.Series(estimate_cost(manifest), index=manifest["job_id"].to_numpy())
        done_cost = float(cost.loc[list(done_ids)].sum())
        cpu_left = cpu_used / done_cost * float(cost.loc[pending["job_id"]].sum())
    return {
        "jobs_total": int(len(manifest)),
        "jobs_done": int(len(jobs)),
        "jobs_pending": int(len(pending)),
        "rows": int(len(rows)),
        "orphan_jobs": orphans,
        "by_failure_class": by_class,
        "not_converged_at_stage": not_converged_at,
        "by_stage": by_stage,
        "attempts": int(jobs["attempts"].sum()) if len(jobs) else 0,
        "wall_span_s": span,
        "throughput_jobs_per_hour": throughput,
        "cpu_time_used_s": cpu_used,
        "cpu_time_left_estimate_s": cpu_left,
    }

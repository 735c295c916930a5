"""The result store under RUN_DIR: one Parquet file per job, HDF5 fields, crash-safe writes.

Layout::

    RUN_DIR/results/job-<job_id>.parquet   one row per requested stage of the job (all classes)
    RUN_DIR/fields/<job_id>.h5              displacement and cellwise von Mises per stored stage
    RUN_DIR/fields/mesh-<geometry_id>.h5    the mesh, once per geometry
    RUN_DIR/logs/job-<job_id>.log           the job's stdout/stderr, one header per attempt
    RUN_DIR/tmp/                            solver outputs in flight (host and runner pid named)
    RUN_DIR/corrupt/                        result files that failed validation, moved aside

Crash safety: every file is written to a temporary name (a dot file in the same directory,
which pyarrow ignores), flushed, fsynced and moved into place with ``os.replace``; a reader
sees the old file or the whole new one. The fields of a job are written before its Parquet
file, so "Parquet file present and valid" means the job is complete, fields included: that
is the resume rule. A job owns exactly one Parquet file, so a rerun or two shards racing on
one job replace it and never duplicate rows; ``pandas.read_parquet("RUN_DIR/results")`` reads
the whole store. Failed jobs get rows too (status ``not-run`` for stages without a result),
so counts by ``failure_class`` come straight from the store.

Parquet files carry page checksums and a footer record (``woundsweep`` key: job id, stages,
failure class, fields file and its size, and a sha256 of the rows' values, since page CRCs
miss some damage, e.g. in page headers) that resume validation checks; HDF5 datasets are
float32 (coordinates float64), gzip-compressed with Fletcher-32 checksums.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import re
import socket
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from . import __version__
from .errors import StoreError
from .fsutil import atomic_write
from .grid import MANIFEST_COLUMNS
from .shards import estimate_cost

__all__ = [
    "FAILURE_CLASSES",
    "FIELDS_CHOICES",
    "STAGE_FIELDS",
    "STAGE_STATUSES",
    "TRANSIENT_CLASSES",
    "JobOutcome",
    "JobState",
    "SolverOutput",
    "Store",
    "read_results",
    "read_solver_output",
    "result_schema",
    "summarize",
]

FAILURE_CLASSES = (
    "converged",
    "not-converged",
    "timeout",
    "out-of-memory",
    "crashed",
    "mesh-failed",
    "invalid",
)
# Retried up to --retries times: they depend on the machine's state (load, a JIT lock, a node
# fault), not on the job. Out-of-memory is not: a job's memory use is set by its mesh, so the
# same cap stops it again; rerun those with a larger --max-memory and --rerun-failed.
TRANSIENT_CLASSES = frozenset({"timeout", "crashed"})
STAGE_STATUSES = (
    "converged",
    "max-iterations",
    "diverged",
    "inverted",
    "linear-solver-failed",
    "not-run",
)
FIELDS_CHOICES = ("all", "final", "none")
STAGE_DATASETS = frozenset({"displacement_mm", "von_mises_kPa"})
MESH_DATASETS = frozenset({"points", "cells", "cell_tags"})

# StageResult fields of docs/design.md (besides `stage` and `status`) and their Arrow types.
STAGE_FIELDS: dict[str, pa.DataType] = {
    "newton_iterations": pa.int64(),
    "time_s": pa.float64(),
    "p99_von_mises_kPa": pa.float64(),
    "p99_von_mises_nodal_kPa": pa.float64(),
    "max_von_mises_kPa": pa.float64(),
    "max_location_x_mm": pa.float64(),
    "max_location_y_mm": pa.float64(),
    "max_location_z_mm": pa.float64(),
    "closure_gap_mm": pa.float64(),
    "min_J": pa.float64(),
    "n_penetrating": pa.int64(),
    "max_penetration_mm": pa.float64(),
    "contact_force_mN": pa.float64(),
    "residual_norm": pa.float64(),
    "dofs": pa.int64(),
    "cells": pa.int64(),
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


def _content_digest(table: pa.Table) -> str:
    """sha256 of the table's values (canonical JSON), kept in the footer record."""
    text = json.dumps(table.to_pylist(), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def result_schema() -> pa.Schema:
    """The Arrow schema of every result file (fixed, so the files always form one dataset)."""
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


class SolverOutput(NamedTuple):
    """What a solver HDF5 file says: root attributes and the per-stage results by stage."""

    path: Path
    attrs: dict[str, Any]
    stages: dict[int, dict[str, Any]]


class JobOutcome(NamedTuple):
    """What the runner learned about one job (its last attempt, times summed over attempts)."""

    failure_class: str
    failure_detail: str
    exit_code: int | None
    attempts: int
    wall_time_s: float
    cpu_time_s: float
    total_wall_time_s: float
    total_cpu_time_s: float
    max_rss_MiB: float | None
    started_at: float
    finished_at: float
    output: SolverOutput | None


class JobState(NamedTuple):
    """Resume bookkeeping for one job: ``state`` is ``missing``, ``done``, ``stale`` or ``corrupt``."""

    state: str
    failure_class: str | None = None
    reason: str = ""


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_solver_output(path: str | Path, job_id: str, stages: tuple[int, int]) -> SolverOutput:
    """Read and check a ``woundsweep solve`` HDF5 file; ``StoreError`` says what is wrong."""
    import h5py

    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
            groups = {g: set(f[g].keys()) for g in f.keys() if isinstance(f[g], h5py.Group)}
    except (OSError, KeyError, ValueError) as err:
        raise StoreError(f"{path}: unreadable solver output ({err})") from None
    if attrs.get("job_id") != job_id:
        raise StoreError(f"{path}: job_id {attrs.get('job_id')!r} is not {job_id!r}")
    try:
        rows = json.loads(attrs.get("stage_results", ""))
        by_stage = {int(r["stage"]): dict(r) for r in rows}
    except (ValueError, TypeError, KeyError) as err:
        raise StoreError(f"{path}: bad stage_results attribute ({err})") from None
    for k, r in by_stage.items():
        if r.get("status") not in STAGE_STATUSES:
            raise StoreError(f"{path}: stage {k} has unknown status {r.get('status')!r}")
        if r["status"] == "converged" and not STAGE_DATASETS <= groups.get(f"stage_{k}", set()):
            raise StoreError(
                f"{path}: converged stage {k} lacks stage_{k}/{sorted(STAGE_DATASETS)}"
            )
    for g, names in groups.items():
        if (g == "mesh" and not MESH_DATASETS <= names) or (
            g.startswith("stage_") and not STAGE_DATASETS <= names
        ):
            raise StoreError(f"{path}: group {g} is incomplete ({sorted(names)})")
    attrs["_groups"] = sorted(groups)
    return SolverOutput(
        path, attrs, {k: v for k, v in by_stage.items() if stages[0] <= k <= stages[1]}
    )


def _float_or_none(value: Any) -> float | None:
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _utc(ts: float) -> _dt.datetime:
    return _dt.datetime.fromtimestamp(ts, tz=_dt.timezone.utc)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _copy_dataset(src: Any, dst_group: Any, name: str) -> None:
    data = src[()]
    if data.dtype.kind == "f" and name != "points":
        data = data.astype(np.float32)  # fields: float32 is ample for stresses and mm
    dst_group.create_dataset(
        name,
        data=data,
        chunks=True if data.ndim else None,
        compression="gzip" if data.ndim else None,
        compression_opts=4 if data.ndim else None,
        shuffle=bool(data.ndim),
        fletcher32=bool(data.ndim),
    )


def _mesh_digest(mesh: Any) -> str:
    h = hashlib.sha256()
    for name in ("points", "cells", "cell_tags"):
        if name in mesh:
            arr = np.ascontiguousarray(mesh[name][()])
            h.update(name.encode() + str(arr.dtype).encode() + str(arr.shape).encode())
            h.update(arr.tobytes())
    return h.hexdigest()


class Store:
    """Paths, atomic writes and resume validation for one run directory."""

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        self.results_dir = self.run_dir / "results"
        self.fields_dir = self.run_dir / "fields"
        self.logs_dir = self.run_dir / "logs"
        self.tmp_dir = self.run_dir / "tmp"
        self.corrupt_dir = self.run_dir / "corrupt"
        self.host = socket.gethostname()

    def ensure_dirs(self) -> None:
        for d in (self.results_dir, self.fields_dir, self.logs_dir, self.tmp_dir):
            d.mkdir(parents=True, exist_ok=True)

    def result_path(self, job_id: str) -> Path:
        return self.results_dir / f"job-{job_id}.parquet"

    def log_path(self, job_id: str) -> Path:
        return self.logs_dir / f"job-{job_id}.log"

    def tmp_path(self, job_id: str, attempt: int, suffix: str = ".h5") -> Path:
        """A per-attempt temporary file named after this host and runner pid (see clean_tmp)."""
        return self.tmp_dir / f"{job_id}~{self.host}~{os.getpid()}~{attempt}{suffix}"

    # ---- resume bookkeeping -------------------------------------------------------------
    def job_state(self, job_id: str, stages: tuple[int, int]) -> JobState:
        """Is the job's result present, valid, and does it cover ``stages``?"""
        path = self.result_path(job_id)
        if not path.exists():
            return JobState("missing")
        try:
            meta = _validate_result_file(path, job_id, self.run_dir)
        except StoreError as err:
            return JobState("corrupt", reason=str(err))
        lo, hi = meta["stages"]
        if lo > stages[0] or hi < stages[1]:
            return JobState("stale", meta["failure_class"], f"has stages {lo}-{hi}")
        return JobState("done", meta["failure_class"])

    def quarantine(self, job_id: str) -> Path | None:
        """Move a result file that failed validation to RUN_DIR/corrupt/ (kept for inspection)."""
        src = self.result_path(job_id)
        self.corrupt_dir.mkdir(parents=True, exist_ok=True)
        dst = self.corrupt_dir / f"{src.name}.{int(time.time())}"
        try:
            os.replace(src, dst)
        except FileNotFoundError:
            return None
        return dst

    def clean_tmp(self, max_age_s: float = 86400.0) -> int:
        """Remove temporaries of dead runners on this host, and any older than ``max_age_s``.

        Other shards (other pids, other hosts) may be writing their own at this moment.
        """
        removed = 0
        now = time.time()
        candidates: list[Path] = []
        if self.tmp_dir.is_dir():
            candidates += list(self.tmp_dir.iterdir())
        for d in (self.results_dir, self.fields_dir):
            if d.is_dir():
                candidates += [p for p in d.iterdir() if p.name.startswith(".")]
        for p in candidates:
            parts = p.name.split("~")
            dead = False
            if len(parts) >= 4 and parts[1] == self.host:
                try:
                    os.kill(int(parts[2]), 0)
                except ProcessLookupError:
                    dead = True
                except (ValueError, PermissionError):
                    pass
            try:
                old = now - p.stat().st_mtime > max_age_s
            except FileNotFoundError:
                continue
            if dead or old:
                try:
                    p.unlink()
                    removed += 1
                except (FileNotFoundError, IsADirectoryError):
                    pass
        return removed

    # ---- writing ------------------------------------------------------------------------
    def _write_fields(
        self, out: SolverOutput, job_id: str, geometry_id: str, fields: str
    ) -> tuple[str, int, str]:
        """Write the job's HDF5 fields (and the geometry's mesh once); returns names and size."""
        import h5py

        stage_groups = sorted(
            int(g.split("_", 1)[1]) for g in out.attrs["_groups"] if re.fullmatch(r"stage_\d+", g)
        )
        stage_groups = [k for k in stage_groups if k in out.stages]
        keep = stage_groups if fields == "all" else stage_groups[-1:]
        if not keep:
            return "", 0, ""
        mesh_name = ""
        with h5py.File(out.path, "r") as src:
            embed_mesh = False
            if "mesh" in src:
                digest = _mesh_digest(src["mesh"])
                mesh_path = self.fields_dir / f"mesh-{geometry_id}.h5"
                existing = _mesh_file_digest(mesh_path)
                if existing is None:
                    atomic_write(
                        mesh_path, lambda tmp: _write_mesh(tmp, src["mesh"], digest, geometry_id)
                    )
                    existing = digest
                if existing == digest:
                    mesh_name = mesh_path.name
                else:  # a job whose mesh differs from the geometry's stored one keeps its own
                    embed_mesh = True

            def write(tmp: str) -> None:
                with h5py.File(tmp, "w") as dst:
                    for k, v in out.attrs.items():
                        if not k.startswith("_"):
                            dst.attrs[k] = v
                    dst.attrs["stored_stages"] = json.dumps(keep)
                    dst.attrs["mesh_file"] = mesh_name
                    if embed_mesh:
                        g = dst.create_group("mesh")
                        for name, ds in src["mesh"].items():
                            _copy_dataset(ds, g, name)
                    for k in keep:
                        g = dst.create_group(f"stage_{k}")
                        for name, ds in src[f"stage_{k}"].items():
                            _copy_dataset(ds, g, name)

            path = self.fields_dir / f"{job_id}.h5"
            atomic_write(path, write)
        return path.name, path.stat().st_size, mesh_name

    def write_job(
        self,
        job: dict[str, Any],
        outcome: JobOutcome,
        stages: tuple[int, int],
        fields: str,
        shard: str,
    ) -> Path:
        """Write the job's fields, then its Parquet rows (that order: see the module doc)."""
        self.ensure_dirs()
        job_id = str(job["job_id"])
        fields_file, fields_bytes, mesh_file = "", 0, ""
        out = outcome.output
        if out is not None and fields != "none":
            fields_file, fields_bytes, mesh_file = self._write_fields(
                out, job_id, str(job["geometry_id"]), fields
            )
        failed_stage = None
        if outcome.failure_class == "not-converged" and out is not None:
            bad = [k for k in sorted(out.stages) if out.stages[k].get("status") != "converged"]
            failed_stage = bad[0] if bad else None
        attrs = out.attrs if out is not None else {}
        base: dict[str, Any] = {}
        for name in MANIFEST_COLUMNS:
            v = job[name]
            base[name] = v.item() if isinstance(v, np.generic) else v
        common = {
            "failure_class": outcome.failure_class,
            "failed_stage": failed_stage,
            "failure_detail": outcome.failure_detail,
            "exit_code": outcome.exit_code,
            "attempts": outcome.attempts,
            "job_wall_time_s": outcome.wall_time_s,
            "job_cpu_time_s": outcome.cpu_time_s,
            "total_wall_time_s": outcome.total_wall_time_s,
            "total_cpu_time_s": outcome.total_cpu_time_s,
            "max_rss_MiB": outcome.max_rss_MiB,
            "started_at_utc": _utc(outcome.started_at),
            "finished_at_utc": _utc(outcome.finished_at),
            "host": self.host,
            "shard": shard,
            "stages_requested": f"{stages[0]}-{stages[1]}",
            "fields": fields,
            "fields_file": fields_file,
            "mesh_file": mesh_file,
            "woundsweep_version": str(attrs.get("woundsweep_version", __version__)),
            "dolfinx_version": attrs.get("dolfinx_version"),
            "python_version": sys.version.split()[0],
            "jit_time_s": _float_or_none(attrs.get("jit_time_s")),
        }
        rows = []
        for k in range(stages[0], stages[1] + 1):
            sr = dict(out.stages.get(k, {})) if out is not None else {}
            row = dict(base)
            row["stage"] = k
            row["status"] = sr.pop("status", "not-run")
            sr.pop("stage", None)
            for name in STAGE_FIELDS:
                v = sr.pop(name, None)
                row[name] = None if v is None or (isinstance(v, float) and np.isnan(v)) else v
            row["stage_extra_json"] = json.dumps(sr, sort_keys=True) if sr else None
            row.update(common)
            rows.append(row)
        table = pa.Table.from_pylist(rows, schema=result_schema())
        meta = {
            "format": FORMAT_VERSION,
            "job_id": job_id,
            "job_index": int(base["job_index"]),
            "stages": list(stages),
            "failure_class": outcome.failure_class,
            "fields_file": fields_file,
            "fields_bytes": fields_bytes,
            "mesh_file": mesh_file,
            "sha256": _content_digest(table),
        }
        table = table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
        path = self.result_path(job_id)
        atomic_write(path, lambda tmp: pq.write_table(table, tmp, write_page_checksum=True))
        return path


def _write_mesh(tmp: str, mesh: Any, digest: str, geometry_id: str) -> None:
    import h5py

    with h5py.File(tmp, "w") as dst:
        dst.attrs["geometry_id"] = geometry_id
        dst.attrs["mesh_sha256"] = digest
        g = dst.create_group("mesh")
        for name, ds in mesh.items():
            _copy_dataset(ds, g, name)


def _mesh_file_digest(path: Path) -> str | None:
    import h5py

    if not path.exists():
        return None
    try:
        with h5py.File(path, "r") as f:
            return str(_attr(f.attrs["mesh_sha256"]))
    except (OSError, KeyError):
        return None  # damaged: rewritten (atomically) by the next job of this geometry


def _validate_result_file(path: Path, job_id: str | None, run_dir: Path) -> dict[str, Any]:
    """Read a whole result file with page checksums; returns its footer record."""
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
    if meta["sha256"] != _content_digest(table):
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
    """All result rows of a run (empty frame with the result columns if none).

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
            meta = _validate_result_file(p, p.name[4:-8], run_dir)
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
    by_class = {c: int((jobs["failure_class"] == c).sum()) for c in FAILURE_CLASSES}
    by_stage: dict[str, dict[str, int]] = {}
    for stage, g in rows.groupby("stage", sort=True):
        counts = g["status"].value_counts()
        by_stage[str(int(stage))] = {s: int(counts.get(s, 0)) for s in STAGE_STATUSES}
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

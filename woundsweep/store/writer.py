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

Parquet files carry page checksums and a footer record that resume validation checks
(`woundsweep.store.reader`, which also holds `read_results`, the validated reader): the
result's fingerprint (`woundsweep.store.identity`; another one means stale: redone) and the
sha256 of its fields and mesh files (another one means damaged: the files go to corrupt/ and
the job is redone). HDF5 datasets are float32 (coordinates float64), gzip-compressed with
Fletcher-32 checksums.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .. import __version__
from ..config.manifest import JobRow, load_run
from ..config.sweep import MANIFEST_COLUMNS, Sweep, load_sweep
from ..core.diagnostics import StageReport
from ..core.errors import StoreError
from ..core.fsutil import atomic_write
from ..core.schema import FailureClass, ResultState, StageResult, StageStatus
from ..core.versions import RESULT_FORMAT_VERSION
from .identity import file_sha256, fingerprints, result_fingerprint
from .reader import (
    META_KEY,
    check_result,
    content_digest,
    read_footer,
    result_schema,
    store_file_names,
)
from .solverfile import MESH_DATASETS, MESH_GROUP, SolverOutput, stage_group, stage_of_group

__all__ = [
    "FIELDS_CHOICES",
    "AttemptOutcome",
    "JobState",
    "Store",
]

FIELDS_CHOICES = ("all", "final", "none")


class AttemptOutcome(NamedTuple):
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
    """Resume bookkeeping for one job: its `ResultState`, stored failure class and why."""

    state: ResultState
    failure_class: str | None = None
    reason: str = ""


def _float_or_none(value: Any) -> float | None:
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _utc(ts: float) -> _dt.datetime:
    return _dt.datetime.fromtimestamp(ts, tz=_dt.timezone.utc)


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
    for name in MESH_DATASETS:
        if name in mesh:
            arr = np.ascontiguousarray(mesh[name][()])
            h.update(name.encode() + str(arr.dtype).encode() + str(arr.shape).encode())
            h.update(arr.tobytes())
    return h.hexdigest()


class Store:
    """Paths, atomic writes and resume validation for one run directory."""

    def __init__(self, run_dir: str | Path, sweep: Sweep | None = None) -> None:
        self.run_dir = Path(run_dir)
        self._sweep = sweep
        self._expected: dict[str, str] | None = None
        self._memo: dict = {}
        self.results_dir = self.run_dir / "results"
        self.fields_dir = self.run_dir / "fields"
        self.logs_dir = self.run_dir / "logs"
        self.tmp_dir = self.run_dir / "tmp"
        self.corrupt_dir = self.run_dir / "corrupt"
        self.host = socket.gethostname()

    def ensure_dirs(self) -> None:
        dirs = (self.results_dir, self.fields_dir, self.logs_dir, self.tmp_dir)
        for d in dirs:  # all checked before any is made: a refused run changes nothing
            if d.exists() and not d.is_dir():
                raise StoreError(f"{d}: exists and is not a directory (move it away)")
        for d in dirs:
            d.mkdir(parents=True, exist_ok=True)

    def result_path(self, job_id: str) -> Path:
        return self.results_dir / f"job-{job_id}.parquet"

    def log_path(self, job_id: str) -> Path:
        return self.logs_dir / f"job-{job_id}.log"

    def tmp_path(self, job_id: str, attempt: int, suffix: str = ".h5") -> Path:
        """A per-attempt temporary file named after this host and runner pid (see clean_tmp)."""
        return self.tmp_dir / f"{job_id}~{self.host}~{os.getpid()}~{attempt}{suffix}"

    @property
    def sweep(self) -> Sweep:
        """The run's sweep (its settings make the results' fingerprints)."""
        if self._sweep is None:
            self._sweep = load_sweep(self.run_dir / "sweep.yaml")
        return self._sweep

    def fingerprint(self, job: JobRow) -> str:
        return result_fingerprint(self.sweep, job)

    # ---- resume bookkeeping -------------------------------------------------------------
    def job_state(
        self, job_id: str, stages: tuple[int, int], fingerprint: str | None = None
    ) -> JobState:
        """Is the job's result present, valid, current, with intact files, covering ``stages``?

        ``fingerprint`` defaults to the one the run's manifest and sweep give the job.
        """
        path = self.result_path(job_id)
        if not path.exists():
            return JobState(ResultState.MISSING)
        if fingerprint is None:
            if self._expected is None:
                run = load_run(self.run_dir)
                self._expected = fingerprints(run.sweep, run.manifest)
            fingerprint = self._expected.get(job_id)
        chk = check_result(path, job_id, self.run_dir, fingerprint, memo=self._memo)
        meta = chk.meta or {}
        if chk.state != ResultState.DONE:
            return JobState(chk.state, meta.get("failure_class"), chk.reason)
        lo, hi = meta["stages"]
        if lo > stages[0] or hi < stages[1]:
            return JobState(ResultState.STALE, meta["failure_class"], f"has stages {lo}-{hi}")
        return JobState(ResultState.DONE, meta["failure_class"])

    def quarantine(self, job_id: str, files: bool = False) -> Path | None:
        """Move a result file that failed validation to RUN_DIR/corrupt/ (kept for inspection).

        With ``files`` its fields file and a mesh file whose checksum differs go there too.
        """
        src = self.result_path(job_id)
        self.corrupt_dir.mkdir(parents=True, exist_ok=True)
        stamp = int(time.time())
        if files:
            meta = read_footer(src) or {}  # a damaged footer names no files to move
            try:  # only the store's own plain names: a crafted footer moves nothing outside
                names = store_file_names(meta, job_id)
            except StoreError:
                names = ("", "")
            for name, key in zip(names, ("fields_sha256", "mesh_sha256")):
                f = self.fields_dir / name
                if name and f.is_file():
                    if key == "mesh_sha256" and file_sha256(f) == meta.get(key):
                        continue  # the geometry's mesh is intact: other jobs use it
                    os.replace(f, self.corrupt_dir / f"{f.name}.{stamp}")
        dst = self.corrupt_dir / f"{src.name}.{stamp}"
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
        """Write the job's HDF5 fields (and the geometry's mesh once); returns names and size.

        A mesh file that does not open is replaced (its jobs' checksums then differ: redone).
        """
        import h5py

        groups = (stage_of_group(g) for g in out.attrs["_groups"])
        stage_groups = sorted(k for k in groups if k is not None and k in out.stages)
        keep = stage_groups if fields == "all" else stage_groups[-1:]
        if not keep:
            return "", 0, ""
        mesh_name = ""
        with h5py.File(out.path, "r") as src:
            embed_mesh = False
            if MESH_GROUP in src:
                digest = _mesh_digest(src[MESH_GROUP])
                mesh_path = self.fields_dir / f"mesh-{geometry_id}.h5"
                existing = _mesh_file_digest(mesh_path)
                if existing is None:
                    atomic_write(
                        mesh_path,
                        lambda tmp: _write_mesh(tmp, src[MESH_GROUP], digest, geometry_id),
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
                        g = dst.create_group(MESH_GROUP)
                        for name, ds in src[MESH_GROUP].items():
                            _copy_dataset(ds, g, name)
                    for k in keep:
                        g = dst.create_group(stage_group(k))
                        for name, ds in src[stage_group(k)].items():
                            _copy_dataset(ds, g, name)

            path = self.fields_dir / f"{job_id}.h5"
            atomic_write(path, write)
        return path.name, path.stat().st_size, mesh_name

    def _sha(self, name: str) -> str | None:
        return file_sha256(self.fields_dir / name) if name else None

    def write_job(
        self,
        job: JobRow,
        outcome: AttemptOutcome,
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
        if outcome.failure_class == FailureClass.NOT_CONVERGED and out is not None:
            bad = [k for k in sorted(out.stages) if out.stages[k].status != StageStatus.CONVERGED]
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
            "result_fingerprint": self.fingerprint(job),
            "fields_file_sha256": self._sha(fields_file),
            "mesh_file_sha256": self._sha(mesh_file),
        }
        rows = []
        for k in range(stages[0], stages[1] + 1):
            report = out.stages.get(k) if out is not None else None
            if report is None:
                report = StageReport(StageResult(k, StageStatus.NOT_RUN.value), {})
            row = dict(base)
            row.update(report.result._asdict())
            row["stage"] = k
            row["stage_extra_json"] = report.diagnostics_json()
            row.update(common)
            rows.append(row)
        table = pa.Table.from_pylist(rows, schema=result_schema())
        meta = {
            "format": RESULT_FORMAT_VERSION,
            "job_id": job_id,
            "job_index": int(base["job_index"]),
            "stages": list(stages),
            "failure_class": outcome.failure_class,
            "fields_file": fields_file,
            "fields_bytes": fields_bytes,
            "fields_sha256": common["fields_file_sha256"],
            "mesh_file": mesh_file,
            "mesh_sha256": common["mesh_file_sha256"],
            "fingerprint": common["result_fingerprint"],
            "sha256": content_digest(table),
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
        g = dst.create_group(MESH_GROUP)
        for name, ds in mesh.items():
            _copy_dataset(ds, g, name)


def _mesh_file_digest(path: Path) -> str | None:
    import h5py

    if not path.exists():
        return None
    try:
        with h5py.File(path, "r") as f:
            value = f.attrs["mesh_sha256"]
    except (OSError, KeyError):
        return None  # damaged: rewritten (atomically) by the next job of this geometry
    return value.decode() if isinstance(value, bytes) else str(value)

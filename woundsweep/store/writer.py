"""Writing a job's result to the store crash-safely: its HDF5 fields, then its Parquet rows.

Crash safety: every file is written to a temporary name (a dot file in the same directory,
which pyarrow ignores), flushed, fsynced and moved into place with ``os.replace``; a reader
sees the old file or the whole new one. The fields of a job are written before its Parquet
file, so "Parquet file present and valid" means the job is complete, fields included (the
resume rule, `woundsweep.store.triage`). A job owns exactly one Parquet file, so a rerun or
two shards racing on one job replace it and never duplicate rows;
``pandas.read_parquet("RUN_DIR/results")`` reads the whole store. Failed jobs get rows too
(status ``not-run`` for stages without a result), so counts by ``failure_class`` come
straight from the store. Each row carries its stage's diagnostics, one typed column each
(`woundsweep.core.diagnostics`), and the job's ``element_degree``.

Parquet files carry page checksums and a footer record that resume validation checks
(`woundsweep.store.reader`, which also holds `read_results`, the validated reader): the
result's fingerprint (`woundsweep.store.identity`; another one means stale: redone) and the
sha256 of its fields and mesh files (another one means damaged: the files go to corrupt/ and
the job is redone). HDF5 datasets are float32 (coordinates float64), gzip-compressed with
Fletcher-32 checksums. Where the files go: `woundsweep.store.paths`.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import sys
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .. import __version__
from ..config.geometry import GeometrySpec
from ..config.manifest import JobRow, job_geometry
from ..config.sweep import MANIFEST_COLUMNS
from ..core.diagnostics import StageReport
from ..core.fsutil import atomic_write
from ..core.schema import FailureClass, StageResult, StageStatus
from ..core.versions import RESULT_FORMAT_VERSION
from .identity import file_sha256
from .reader import META_KEY, content_digest, result_schema
from .solverfile import MESH_DATASETS, MESH_GROUP, SolverOutput, stage_group, stage_of_group
from .triage import JobState, StoreTriage

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


class Store(StoreTriage):
    """One run directory's store: its paths (`StorePaths`), resume triage (`StoreTriage`)
    and the atomic writing of a job's result."""

    # ---- writing ------------------------------------------------------------------------
    def _write_fields(
        self, out: SolverOutput, job_id: str, spec: GeometrySpec, fields: str
    ) -> tuple[str, int, str]:
        """Write the job's HDF5 fields (and the mesh of ``spec`` once); returns names and size.

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
                mesh_path = self.layout.mesh_file(spec.mesh_id)
                existing = _mesh_file_digest(mesh_path)
                if existing is None:
                    atomic_write(
                        mesh_path, lambda tmp: _write_mesh(tmp, src[MESH_GROUP], digest, spec)
                    )
                    existing = digest
                if existing == digest:
                    mesh_name = mesh_path.name
                else:  # a job whose mesh differs from the stored one of its id keeps its own
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
                    for stage in keep:
                        g = dst.create_group(stage_group(stage))
                        for name, ds in src[stage_group(stage)].items():
                            _copy_dataset(ds, g, name)

            path = self.layout.fields_file(job_id)
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
                out, job_id, job_geometry(self.sweep, job), fields
            )
        failed_stage = None
        if outcome.failure_class == FailureClass.NOT_CONVERGED and out is not None:
            bad = [k for k in sorted(out.stages) if out.stages[k].status != StageStatus.CONVERGED]
            failed_stage = bad[0] if bad else None
        attrs = out.attrs if out is not None else {}
        base: dict[str, Any] = {}
        for name in MANIFEST_COLUMNS:
            v = job[name]  # type: ignore[literal-required]  # the manifest columns: JobRow keys
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
        degree = int(self.sweep.solver.element_degree)  # the job's, where the solver gave none
        rows = []
        for k in range(stages[0], stages[1] + 1):
            report = out.stages.get(k) if out is not None else None
            if report is None:
                report = StageReport(StageResult(k, StageStatus.NOT_RUN.value), {})
            row = dict(base)
            row.update(report.result._asdict())
            row["stage"] = k
            if row["element_degree"] is None:
                row["element_degree"] = degree
            row.update(report.diagnostic_columns())
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
        }
        return self.commit_rows(table, meta)

    def commit_rows(self, table: pa.Table, meta: dict[str, Any]) -> Path:
        """Write job ``meta["job_id"]``'s result rows with footer ``meta`` (its content
        ``sha256`` is added here), atomically: the last step of storing a job."""
        meta = {**meta, "sha256": content_digest(table)}
        table = table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
        path = self.result_path(str(meta["job_id"]))
        atomic_write(path, lambda tmp: _write_parquet(table, tmp))
        return path


def _write_parquet(table: pa.Table, tmp: str) -> None:
    sink = pa.BufferOutputStream()  # bytes written by Python: pyarrow takes a path (or a
    pq.write_table(table, sink, write_page_checksum=True)  # file's name) as UTF-8 only
    with open(tmp, "wb") as fh:
        fh.write(memoryview(sink.getvalue()))


def _write_mesh(tmp: str, mesh: Any, digest: str, spec: GeometrySpec) -> None:
    import h5py

    with h5py.File(tmp, "w") as dst:
        dst.attrs["mesh_id"] = spec.mesh_id
        dst.attrs["element_degree"] = spec.element_degree
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

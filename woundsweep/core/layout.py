"""The files and directories of a run directory, named in one place.

Layout::

    RUN_DIR/sweep.yaml, manifest.parquet, provenance.json   written by `generate`
    RUN_DIR/run.lock                        held by runners and `generate` (`runlock`)
    RUN_DIR/results/job-<job_id>.parquet    one row per requested stage of the job
    RUN_DIR/fields/<job_id>.h5              the job's stored fields
    RUN_DIR/fields/mesh-<mesh_id>.h5        the mesh its jobs share (`GeometrySpec.mesh_id`)
    RUN_DIR/logs/job-<job_id>.log           the job's stdout/stderr
    RUN_DIR/tmp/, corrupt/                  solver outputs in flight, results moved aside
    RUN_DIR/meshes/<mesh_id>.npz            the mesh cache (`woundsweep.mesh.cache`)
    RUN_DIR/solve/job_<N>.h5                `woundsweep solve` without ``--out``
    RUN_DIR/analysis/, atlas/, convergence/, slurm/   what `analyze`, `atlas`, `converge`
                                            and `slurm` write
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import TYPE_CHECKING

__all__ = [
    "ANALYSIS_METRICS",
    "ANALYSIS_REPORT",
    "FIELDS_NAME",
    "MESH_NAME",
    "RESULT_NAME",
    "RunLayout",
]

# The names the store gives its result files; anything else in results/ is not the store's.
RESULT_NAME = re.compile(r"job-([0-9a-f]{16})\.parquet")
# The names a result's footer may give its fields and mesh files: plain names in fields/.
FIELDS_NAME = re.compile(r"[0-9a-f]{16}\.h5")
MESH_NAME = re.compile(r"mesh-[0-9a-f]{16}\.h5")
# The analysis' summary files (in RUN_DIR/analysis/ or the directory `analyze` is given).
ANALYSIS_METRICS = "metrics.json"
ANALYSIS_REPORT = "report.md"


class _Below:
    """A fixed path below the run directory, read as an attribute of a `RunLayout`."""

    def __init__(self, *parts: str) -> None:
        self.parts = parts

    def __get__(self, layout: RunLayout, owner: type | None = None) -> Path:
        return layout.run_dir.joinpath(*self.parts)


@dataclasses.dataclass(frozen=True)
class RunLayout:
    """The paths of one run directory (nothing is read or made here)."""

    run_dir: Path

    if TYPE_CHECKING:  # the generated __init__, as `__post_init__` makes it: a str is taken too

        def __init__(self, run_dir: str | Path) -> None: ...

    def __post_init__(self) -> None:  # a str is taken too
        object.__setattr__(self, "run_dir", Path(self.run_dir))

    # what `generate` writes, and the lock
    sweep = _Below("sweep.yaml")
    manifest = _Below("manifest.parquet")
    provenance = _Below("provenance.json")
    lock = _Below("run.lock")
    # the result store
    results_dir = _Below("results")
    fields_dir = _Below("fields")
    logs_dir = _Below("logs")
    tmp_dir = _Below("tmp")
    corrupt_dir = _Below("corrupt")
    # caches and the commands' outputs
    meshes_dir = _Below("meshes")
    solve_dir = _Below("solve")
    analysis_dir = _Below("analysis")
    analysis_metrics = _Below("analysis", ANALYSIS_METRICS)
    analysis_report = _Below("analysis", ANALYSIS_REPORT)
    atlas_dir = _Below("atlas")
    convergence_dir = _Below("convergence")
    slurm_dir = _Below("slurm")

    def is_run(self) -> bool:
        """Whether the directory holds a sweep copy and a manifest (`generate` made it)."""
        return self.manifest.is_file() and self.sweep.is_file()

    def result_file(self, job_id: str) -> Path:
        return self.results_dir / f"job-{job_id}.parquet"

    def fields_file(self, job_id: str) -> Path:
        return self.fields_dir / f"{job_id}.h5"

    def mesh_file(self, mesh_id: str) -> Path:
        """The stored mesh of a mesh id (the fields files of its jobs refer to it)."""
        return self.fields_dir / f"mesh-{mesh_id}.h5"

    def log_file(self, job_id: str) -> Path:
        return self.logs_dir / f"job-{job_id}.log"

    def mesh_cache_file(self, mesh_id: str) -> Path:
        return self.meshes_dir / f"{mesh_id}.npz"

    def solve_file(self, job_index: int) -> Path:
        """Where `woundsweep solve` writes a job without ``--out``."""
        return self.solve_dir / f"job_{int(job_index)}.h5"

    @property
    def own_dirs(self) -> tuple[Path, ...]:
        """The directories the run's commands write (a site or copy must not go there)."""
        return (
            self.results_dir, self.fields_dir, self.logs_dir, self.meshes_dir, self.tmp_dir,
            self.corrupt_dir, self.analysis_dir, self.slurm_dir,
        )  # fmt: skip

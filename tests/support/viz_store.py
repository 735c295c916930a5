"""A small real run directory with fields, for the viz tests (gmsh, no DOLFINx).

`make_store` generates a one-geometry sweep (a coarse wedge wound, three skin types x two
orientations = six jobs), meshes it into the mesh cache, and stores through `Store.write_job` solver files
written by `write_solver_file` with known fields (`displacement`, `von_mises`):

- job 0: converged, six stages, ``--fields all``;
- job 1: not converged at stage 4 (max-iterations), ``--fields final``: stage 3 kept,
  stages 1-2 not kept, 5-6 not run;
- job 2: converged, six stages, ``--fields none``;
- jobs 3-5: no result stored (pending).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from woundsweep.config.manifest import expand, job_geometry
from woundsweep.config.sweep import parse_sweep
from woundsweep.core.diagnostics import StageReport
from woundsweep.core.schema import ExitCode, FailureClass, StageStatus
from woundsweep.mesh.cache import get_mesh
from woundsweep.store.solverfile import read_solver_file, write_solver_file
from woundsweep.store.writer import AttemptOutcome, Store

__all__ = ["SWEEP", "displacement", "make_store", "von_mises"]

SWEEP = {
    "name": "viz-test",
    "grid": {
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
        "wound_width_factor": [0.5],
        "mesh_size_factor": [0.3],
        "skin_type": ["normal", "stiff", "soft"],
        "orientation_deg": [0, 90],
    },
    "shapes": {"wedge": {"wound_depth_factor": [0.3]}},
    "solver": {"element_degree": 1},
}


def displacement(points: np.ndarray, stage: int, job: int) -> np.ndarray:
    """A known displacement field (mm): smooth, different per stage and job."""
    x, y, z = points.T
    s = 0.01 * stage * (1 + job)
    return np.c_[s * np.sin(x), -s * y * z, s * (x + 2 * y)]


def von_mises(points: np.ndarray, cells: np.ndarray, stage: int, job: int) -> np.ndarray:
    """A known cellwise von Mises field (kPa) from the cells' midpoints."""
    mid = points[cells].mean(axis=1)
    return 10.0 * stage + (1 + job) * (mid[:, 0] ** 2 + np.abs(mid[:, 1])) - mid[:, 2]


def _row(stage: int, status: str, vm: np.ndarray | None, cells: int) -> dict:
    r = {"stage": stage, "status": status, "cells": cells, "dofs": 3 * 100}
    if vm is not None:
        r.update(
            p99_von_mises_kPa=float(np.percentile(vm, 99)),
            max_von_mises_kPa=float(vm.max()),
            newton_iterations=5,
            time_s=0.5,
        )
    return r


def _outcome(cls: str, out, code: int) -> AttemptOutcome:
    return AttemptOutcome(cls, "", code, 1, 1.0, 1.0, 1.0, 1.0, None, 0.0, 1.0, out)


def make_store(run_dir: str | Path) -> Path:
    """Write the run directory described in the module docstring; returns it."""
    rd = Path(run_dir)
    rd.mkdir(parents=True, exist_ok=True)
    (rd / "sweep.yaml").write_text(yaml.safe_dump(SWEEP, sort_keys=False))
    sweep = parse_sweep(SWEEP, str(rd / "sweep.yaml"))
    manifest = expand(sweep)
    manifest.to_parquet(rd / "manifest.parquet", index=False)
    store = Store(rd)
    store.ensure_dirs()
    for job in manifest.to_dict("records")[:3]:
        j = int(job["job_index"])
        mesh = get_mesh(rd, job_geometry(sweep, job)).mesh
        n_cells = len(mesh.cells)
        last = 3 if j == 1 else 6
        fields = {
            k: (
                displacement(mesh.points, k, j).astype(np.float32),
                von_mises(mesh.points, mesh.cells, k, j).astype(np.float32),
            )
            for k in range(1, last + 1)
        }
        rows = [_row(k, StageStatus.CONVERGED.value, fields[k][1], n_cells) for k in fields]
        if j == 1:
            rows.append(_row(4, StageStatus.MAX_ITERATIONS.value, None, n_cells))
        path = rd / "tmp" / f"{job['job_id']}.h5"
        attrs = {"job_id": job["job_id"], "job_index": j, "geometry_id": job["geometry_id"]}
        write_solver_file(path, attrs, mesh, [StageReport.from_row(r) for r in rows], fields)
        out = read_solver_file(path, job["job_id"], (1, 6))
        if j == 1:
            outcome = _outcome(FailureClass.NOT_CONVERGED.value, out, int(ExitCode.NOT_CONVERGED))
        else:
            outcome = _outcome(FailureClass.CONVERGED.value, out, int(ExitCode.OK))
        store.write_job(job, outcome, (1, 6), ("all", "final", "none")[j], "0/1")
        store.log_path(job["job_id"]).write_text(f"job {j} log line\n" * 3)
    return rd

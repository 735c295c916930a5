"""Solver outputs and job outcomes written by tests, for the result-store tests.

`solver_file` writes an HDF5 file in the format docs/design.md fixes for `woundsweep solve
--out`; `outcome` is a `AttemptOutcome` of a given failure class; `store_converged` stores one
manifest job as converged through `Store.write_job`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pandas as pd

from woundsweep.config.manifest import load_run
from woundsweep.store.solverfile import read_solver_file
from woundsweep.store.writer import AttemptOutcome, Store


def manifest(rd: Path) -> pd.DataFrame:
    return load_run(rd).manifest


def solver_file(
    path: Path,
    job: pd.Series,
    stages: range,
    fail_at: int | None = None,
    mesh_seed: int = 0,
    reopened_at: int | None = None,
) -> dict[int, dict[str, Any]]:
    """Write a solver output per docs/design.md; returns the stage results written."""
    rng = np.random.default_rng(int(job["job_index"]) + 100)
    mesh_rng = np.random.default_rng(mesh_seed)
    n, m = 40, 90
    results, ok = {}, True
    with h5py.File(path, "w") as f:
        for k, v in {
            "job_id": job["job_id"], "job_index": int(job["job_index"]),
            "geometry_id": job["geometry_id"], "woundsweep_version": "0.1.0",
            "dolfinx_version": "0.5.2", "units": "mm, kPa, mN, s",
        }.items():  # fmt: skip
            f.attrs[k] = v
        f["mesh/points"] = mesh_rng.random((n, 3))
        f["mesh/cells"] = mesh_rng.integers(0, n, (m, 4))
        f["mesh/cell_tags"] = np.where(np.arange(m) < 50, 1, 2).astype(np.int32)
        for k in stages:
            if not ok:
                results[k] = {"stage": k, "status": "not-run"}
                continue
            status = "diverged" if k == fail_at else "converged"
            ok = status == "converged"
            f[f"stage_{k}/displacement_mm"] = rng.random((n, 3))  # float64: store makes float32
            f[f"stage_{k}/von_mises_kPa"] = rng.random(m)
            results[k] = {
                "stage": k, "status": status, "newton_iterations": 3 + k, "time_s": 0.5 * k,
                "p99_von_mises_kPa": 10.0 * k, "p99_von_mises_nodal_kPa": 11.0 * k,
                "max_von_mises_kPa": 20.0 * k, "max_location_x_mm": 0.1, "max_location_y_mm": 0.2,
                "max_location_z_mm": -0.3, "closure_gap_max_mm": 0.01 * k, "min_J": 0.8,
                "n_penetrating": 0, "max_penetration_mm": 0.0, "contact_force_mN": 0.0,
                "residual_norm": 1e-9, "dofs": 3 * n, "cells": m,
                "closed": None if k == 1 else int(k != reopened_at),
                # Diagnostics: a count on every stage, a force from stage 2 on.
                "load_increments": k, "pin_reaction_max_mN": None if k == 1 else 0.25 * k,
            }  # fmt: skip
        f.attrs["stage_results"] = json.dumps(list(results.values()))
    return results


def outcome(cls: str, output: Any = None, attempts: int = 1, cpu: float = 10.0) -> AttemptOutcome:
    now = time.time()
    return AttemptOutcome(
        failure_class=cls,
        failure_detail="" if cls == "converged" else f"{cls} for the test",
        exit_code={"converged": 0, "not-converged": 3, "invalid": 2}.get(cls),
        attempts=attempts,
        wall_time_s=cpu + 1,
        cpu_time_s=cpu,
        total_wall_time_s=attempts * (cpu + 1),
        total_cpu_time_s=attempts * cpu,
        max_rss_MiB=300.0,
        started_at=now - cpu - 1,
        finished_at=now,
        output=output,
    )


def store_converged(
    rd: Path, i: int, fields: str = "final", stages=(1, 6), tag: str = "", **kw: Any
) -> Path:
    """Manifest job ``i`` stored as converged from a solver file written beside the run."""
    job = manifest(rd).iloc[i]
    src = rd / f"solver-{i}{tag}.h5"
    solver_file(src, job, range(stages[0], stages[1] + 1), **kw)
    out = read_solver_file(src, job["job_id"], stages)
    return Store(rd).write_job(job.to_dict(), outcome("converged", out), stages, fields, "0/1")

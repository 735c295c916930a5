"""Synthetic result stores in the real run-directory layout, for the analysis tests.

`write_store` expands a sweep with `woundsweep.grid` (so the manifest is the real one),
writes ``RUN_DIR/sweep.yaml`` and ``RUN_DIR/manifest.parquet``, and writes one row per job
and stage (manifest columns + ``stage``, ``status``, ``failure_class`` and the `StageResult`
fields of docs/design.md) as Parquet shards under ``RUN_DIR/results/``. The stress is
whatever function the caller passes, so tests know the truth the model should find.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from woundsweep.grid import expand, parse_sweep

__all__ = [
    "SMALL_SWEEP",
    "STAGE_RESULT_COLUMNS",
    "depth_level",
    "depth_stress",
    "random_stress",
    "write_store",
]

STAGE_RESULT_COLUMNS = (
    "stage", "status", "newton_iterations", "time_s", "p99_von_mises_kPa",
    "p99_von_mises_nodal_kPa", "max_von_mises_kPa", "max_location_x_mm", "max_location_y_mm",
    "max_location_z_mm", "closure_gap_mm", "min_J", "n_penetrating", "max_penetration_mm",
    "contact_force_mN", "residual_norm", "dofs", "cells",
)  # fmt: skip

# 2 thicknesses x 3 subcutis x 6 (patch, width) pairs x 3 third factors x 2 shapes = 216
# geometries x 3 skins x 3 orientations = 1,944 jobs x 6 stages = 11,664 rows.
SMALL_SWEEP: dict[str, Any] = {
    "name": "synthetic",
    "grid": {
        "dermal_thickness_mm": [1, 2],
        "subcutis_thickness_factor": [0.5, 1, 2],
        "patch_size_factor": [1, 2, 3],
        "wound_width_factor": [0.3, 0.5, 0.8],
        "mesh_size_factor": [0.5],
        "skin_type": ["normal", "stiff", "soft"],
        "orientation_deg": [0, 45, 90],
    },
    "shapes": {
        "cylindrical": {"wound_aspect_factor": [0, 0.1, 0.2]},
        "wedge": {"wound_depth_factor": [0.3, 0.5, 0.7]},
    },
    "exclude": ["wound_width_mm > total_thickness_mm"],
}

StressFn = Callable[[pd.DataFrame, np.random.Generator], np.ndarray]


def depth_level(df: pd.DataFrame) -> np.ndarray:
    """0.3 / 0.5 / 0.7 from the wedge depth factor or, for cylinders, 0.7 - 2 * aspect.

    A larger cylinder offset gives a shallower wound, so both shapes map onto one depth scale.
    """
    wedge = df["wound_shape"].to_numpy() == "wedge"
    return np.where(wedge, df["wound_depth_factor"], 0.7 - 2.0 * df["wound_aspect_factor"])


def depth_stress(df: pd.DataFrame, rng: np.random.Generator, noise: float = 0.05) -> np.ndarray:
    """Stress that depends on the wound depth (strongly) and the stage (weakly), plus noise."""
    d = depth_level(df)
    return (
        20.0
        * np.exp(3.0 * d)
        * (1.0 + 0.05 * (df["stage"] - 1))
        * rng.lognormal(0.0, noise, len(df))
    )


def random_stress(df: pd.DataFrame, rng: np.random.Generator) -> np.ndarray:
    """Stress unrelated to any parameter."""
    return rng.lognormal(4.0, 1.0, len(df))


def _locations(df: pd.DataFrame, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Plausible max locations (mm): stage 2 at the closure-zone ends, others near the edges."""
    n = len(df)
    L = df["patch_half_length_mm"].to_numpy()
    w = df["wound_width_mm"].to_numpy()
    T = df["total_thickness_mm"].to_numpy()
    stage = df["stage"].to_numpy()
    y = np.where(
        stage == 2,
        rng.choice([-1.0, 1.0], n) * L / 3 + rng.normal(0, 0.05, n) * L,
        rng.uniform(-L, L),
    )
    edge = np.where(rng.random(n) < 0.5, 0.0, w)
    x = edge + rng.normal(0, 0.1, n) * L
    z = -np.abs(rng.normal(0, 0.15, n)) * T
    return {
        "max_location_x_mm": np.clip(x, -L, L + w),
        "max_location_y_mm": np.clip(y, -L, L),
        "max_location_z_mm": np.clip(z, -T, 0.0),
    }


def write_store(
    run_dir: str | Path,
    stress: StressFn = depth_stress,
    *,
    sweep: dict[str, Any] | None = None,
    seed: int = 0,
    failed_fraction: float = 0.02,
    stages: tuple[int, ...] = (1, 2, 3, 4, 5, 6),
    shards: int = 2,
) -> pd.DataFrame:
    """Write a synthetic run directory; return the full results table that was written.

    ``failed_fraction`` of the jobs fail at a random stage: that stage gets status
    ``max-iterations`` with NaN results and the later stages ``not-run``, as the runner does.
    """
    rd = Path(run_dir)
    rd.mkdir(parents=True, exist_ok=True)
    doc = dict(SMALL_SWEEP if sweep is None else sweep)
    manifest = expand(parse_sweep(doc, str(rd / "sweep.yaml")))
    (rd / "sweep.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    manifest.to_parquet(rd / "manifest.parquet", index=False)

    rng = np.random.default_rng(seed)
    rows = manifest.loc[manifest.index.repeat(len(stages))].reset_index(drop=True)
    rows["stage"] = np.tile(np.asarray(stages, dtype=np.int64), len(manifest))
    n = len(rows)
    s = np.asarray(stress(rows, rng), dtype=float)
    rows["status"] = "converged"
    rows["failure_class"] = None
    rows["newton_iterations"] = rng.integers(3, 20, n)
    rows["time_s"] = rng.uniform(1.0, 10.0, n)
    rows["p99_von_mises_kPa"] = s
    rows["p99_von_mises_nodal_kPa"] = s * 1.02
    rows["max_von_mises_kPa"] = s * 1.5
    for k, v in _locations(rows, rng).items():
        rows[k] = v
    rows["closure_gap_mm"] = np.where(rows["stage"] >= 2, 0.01, np.nan)
    rows["min_J"] = 0.9
    rows["n_penetrating"] = 0
    rows["max_penetration_mm"] = 0.0
    rows["contact_force_mN"] = np.where(rows["stage"] >= 4, 1.0, 0.0)
    rows["residual_norm"] = 1e-9
    rows["dofs"] = 3000
    rows["cells"] = 4000

    # Failures: stage k of a job fails, later stages are not run.
    failed_jobs = rng.random(len(manifest)) < failed_fraction
    fail_stage = rng.integers(min(stages), max(stages) + 1, len(manifest))
    job = np.repeat(np.arange(len(manifest)), len(stages))
    failed_here = failed_jobs[job] & (rows["stage"].to_numpy() == fail_stage[job])
    after = failed_jobs[job] & (rows["stage"].to_numpy() > fail_stage[job])
    result_cols = [c for c in STAGE_RESULT_COLUMNS if c not in ("stage", "status", "dofs", "cells")]
    rows.loc[failed_here | after, result_cols] = np.nan
    rows.loc[failed_here, "status"] = "max-iterations"
    rows.loc[failed_here, "failure_class"] = "nonconvergence"
    rows.loc[after, "status"] = "not-run"

    results = rd / "results"
    results.mkdir(exist_ok=True)
    for i, part in enumerate(np.array_split(np.arange(n), shards)):
        rows.iloc[part].to_parquet(results / f"part-{i:05d}.parquet", index=False)
    return rows

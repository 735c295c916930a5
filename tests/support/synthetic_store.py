"""Synthetic result stores in the real run-directory layout, for the analysis tests.

`write_store` expands a sweep with `woundsweep.config.sweep` (so the manifest is the real one),
writes ``RUN_DIR/sweep.yaml`` and ``RUN_DIR/manifest.parquet``, makes one row per job and
stage (manifest columns + ``stage``, ``status`` and the `StageResult` fields of
docs/design.md) and writes them with `write_results` through the store's own writer
(`Store.write_job`, no fields), so `read_results` validates them like a real run's. The rows
give no ``element_degree``: the writer stores the sweep's. The stress is whatever function
the caller passes, so tests know the truth the model should find.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from woundsweep.config.manifest import expand
from woundsweep.config.sweep import parse_sweep
from woundsweep.core.diagnostics import DIAGNOSTIC_KEYS, StageReport
from woundsweep.core.schema import ExitCode, FailureClass, StageResult, StageStatus
from woundsweep.store.solverfile import SolverOutput
from woundsweep.store.writer import AttemptOutcome, Store

__all__ = [
    "CLI_FAST",
    "CLI_SWEEP",
    "PREDICT_FAST",
    "PREDICT_SWEEP",
    "SMALL_SWEEP",
    "SMOOTH_NOISE",
    "STAGE_RESULT_COLUMNS",
    "depth_level",
    "depth_stress",
    "random_stress",
    "smooth_stress",
    "write_results",
    "write_store",
]

STAGE_RESULT_COLUMNS: tuple[str, ...] = StageResult._fields

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
    "solver": {"element_degree": 1},
}

# The analyze-through-the-CLI store (tests/commands/test_cli_analyze.py and
# tests/analysis/test_analysis_stale.py): 108 geometries x 3 skins x 2 orientations x 6 stages
# = 3,888 rows, and `analyze` options that train it fast.
CLI_SWEEP: dict[str, Any] = {
    **SMALL_SWEEP,
    "grid": {**SMALL_SWEEP["grid"], "dermal_thickness_mm": [1], "orientation_deg": [0, 90]},
    "analysis": {"max_depth": 4},
}
CLI_FAST = [
    "--param",
    "n_estimators=30",
    "--param",
    "learning_rate=0.3",
    "--param",
    "early_stopping_rounds=5",
]

# The predict tests' store (tests/commands/test_surrogate_cli.py, test_predict_table.py):
# 12 geometries x 3 skins x 3 orientations = 108 jobs x 6 stages = 648 rows, and `analyze`
# options that train it fast.
PREDICT_SWEEP: dict[str, Any] = {
    **SMALL_SWEEP,
    "grid": {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
    },
}
PREDICT_FAST = ["--param", "n_estimators=20", "--param", "learning_rate=0.3",
                "--param", "early_stopping_rounds=5", "--param", "sobol_samples=256"]  # fmt: skip

# A predict table's column -> the one-wound option (tests/commands/test_predict_*.py).
PREDICT_FLAGS = {
    "wound_shape": "--shape", "dermal_thickness_mm": "--dermal-thickness",
    "subcutis_thickness_factor": "--subcutis-thickness-factor",
    "patch_size_factor": "--patch-size-factor", "wound_width_factor": "--wound-width-factor",
    "wound_depth_factor": "--wound-depth-factor", "wound_aspect_factor": "--wound-aspect-factor",
    "mesh_size_factor": "--mesh-size-factor", "orientation_deg": "--orientation",
    "angle_to_langer_deg": "--angle-to-langer", "skin_type": "--skin-type", "stage": "--stage",
}  # fmt: skip

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


SMOOTH_NOISE = 0.05  # smooth_stress's log-normal sigma
_SKIN_EFFECT = {"soft": -1.0, "normal": 0.0, "stiff": 1.0}


def smooth_stress(df: pd.DataFrame, rng: np.random.Generator) -> np.ndarray:
    """Stress smooth in every factor, monotone in most, independent of the dermal thickness
    (as the physics: every length scales with it), times log-normal noise (`SMOOTH_NOISE`)."""
    log = (
        3.0
        + 3.0 * depth_level(df)
        + 0.5 * np.log(df["subcutis_thickness_factor"])
        - 0.4 * np.log(df["patch_size_factor"])
        + 1.2 * df["wound_width_factor"] ** 2
        + 0.3 * np.cos(np.radians(2.0 * df["orientation_deg"]))
        + 0.3 * df["skin_type"].map(_SKIN_EFFECT)
        + 0.05 * (df["stage"] - 1)
    )
    return np.exp(log + rng.normal(0.0, SMOOTH_NOISE, len(df)))


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
    rows["status"] = StageStatus.CONVERGED.value
    rows["newton_iterations"] = rng.integers(3, 20, n)
    rows["time_s"] = rng.uniform(1.0, 10.0, n)
    rows["p99_von_mises_kPa"] = s
    rows["p99_von_mises_nodal_kPa"] = s * 1.02
    rows["max_von_mises_kPa"] = s * 1.5
    for k, v in _locations(rows, rng).items():
        rows[k] = v
    rows["closure_gap_max_mm"] = np.where(rows["stage"] >= 2, 0.01, np.nan)
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
    kept = ("stage", "status", "dofs", "cells", "element_degree")
    result_cols = [c for c in STAGE_RESULT_COLUMNS if c not in kept]
    rows.loc[failed_here | after, result_cols] = np.nan
    rows.loc[failed_here, "status"] = StageStatus.MAX_ITERATIONS.value
    rows.loc[after, "status"] = StageStatus.NOT_RUN.value
    write_results(rd, rows)
    return rows


def write_results(run_dir: str | Path, rows: pd.DataFrame) -> None:
    """Write ``rows`` (manifest columns + stage results) as one result file per job.

    Stages with status ``not-run`` are left out of the job's solver output, so the store
    writes them as not run; columns named after a diagnostic (`DIAGNOSTIC_KEYS`; NaN: absent)
    are the stages' diagnostics; a job whose stages did not all converge is ``not-converged``.
    """
    store = Store(run_dir)
    fields = STAGE_RESULT_COLUMNS[2:]
    diagnostics = [c for c in rows.columns if c in DIAGNOSTIC_KEYS]
    records = rows.to_dict("records")
    for idx in rows.groupby("job_id", sort=False).indices.values():
        job = [records[i] for i in idx]
        stages = {
            int(r["stage"]): StageReport.from_row(
                {
                    "stage": int(r["stage"]),
                    "status": r["status"],
                    **{f: r.get(f) for f in fields},
                    **{c: r[c] for c in diagnostics if pd.notna(r[c])},
                }
            )
            for r in job
            if r["status"] != StageStatus.NOT_RUN
        }
        converged = len(stages) == len(job) and all(
            s.status == StageStatus.CONVERGED for s in stages.values()
        )
        outcome = AttemptOutcome(
            failure_class=(
                FailureClass.CONVERGED if converged else FailureClass.NOT_CONVERGED
            ).value,
            failure_detail="",
            exit_code=int(ExitCode.OK if converged else ExitCode.NOT_CONVERGED),
            attempts=1,
            wall_time_s=1.0,
            cpu_time_s=1.0,
            total_wall_time_s=1.0,
            total_cpu_time_s=1.0,
            max_rss_MiB=None,
            started_at=0.0,
            finished_at=1.0,
            output=SolverOutput(Path(run_dir), {}, stages),
        )
        span = (min(int(r["stage"]) for r in job), max(int(r["stage"]) for r in job))
        store.write_job(job[0], outcome, span, "none", "1/1")

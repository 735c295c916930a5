"""The analysis's rows: the run's result store, read through the store's validated reader.

Rows are the converged (job, stage) results with a finite, positive `STRESS`; the model
matrix (`model_features` of the rows' shapes) encodes the wound shape by `SHAPE_CODES` and
the skin type by its Fung ``c`` (kPa).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..config.manifest import Run, load_run
from ..core.errors import AnalysisError
from ..core.layout import RunLayout
from ..core.schema import StageStatus
from ..store.reader import read_results
from .settings import (
    DUPLICATE_COLUMNS,
    DUPLICATE_RTOL,
    REQUIRED_COLUMNS,
    SHAPE_CODES,
    STRESS,
    model_features,
)

__all__ = [
    "drop_orphans",
    "duplicate_states",
    "encode_features",
    "load_results",
    "require_columns",
    "run_or_none",
    "select_rows",
    "skin_codes",
    "sweep_settings",
]


def run_or_none(run_dir: str | Path) -> Run | None:
    """The run directory's sweep and manifest (`load_run`), or None for a directory that
    holds a result store alone."""
    return load_run(run_dir) if RunLayout(run_dir).is_run() else None


def sweep_settings(run: Run | None) -> tuple[dict[str, Any], dict[str, float]]:
    """``Sweep.analysis`` and skin type -> Fung c (kPa) of the run, or the paper's defaults."""
    from ..config.paper import Materials

    if run is not None:
        analysis, materials = dataclasses.asdict(run.sweep.analysis), run.sweep.materials
    else:
        analysis, materials = {}, Materials.table2()
    return analysis, {name: float(p.c_kPa) for name, p in materials.skin_types.items()}


def skin_codes(run_dir: str | Path) -> dict[str, float]:
    """Skin type name -> its Fung ``c`` in kPa: an ordered, physical code for the model."""
    return sweep_settings(run_or_none(run_dir))[1]


def require_columns(df: pd.DataFrame, where: object) -> pd.DataFrame:
    """``df`` if it holds every `REQUIRED_COLUMNS` entry; else `AnalysisError` naming them."""
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise AnalysisError(f"{where}: missing columns {missing}")
    return df


def load_results(run_dir: str | Path, run: Run | None = None) -> pd.DataFrame:
    """All rows of ``RUN_DIR/results`` (one per job and stage), validated by the store
    (``run``: the directory's `run_or_none`, if the caller has it).

    A damaged result file raises the store's `StoreError` naming it and the fix.
    """
    rd = Path(run_dir)
    res = RunLayout(rd).results_dir
    if not res.is_dir():
        raise AnalysisError(f"{res}: no result store (run `woundsweep run {run_dir}` first)")
    df = read_results(rd, run=run)
    if df.empty:
        raise AnalysisError(f"{res}: the result store holds no result files (job-*.parquet)")
    return require_columns(df, res)


def drop_orphans(results: pd.DataFrame, run: Run | None) -> tuple[pd.DataFrame, int]:
    """The rows of jobs in the run's manifest (all rows without a run), and how many rows
    were not.

    Rows of jobs that a regenerated manifest no longer holds belong to another sweep.
    """
    if run is None:
        return results, 0
    in_manifest = results["job_id"].isin(set(run.manifest["job_id"]))
    return results[in_manifest], int((~in_manifest).sum())


def _flag(df: pd.DataFrame, name: str) -> pd.Series:
    """A 0/1 column as numbers (NaN where it does not apply or is absent)."""
    if name not in df:
        return pd.Series(np.nan, index=df.index)
    return pd.to_numeric(df[name], errors="coerce").astype(float)


def duplicate_states(rows: pd.DataFrame, stress: str = STRESS) -> np.ndarray:
    """Per row: True where it repeats an earlier stage's state of the same job (``stress``
    and each `DUPLICATE_COLUMNS` entry the rows have, finite in both, within
    `DUPLICATE_RTOL` relative; a column missing or NaN in either row does not decide)."""
    cols = [stress, *(c for c in DUPLICATE_COLUMNS if c in rows and c != stress)]
    values = np.column_stack(
        [pd.to_numeric(rows[c], errors="coerce").to_numpy(float) for c in cols]
    )
    job = rows["job_id"].astype(str).to_numpy()
    order = np.lexsort((rows["stage"].to_numpy(), job))
    dup = np.zeros(len(rows), dtype=bool)
    start = 0
    while start < len(order):
        end = start
        while end < len(order) and job[order[end]] == job[order[start]]:
            end += 1
        idx = order[start:end]
        for a in range(1, len(idx)):
            v = values[idx[a]]
            for b in range(a):
                w = values[idx[b]]
                both = np.isfinite(v) & np.isfinite(w)
                tol = DUPLICATE_RTOL * np.maximum(np.abs(v), np.abs(w))
                if both[0] and np.all(np.abs(v - w)[both] <= tol[both]):
                    dup[idx[a]] = True
                    break
        start = end
    return dup


def select_rows(
    df: pd.DataFrame,
    drop_interpenetrating: bool = False,
    keep_reopened: bool = False,
    keep_duplicates: bool = False,
    stress: str = STRESS,
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Converged rows with a finite, positive ``stress``, without the rows whose sutured
    zone has reopened (``closed`` = 0) unless ``keep_reopened``, without the rows that repeat
    an earlier stage's state (`duplicate_states`) unless ``keep_duplicates``, and without the
    rows whose flanks interpenetrate if ``drop_interpenetrating``; and the row counts."""
    if stress not in df:
        raise AnalysisError(f"no column {stress!r} in the result store")
    converged = df["status"].astype(str) == StageStatus.CONVERGED.value
    stress_values = pd.to_numeric(df[stress], errors="coerce")
    positive = converged & np.isfinite(stress_values) & (stress_values > 0)
    overlap = positive & (_flag(df, "interpenetrating") == 1)
    reopened = positive & (_flag(df, "closed") == 0)
    drop = (overlap & drop_interpenetrating) | (reopened & (not keep_reopened))
    duplicate = pd.Series(False, index=df.index)
    kept = positive & ~drop
    twice = df[kept].duplicated(["job_id", "stage"])
    if twice.any():
        raise AnalysisError(
            f"the result store has {int(twice.sum())} duplicate (job_id, stage) rows"
        )
    if kept.any():
        duplicate[kept] = duplicate_states(df[kept], stress)
    rows = df[kept & ~(duplicate & (not keep_duplicates))].reset_index(drop=True)
    counts = {
        "store_rows": int(len(df)),
        "jobs": int(df["job_id"].nunique()),
        "converged_rows": int(converged.sum()),
        "used_rows": int(len(rows)),
        "interpenetrating_rows": int(overlap.sum()),
        "interpenetrating_dropped": bool(drop_interpenetrating),
        "reopened_rows": int(reopened.sum()),
        "reopened_dropped": not keep_reopened,
        "duplicate_rows": int(duplicate.sum()),
        "duplicate_dropped": not keep_duplicates,
        "duplicate_rule": (
            f"{stress} and {', '.join(c for c in DUPLICATE_COLUMNS if c in df)} within "
            f"{DUPLICATE_RTOL:g} relative of an earlier stage of the job"
        ),
        "distinct_geometries": int(rows["geometry_id"].nunique())
        if "geometry_id" in rows
        else None,
        "status": {
            str(k): int(v) for k, v in df["status"].astype(str).value_counts().sort_index().items()
        },
        "used_rows_by_stage": {
            str(int(k)): int(v) for k, v in rows["stage"].value_counts().sort_index().items()
        },
    }
    if not converged.any():
        raise AnalysisError(
            f"no converged rows in the result store ({len(df)} rows: {counts['status']})"
        )
    if rows.empty:
        raise AnalysisError("no converged row has a positive, finite maximal stress")
    return rows, counts


def encode_features(
    rows: pd.DataFrame, skins: Mapping[str, float], features: Sequence[str] | None = None
) -> np.ndarray:
    """The model matrix (rows x ``features``; default `model_features` of the rows' shapes),
    float64, NaN for factors that do not apply."""
    if features is None:
        features = model_features(rows["wound_shape"].astype(str))
    X = np.empty((len(rows), len(features)), dtype=np.float64)
    for j, name in enumerate(features):
        if name not in rows:  # a store of trenches read before the excision existed
            X[:, j] = np.nan
            continue
        col = rows[name]
        if name in ("wound_shape", "skin_type"):
            codes = SHAPE_CODES if name == "wound_shape" else skins
            unknown = sorted(set(col.astype(str)) - set(codes))
            if unknown:
                raise AnalysisError(f"{name}: unknown values {unknown} (known: {sorted(codes)})")
            X[:, j] = col.astype(str).map(codes).to_numpy(dtype=np.float64)
        else:
            X[:, j] = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64)
    return X

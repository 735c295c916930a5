"""The HDF5 file ``woundsweep solve`` writes and the store reads: one description of its layout.

Layout (docs/design.md, "Solver output"): root attributes (`ROOT_ATTRS`; ``stage_results`` is
a JSON list with one dict per reported stage: the `StageResult` fields plus diagnostic keys),
the group ``mesh`` with `MESH_DATASETS` in the input numbering, and for every converged stage
a group ``stage_<k>`` with `STAGE_DATASETS` (float32 per point, per cell) and, when the
solver sampled them, `PROFILE_DATASETS` (von Mises on the lines of `woundsweep.physics.profiles`)
and `CLOSURE_LINE_DATASETS` (line loads along the wound, `woundsweep.physics.closure`). An
unconverged state is never written as a field.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .. import __version__
from ..core.diagnostics import StageReport
from ..core.errors import StoreError
from ..core.fsutil import atomic_write
from ..core.schema import UNITS, MeshData, StageStatus

__all__ = [
    "CLOSURE_LINE_DATASETS",
    "FINGERPRINT_ATTR",
    "MESH_DATASETS",
    "MESH_GROUP",
    "PROFILE_DATASETS",
    "ROOT_ATTRS",
    "STAGE_DATASETS",
    "SolverOutput",
    "read_solver_file",
    "stage_group",
    "stage_of_group",
    "stamp_fingerprint",
    "write_solver_file",
]

ROOT_ATTRS = (
    "job_id",
    "job_index",
    "geometry_id",
    "jit_time_s",
    "woundsweep_version",
    "dolfinx_version",
    "units",
    "stage_results",
)
MESH_GROUP = "mesh"
MESH_DATASETS: Mapping[str, Any] = {"points": np.float64, "cells": np.int64, "cell_tags": np.int32}
STAGE_DATASETS = ("displacement_mm", "von_mises_kPa")
# Optional per stage: (3, 100) von Mises on the profile lines and their (3, 100, 3) points.
PROFILE_DATASETS = ("profile_von_mises_kPa", "profile_points_mm")
# Optional per stage: forces per length along the wound at bin centres (closing and contact,
# on the left flank; `woundsweep.physics.closure.LineLoads`), in this order.
CLOSURE_LINE_DATASETS = (
    "closure_line_y_mm",
    "closing_force_per_length_mN_per_mm",
    "contact_force_per_length_mN_per_mm",
)
_STAGE_GROUP = re.compile(r"stage_(\d+)")
# The root attribute `woundsweep solve` stamps: the result fingerprint (`store.identity`) of
# the settings the file was solved with, so a viewer can refuse a file of an earlier sweep.
FINGERPRINT_ATTR = "result_fingerprint"


def stage_group(stage: int) -> str:
    """The group name of a stage's fields."""
    return f"stage_{int(stage)}"


def stage_of_group(name: str) -> int | None:
    """The stage of a group name, or None if it is not a stage group."""
    m = _STAGE_GROUP.fullmatch(name)
    return int(m.group(1)) if m else None


class SolverOutput(NamedTuple):
    """What a solver file says: root attributes and the per-stage results by stage."""

    path: Path
    attrs: dict[str, Any]
    stages: dict[int, StageReport]


def write_solver_file(
    path: str | Path,
    attrs: Mapping[str, Any],
    mesh: MeshData,
    reports: Sequence[StageReport],
    fields: Mapping[int, tuple[np.ndarray, np.ndarray]],
    extra: Mapping[int, Mapping[str, np.ndarray]] | None = None,
) -> None:
    """Write a solver file atomically.

    ``attrs`` holds the job's root attributes (``woundsweep_version`` and ``units`` are
    added), ``mesh`` has ``points``, ``cells`` and ``cell_tags``, ``reports`` are the reported
    stages', and ``fields`` maps a converged stage to its (displacement,
    von Mises) arrays in `STAGE_DATASETS` order; ``extra`` adds datasets to a converged
    stage's group (e.g. `PROFILE_DATASETS`).
    """
    import h5py

    def _write(tmp: str) -> None:
        with h5py.File(tmp, "w") as f:
            for k, v in attrs.items():
                f.attrs[k] = v
            f.attrs["woundsweep_version"] = __version__
            f.attrs["units"] = UNITS
            f.attrs["stage_results"] = json.dumps([r.to_row() for r in reports])
            g = f.create_group(MESH_GROUP)
            for name, dtype in MESH_DATASETS.items():
                g.create_dataset(name, data=np.asarray(getattr(mesh, name), dtype=dtype))
            for stage, arrays in fields.items():
                s = f.create_group(stage_group(stage))
                for name, data in zip(STAGE_DATASETS, arrays):
                    s.create_dataset(name, data=data, compression="gzip")
                for name, data in (extra or {}).get(stage, {}).items():
                    s.create_dataset(name, data=data)

    atomic_write(path, _write)


def stamp_fingerprint(path: str | Path, fingerprint: str) -> None:
    """Record ``fingerprint`` as the `FINGERPRINT_ATTR` of the solver file ``path`` (a copy
    with the attribute replaces the file atomically)."""
    import shutil

    import h5py

    def _write(tmp: str) -> None:
        shutil.copyfile(path, tmp)
        with h5py.File(tmp, "r+") as f:
            f.attrs[FINGERPRINT_ATTR] = fingerprint

    atomic_write(path, _write)


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_solver_file(path: str | Path, job_id: str, stages: tuple[int, int]) -> SolverOutput:
    """Read and check a solver file; ``StoreError`` says what is wrong.

    The result holds the stages ``stages[0]..stages[1]``; ``attrs["_groups"]`` lists the
    file's groups.
    """
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
        by_stage = {int(r["stage"]): r for r in rows}
    except (ValueError, TypeError, KeyError) as err:
        raise StoreError(f"{path}: bad stage_results attribute ({err})") from None
    reports: dict[int, StageReport] = {}
    for k, r in by_stage.items():
        try:
            reports[k] = StageReport.from_row(r)
        except ValueError as err:
            raise StoreError(f"{path}: stage {k} has {err}") from None
        have = groups.get(stage_group(k), set())
        if r["status"] == StageStatus.CONVERGED and not set(STAGE_DATASETS) <= have:
            raise StoreError(
                f"{path}: converged stage {k} lacks {stage_group(k)}/{sorted(STAGE_DATASETS)}"
            )
    for g, names in groups.items():
        if (g == MESH_GROUP and not set(MESH_DATASETS) <= names) or (
            stage_of_group(g) is not None and not set(STAGE_DATASETS) <= names
        ):
            raise StoreError(f"{path}: group {g} is incomplete ({sorted(names)})")
    attrs["_groups"] = sorted(groups)
    return SolverOutput(
        path, attrs, {k: v for k, v in reports.items() if stages[0] <= k <= stages[1]}
    )

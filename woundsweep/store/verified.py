"""Reading the store's HDF5 files for the viewers only after checking them: regular files,
the checksums their results record, bounded datasets, finite fields, and a solver file
solved with the run's current settings.

`read_fields_file` opens a fields, mesh or solver file (`core.fsutil.open_regular` first: a
named pipe or a link cannot hang or lead the reader out of the run) and reads its groups,
refusing a dataset declared with more than `MAX_DATASET_VALUES` values before reading it and
non-finite coordinates, displacements or stresses. `verify_job_files` checks a stored job's
fields and mesh files against the sha256 its result rows record. `current_solve_file` is
``RUN_DIR/solve/job_<N>.h5`` only if it records the job's current result fingerprint
(`solverfile.FINGERPRINT_ATTR`, stamped by `woundsweep solve`). Every problem is a
`StoreError` of one line naming the file.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..config.manifest import Run
from ..core.errors import StoreError
from ..core.fsutil import open_regular
from ..core.layout import RunLayout
from .identity import file_sha256, result_fingerprint
from .reader import store_file_names
from .solverfile import FINGERPRINT_ATTR, MESH_GROUP, STAGE_DATASETS, stage_of_group

__all__ = [
    "MAX_DATASET_VALUES",
    "check_solver_fingerprint",
    "current_solve_file",
    "read_fields_file",
    "verify_job_files",
]

# Far above any mesh within `mesh.sizing.MAX_CELLS` (2 M cells: 8 M connectivity values, 18 M
# for a per-cell 3 x 3 tensor); a dataset declared larger is damage or a crafted file.
MAX_DATASET_VALUES = 64_000_000
_FINITE = {(MESH_GROUP, "points"), *(("stage", name) for name in STAGE_DATASETS)}


def _regular(path: Path) -> None:
    try:
        os.close(open_regular(path))
    except FileNotFoundError:
        raise StoreError(f"{path}: missing") from None
    except OSError as err:
        raise StoreError(f"{path}: {err.strerror}") from None


def read_fields_file(path: str | Path) -> tuple[dict[str, Any], dict[str, dict[str, np.ndarray]]]:
    """The root attributes (bytes decoded) and every group's datasets of an HDF5 file the
    store or `woundsweep solve` wrote, checked as the module docstring says."""
    import h5py

    path = Path(path)
    _regular(path)
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
            groups: dict[str, dict[str, np.ndarray]] = {}
            for g, group in f.items():
                if not isinstance(group, h5py.Group):
                    continue
                kind = "stage" if stage_of_group(g) is not None else g
                groups[g] = {}
                for name, ds in group.items():
                    if not isinstance(ds, h5py.Dataset):
                        raise StoreError(f"{path}: {g}/{name} is not a dataset")
                    if ds.size > MAX_DATASET_VALUES:
                        raise StoreError(
                            f"{path}: {g}/{name} declares {ds.size:,} values, above the "
                            f"{MAX_DATASET_VALUES:,} any stored mesh or field has"
                        )
                    data = ds[()]
                    if (kind, name) in _FINITE and not np.isfinite(data).all():
                        raise StoreError(f"{path}: {g}/{name} holds non-finite values")
                    groups[g][name] = data
    except StoreError:
        raise
    except Exception as err:  # noqa: BLE001 - h5py raises many types for damaged files
        text = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise StoreError(f"{path}: unreadable HDF5 file ({text})") from None
    return attrs, groups


def verify_job_files(layout: RunLayout, row: Mapping[str, Any]) -> None:
    """StoreError unless the fields and mesh files a stored job's result row names are
    regular files with the sha256 the row records (checked before anything is read)."""
    names = store_file_names(
        {"fields_file": row.get("fields_file") or "", "mesh_file": row.get("mesh_file") or ""}
    )
    for name, key in zip(names, ("fields_file_sha256", "mesh_file_sha256")):
        if not name:
            continue
        path = layout.fields_dir / name
        _regular(path)
        if file_sha256(path) != row.get(key):
            raise StoreError(
                f"{path}: damaged (its sha256 differs from the one its result records); "
                f"`woundsweep run {layout.run_dir}` moves it aside and redoes the job"
            )


def _fingerprint_of(attrs: Mapping[str, Any]) -> str | None:
    value = attrs.get(FINGERPRINT_ATTR)
    return value.decode() if isinstance(value, bytes) else (str(value) if value else None)


def check_solver_fingerprint(run: Run, job: Any, path: Path, attrs: Mapping[str, Any]) -> None:
    """StoreError when the solver file ``path`` records a result fingerprint other than
    ``job``'s under the run's current sweep (solved with an earlier sweep's settings)."""
    recorded = _fingerprint_of(attrs)
    if recorded is not None and recorded != result_fingerprint(run.sweep, job):
        raise StoreError(
            f"{path}: solved with other settings than {run.layout.sweep} gives job "
            f"{job['job_index']} now (the sweep changed since): solve the job again"
        )


def current_solve_file(run: Run, job_index: int) -> Path | None:
    """``RUN_DIR/solve/job_<N>.h5`` when it exists and records the job's current result
    fingerprint; None when there is none; StoreError when it is stale or unverifiable."""
    import h5py

    path = run.layout.solve_file(job_index)
    if not os.path.lexists(path):
        return None
    _regular(path)
    try:
        with h5py.File(path, "r") as f:
            attrs = dict(f.attrs.items())
    except Exception as err:  # noqa: BLE001 - h5py raises many types for damaged files
        raise StoreError(f"{path}: unreadable HDF5 file ({type(err).__name__})") from None
    if _fingerprint_of(attrs) is None:
        raise StoreError(
            f"{path}: records no result fingerprint, so it may be from an earlier sweep: "
            f"solve the job again (`woundsweep solve {run.run_dir} --job {job_index}`)"
        )
    check_solver_fingerprint(run, run.job(job_index), path, attrs)
    return path

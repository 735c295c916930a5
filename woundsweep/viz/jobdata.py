"""One stored job as the viewers need it: mesh with tags, stored stages' fields, result rows.

The store keeps the fields of a job in ``fields/<job_id>.h5`` (the stages `run --fields`
kept) and its mesh once per geometry in ``fields/mesh-<geometry_id>.h5`` (points, cells, cell
tags); the facets and facet tags come from the mesh cache ``meshes/<geometry_id>.npz``
(rebuilt by gmsh if it is missing, and then checked against the stored mesh), which is also
the mesh of a job without stored fields. Every stage of
the job's rows gets a `StageNote` saying whether it has a field and, if not, why.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from ..config.manifest import JobRow, Run
from ..core.errors import StoreError
from ..core.schema import StageStatus
from ..store.reader import store_file_names
from ..store.solverfile import MESH_GROUP, STAGE_DATASETS, stage_group
from .surface import closure_zone_facets

__all__ = ["JobFields", "StageNote", "load_job", "open_job", "records", "stage_notes"]


class StageNote(NamedTuple):
    """A requested stage: its status and whether the store kept its field (and why not)."""

    stage: int
    status: str
    stored: bool
    reason: str  # "" when stored


class JobFields(NamedTuple):
    """A job's reference mesh (input numbering), tags, closure zone and stored fields."""

    job: JobRow  # the manifest row
    rows: list[dict[str, Any]]  # the job's result rows, one per requested stage, by stage
    points: np.ndarray  # (n, 3) float64 mm
    cells: np.ndarray  # (m, 4) int64
    cell_tags: np.ndarray  # (m,) int32
    facets: np.ndarray  # (k, 3) int64, the exterior triangles
    facet_tags: np.ndarray  # (k,) int32
    zone: np.ndarray  # (k,) bool: the facet is in the closure zone
    fields: dict[int, tuple[np.ndarray, np.ndarray]]  # stage -> (displacement_mm, von_mises_kPa)
    notes: list[StageNote]


def records(rows: pd.DataFrame | list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A job's result rows as dicts sorted by stage (pandas rows are slow one by one)."""
    if isinstance(rows, pd.DataFrame):
        rows = rows.to_dict("records")
    return sorted(rows, key=lambda r: int(r["stage"]))


def stage_notes(rows: list[dict[str, Any]], stored: set[int]) -> list[StageNote]:
    """Per requested stage: stored or not, and the reason (not converged, not kept, not run)."""
    notes = []
    fields = str(rows[0]["fields"]) if rows else ""
    for r in rows:
        k, status = int(r["stage"]), str(r["status"])
        if k in stored:
            notes.append(StageNote(k, status, True, ""))
        elif status == StageStatus.CONVERGED:
            notes.append(StageNote(k, status, False, f"not kept by `run --fields {fields}`"))
        elif status == StageStatus.NOT_RUN:
            notes.append(StageNote(k, status, False, "not run"))
        else:
            notes.append(StageNote(k, status, False, f"no field: the stage ended {status}"))
    return notes


def _read_h5(path: Path) -> tuple[dict[str, Any], dict[str, dict[str, np.ndarray]]]:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
            groups = {
                g: {name: ds[()] for name, ds in f[g].items()}
                for g in f
                if isinstance(f[g], h5py.Group)
            }
    except (OSError, KeyError, ValueError) as err:
        raise StoreError(f"{path}: unreadable fields file ({err})") from None
    return attrs, groups


def _plain_names(job: JobRow, fields_file: str, mesh_file: str) -> None:
    """File names read from the store stay inside RUN_DIR/fields (`store_file_names`)."""
    try:
        store_file_names({"fields_file": fields_file, "mesh_file": mesh_file}, job["job_id"])
    except StoreError as err:
        raise StoreError(f"job {job['job_index']}: {err}") from None


def _mesh_arrays(run: Run, job: JobRow, groups: dict[str, Any], mesh_file: str):
    if MESH_GROUP in groups:
        mesh = groups[MESH_GROUP]
    elif not groups:  # no fields stored (`run --fields none`, or no converged stage)
        m = _cached_mesh(run, job).mesh
        return m.points, m.cells, m.cell_tags
    else:
        path = run.run_dir / "fields" / (mesh_file or f"mesh-{job['geometry_id']}.h5")
        if not path.exists():
            raise StoreError(f"{path}: the job's mesh file is missing")
        mesh = _read_h5(path)[1].get(MESH_GROUP)
        if mesh is None:
            raise StoreError(f"{path}: no group {MESH_GROUP!r}")
    try:
        return (
            np.asarray(mesh["points"], np.float64),
            np.asarray(mesh["cells"], np.int64),
            np.asarray(mesh["cell_tags"], np.int32),
        )
    except KeyError as err:
        raise StoreError(f"the stored mesh of job {job['job_index']} lacks {err}") from None


def _cached_mesh(run: Run, job: JobRow) -> Any:
    from ..mesh.cache import get_mesh

    return get_mesh(run.run_dir, str(job["geometry_id"]), run.geometry(job))


def _boundary(run: Run, job: JobRow, points: np.ndarray, cells: np.ndarray):
    """Facets and facet tags from the mesh cache (built if missing), checked against the store."""
    got = _cached_mesh(run, job)
    m = got.mesh
    if m.points.shape != points.shape or m.cells.shape != cells.shape:
        raise StoreError(
            f"job {job['job_index']}: the mesh cache {got.path} does not match the stored mesh"
            f" ({len(m.cells)} vs {len(cells)} cells)"
        )
    if not (np.array_equal(m.cells, cells) and np.allclose(m.points, points, atol=1e-9)):
        raise StoreError(
            f"job {job['job_index']}: the mesh cache {got.path} differs from the stored mesh"
        )
    return np.asarray(m.facets, np.int64), np.asarray(m.facet_tags, np.int32)


def load_job(
    run: Run,
    job: JobRow,
    rows: pd.DataFrame | list[dict[str, Any]],
    cache: dict[Any, Any] | None = None,
) -> JobFields:
    """Read the job's mesh and stored fields (the closure zone from the mesh's facet tags).

    ``run`` is the job's `grid.Run` (its sweep gives the meshes' closure zone and element
    degree). ``rows`` are the job's validated result rows (`read_results`); a job without a fields
    file (failed early, or ``run --fields none``) gets the mesh and no fields. ``cache`` (a
    dict the caller keeps) holds the last geometry's mesh for the next job of that geometry.
    """
    run_dir = run.run_dir
    rows = records(rows)
    if not rows:
        raise StoreError(f"job {job['job_index']} has no stored result yet (run `woundsweep run`)")
    fields_file = str(rows[0]["fields_file"] or "")
    mesh_file = str(rows[0]["mesh_file"] or "")
    _plain_names(job, fields_file, mesh_file)
    groups: dict[str, Any] = {}
    stored: list[int] = []
    if fields_file:
        attrs, groups = _read_h5(run_dir / "fields" / fields_file)
        if attrs.get("job_id") != job["job_id"]:
            raise StoreError(f"fields/{fields_file}: holds job {attrs.get('job_id')!r}")
        stored = [int(k) for k in json.loads(attrs.get("stored_stages", "[]"))]
        mesh_file = str(attrs.get("mesh_file", mesh_file) or mesh_file)
        _plain_names(job, fields_file, mesh_file)
    key = (str(job["geometry_id"]), mesh_file)
    if MESH_GROUP not in groups and cache is not None and key in cache:
        points, cells, cell_tags, facets, facet_tags, in_zone = cache[key]
    else:
        points, cells, cell_tags = _mesh_arrays(run, job, groups, mesh_file)
        facets, facet_tags = _boundary(run, job, points, cells)
        in_zone = closure_zone_facets(facet_tags)
        if MESH_GROUP not in groups and cache is not None:
            cache.clear()  # jobs come grouped by geometry: one mesh at a time
            cache[key] = (points, cells, cell_tags, facets, facet_tags, in_zone)
    fields = {}
    for k in stored:
        g = groups.get(stage_group(k), {})
        if not set(STAGE_DATASETS) <= set(g):
            raise StoreError(f"fields/{fields_file}: stage {k} lacks {list(STAGE_DATASETS)}")
        u, vm = (np.asarray(g[name]) for name in STAGE_DATASETS)
        if u.shape != points.shape or vm.shape != (len(cells),):
            raise StoreError(f"fields/{fields_file}: stage {k} arrays do not fit the mesh")
        fields[k] = (u, vm)
    return JobFields(
        job=job,
        rows=rows,
        points=points,
        cells=cells,
        cell_tags=cell_tags,
        facets=facets,
        facet_tags=facet_tags,
        zone=in_zone,
        fields=fields,
        notes=stage_notes(rows, set(fields)),
    )


def open_job(run_dir: str | Path, job_index: int, cache: dict[Any, Any] | None = None) -> JobFields:
    """`load_job` for one job of a run directory, with its validated rows."""
    from ..config.manifest import load_run
    from ..store.reader import read_results

    run = load_run(run_dir)
    job = run.job(job_index)
    rows = read_results(run.run_dir, [str(job["job_id"])])
    return load_job(run, job, rows, cache)

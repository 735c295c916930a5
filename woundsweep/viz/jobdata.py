"""One stored job as the viewers need it: mesh with tags, stored stages' fields, result rows.

The store keeps the fields of a job in ``fields/<job_id>.h5`` (the stages `run --fields`
kept) and the mesh its geometry's jobs share in ``fields/mesh-<mesh_id>.h5`` (points, cells,
cell tags; `GeometrySpec.mesh_id`); the facets and facet tags come from the mesh cache
``meshes/<mesh_id>.npz`` (rebuilt by gmsh if it is missing, and then checked against the
stored mesh), which is also the mesh of a job without stored fields. Every stage of the job's
rows gets a `StageNote` saying whether it has a field and, if not, why.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, cast

import numpy as np
import pandas as pd

from ..config.manifest import JobRow, Run
from ..config.paper import Materials
from ..core.errors import StoreError
from ..core.layout import RunLayout
from ..core.schema import PROFILE_LINES, FailureClass, StageStatus
from ..store.reader import store_file_names
from ..store.solverfile import (
    CLOSURE_LINE_DATASETS,
    MESH_GROUP,
    PROFILE_DATASETS,
    STAGE_DATASETS,
    stage_group,
)
from ..store.verified import (
    check_solver_fingerprint,
    current_solve_file,
    read_fields_file,
    verify_job_files,
)
from .surface import closure_zone_facets

if TYPE_CHECKING:
    from ..mesh.cache import CachedMesh

# Optional per stage: the solver's cell means of its stress samples (the Cauchy stress tensor
# (m, 3, 3) kPa, the Green-Lagrange strain (m, 3, 3), J (m,)), which `viz.export` writes as
# they are where a fields file holds them (a P2 field's vertex values cannot give them).
SOLVER_CELL_DATASETS = ("cauchy_stress_kPa", "green_lagrange_strain", "det_F")

__all__ = [
    "SOLVER_CELL_DATASETS",
    "JobFields",
    "StageNote",
    "load_job",
    "load_solver_file",
    "open_job",
    "solve_output",
    "records",
    "stage_notes",
]


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
    materials: Materials | None = None  # the run's materials (the derived stresses need them)
    # stage -> line name -> {points_mm (points, 3), von_mises_kPa (points,)}
    profiles: dict[int, dict[str, dict[str, np.ndarray]]] = {}
    # stage -> `CLOSURE_LINE_DATASETS` name -> (k,): the line loads along the wound
    closure_lines: dict[int, dict[str, np.ndarray]] = {}
    source: str = ""  # the file the fields came from
    # stage -> `SOLVER_CELL_DATASETS` name -> per-cell array, where the fields file holds them
    cell_data: dict[int, dict[str, np.ndarray]] = {}

    @property
    def element_degree(self) -> int | None:
        """The element the job's rows were computed with (None if they do not say)."""
        degrees = {int(r["element_degree"]) for r in self.rows if _given(r.get("element_degree"))}
        return degrees.pop() if len(degrees) == 1 else None


def _given(value: Any) -> bool:
    return value is not None and not pd.isna(value)


def records(rows: pd.DataFrame | list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A job's result rows as dicts sorted by stage (pandas rows are slow one by one)."""
    if isinstance(rows, pd.DataFrame):
        rows = cast("list[dict[str, Any]]", rows.to_dict("records"))  # str column names
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
    return read_fields_file(path)  # a regular file, bounded datasets, finite fields


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
        path = (
            run.layout.fields_dir / mesh_file
            if mesh_file
            else run.layout.mesh_file(run.geometry(job).mesh_id)
        )
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


def _cached_mesh(run: Run, job: JobRow) -> CachedMesh:
    from ..mesh.cache import get_mesh

    return get_mesh(run.run_dir, run.geometry(job))


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
    degree; the rows give the element the results were computed with). ``rows`` are the job's validated result rows (`read_results`); a job without a fields
    file (failed early, or ``run --fields none``) gets the mesh and no fields. ``cache`` (a
    dict the caller keeps) holds the last geometry's mesh for the next job of that geometry.
    """
    rows = records(rows)
    if not rows:
        raise StoreError(f"job {job['job_index']} has no stored result yet (run `woundsweep run`)")
    fields_file = str(rows[0]["fields_file"] or "")
    mesh_file = str(rows[0]["mesh_file"] or "")
    _plain_names(job, fields_file, mesh_file)
    verify_job_files(run.layout, rows[0])  # the checksums the result records, before reading
    groups: dict[str, Any] = {}
    stored: list[int] = []
    if fields_file:
        attrs, groups = _read_h5(run.layout.fields_dir / fields_file)
        if attrs.get("job_id") != job["job_id"]:
            raise StoreError(f"fields/{fields_file}: holds job {attrs.get('job_id')!r}")
        stored = [int(k) for k in json.loads(attrs.get("stored_stages", "[]"))]
        mesh_file = str(attrs.get("mesh_file", mesh_file) or mesh_file)
        _plain_names(job, fields_file, mesh_file)
    source = f"fields/{fields_file}"
    return _assemble(run, job, rows, groups, stored, mesh_file, source, cache)


def _assemble(
    run: Run,
    job: JobRow,
    rows: list[dict[str, Any]],
    groups: dict[str, Any],
    stored: list[int],
    mesh_file: str,
    source: str,
    cache: dict[Any, Any] | None,
) -> JobFields:
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
    fields, profiles, closure_lines, cell_data = {}, {}, {}, {}
    for k in stored:
        g = groups.get(stage_group(k), {})
        if not set(STAGE_DATASETS) <= set(g):
            raise StoreError(f"{source}: stage {k} lacks {list(STAGE_DATASETS)}")
        u, vm = (np.asarray(g[name]) for name in STAGE_DATASETS)
        if u.shape != points.shape or vm.shape != (len(cells),):
            raise StoreError(f"{source}: stage {k} arrays do not fit the mesh")
        fields[k] = (u, vm)
        if set(PROFILE_DATASETS) <= set(g):
            profiles[k] = _profiles(*(np.asarray(g[name]) for name in PROFILE_DATASETS))
        if set(CLOSURE_LINE_DATASETS) <= set(g):
            closure_lines[k] = {name: np.asarray(g[name], float) for name in CLOSURE_LINE_DATASETS}
        if set(SOLVER_CELL_DATASETS) <= set(g):
            cell_data[k] = {name: np.asarray(g[name], float) for name in SOLVER_CELL_DATASETS}
            if any(len(a) != len(cells) for a in cell_data[k].values()):
                raise StoreError(f"{source}: stage {k} cell arrays do not fit the mesh")
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
        materials=run.sweep.materials,
        profiles=profiles,
        closure_lines=closure_lines,
        source=source,
        cell_data=cell_data,
    )


def _profiles(values: np.ndarray, points: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """A stage's stored profile lines by name: `PROFILE_LINES` first, then any further lines
    the file holds (named ``line_<i>``)."""
    names = [*PROFILE_LINES, *(f"line_{i}" for i in range(len(PROFILE_LINES), len(values)))]
    return {
        names[i]: {"points_mm": np.asarray(points[i], float), "von_mises_kPa": values[i]}
        for i in range(min(len(values), len(points)))
    }


def load_solver_file(run: Run, job: JobRow | None, path: str | Path) -> JobFields:
    """A job from the HDF5 file ``woundsweep solve`` wrote (``path``); its job is the file's
    ``job_index`` (checked against ``job`` when given, and against the run's manifest)."""
    path = Path(path)
    attrs, groups = _read_h5(path)
    if "stage_results" not in attrs or "job_id" not in attrs:
        raise StoreError(f"{path}: not a solver file of `woundsweep solve`")
    file_job = run.job(int(attrs.get("job_index", -1)))
    check_solver_fingerprint(run, file_job, path, attrs)
    if file_job["job_id"] != attrs["job_id"]:
        raise StoreError(f"{path}: holds job {attrs['job_id']!r}, not one of {run.run_dir}")
    if job is not None and job["job_id"] != attrs["job_id"]:
        raise StoreError(f"{path}: holds job {file_job['job_index']}, not job {job['job_index']}")
    try:
        rows = records(json.loads(attrs["stage_results"]))
    except (ValueError, TypeError, KeyError) as err:
        raise StoreError(f"{path}: bad stage_results ({err})") from None
    ok = all(r.get("status") == StageStatus.CONVERGED for r in rows)
    cls = FailureClass.CONVERGED if ok else FailureClass.NOT_CONVERGED
    for r in rows:
        r.update(failure_class=str(cls), fields="all", fields_file=path.name, mesh_file="")
    stored = sorted(int(g.split("_")[1]) for g in groups if g.startswith("stage_"))
    return _assemble(run, file_job, rows, groups, stored, "", str(path), None)


def solve_output(run_dir: str | Path, job_index: int) -> Path:
    """Where ``woundsweep solve`` writes a job without ``--out``."""
    return RunLayout(run_dir).solve_file(job_index)


def open_job(
    run_dir: str | Path,
    job_index: int | None,
    cache: dict[Any, Any] | None = None,
    result: str | Path | None = None,
) -> JobFields:
    """One job of a run directory: from ``result`` (a file `woundsweep solve` wrote) when
    given, else its stored result (`load_job`), else ``RUN_DIR/solve/job_<N>.h5``."""
    from ..config.manifest import load_run
    from ..store.reader import read_results

    run = load_run(run_dir)
    job = run.job(job_index) if job_index is not None else None
    if result is not None:
        return load_solver_file(run, job, result)
    if job is None:
        raise StoreError("give --job N or --result FILE.h5")
    assert job_index is not None  # job is None without it
    rows = read_results(run.run_dir, [str(job["job_id"])], run=run)
    if len(rows) == 0 and current_solve_file(run, job_index) is not None:
        return load_solver_file(run, job, solve_output(run.run_dir, job_index))
    if len(rows) == 0:
        raise StoreError(
            f"job {job_index} has no stored result yet (run `woundsweep run`, or `woundsweep "
            f"solve` to {solve_output(run.run_dir, job_index)})"
        )
    return load_job(run, job, rows, cache)

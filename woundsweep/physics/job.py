"""One job through the stages: stress statistics, `StageResult` rows and the HDF5 output.

Stress statistics of a stage (von Mises of sigma = J^-1 P F^T, paper eq. 20), over the
samples of the stress (a P1 cell's constant value; a P2 cell's values at the points of a
degree-4 rule, `WoundForms.von_mises_samples`, each holding its weight's share of the
cell's volume):

- ``p99_von_mises_kPa``, the "maximal stress": the volume-weighted 99th percentile, i.e. the
  smallest sample value v such that samples with von Mises <= v hold at least 99% of the
  reference volume (independent of how finely the mesh is graded);
- ``p99_von_mises_nodal_kPa``: the paper's estimator as its code computes it, the unweighted
  99th percentile (numpy's linear interpolation) over the mesh's vertices of von Mises
  interpolated into P1: each vertex takes the value of the last cell (mesh order) holding
  it, evaluated at the vertex, as DOLFINx's interpolation assigns it; for comparison only;
- ``p99_von_mises_wound_kPa``: the volume-weighted p99 over the samples of the cells within
  one total thickness of the wound's surface: a wound-local measure that does not shrink as
  the patch grows (the patch-wide p99 is diluted by healthy skin);
- ``max_von_mises_kPa``, the largest sample, and its reference coordinates.

The stored field and the profiles are cell means.

The output file's layout is `woundsweep.store.solverfile`'s: the reported stages' `StageResult`
fields plus diagnostics, the mesh in the input numbering, and the fields of every converged
stage (an unconverged state is never written as a field).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, cast

import numpy as np

from ..core.diagnostics import StageDiagnostics, StageReport
from ..core.errors import GeometryError, SolverError, WoundsweepError
from ..core.schema import ExitCode, MeshData, StageResult, StageStatus, start_stage
from .closure import LineLoads
from .profiles import line_maxima, locate_cells, profile_lines, sample_profiles, wound_edge_x

if TYPE_CHECKING:
    from ..config.manifest import JobRow, Run
    from .forms import StressSamples
    from .materials import JobMaterials
    from .model import WoundModel

__all__ = [
    "JobOutcome",
    "NotConvergedError",
    "StageRecord",
    "job_model",
    "code_nodal_p99",
    "run_stages",
    "solve_job",
    "stress_summary",
    "write_output",
]


class NotConvergedError(WoundsweepError):
    """A stage did not converge (the output file is written; the CLI exits with 3)."""

    exit_code = ExitCode.NOT_CONVERGED


class StageRecord(NamedTuple):
    """A stage's result row, its diagnostics and (if converged) its fields in input order."""

    result: StageResult
    diagnostics: StageDiagnostics
    displacement_mm: np.ndarray | None
    von_mises_kPa: np.ndarray | None
    # Von Mises on the `profiles` lines, (3, PROFILE_POINTS), if converged.
    profiles_kPa: np.ndarray | None = None
    # Closing and contact forces per length along the wound, if converged (with a wound).
    line_loads: LineLoads | None = None
    # P2, if converged: the solver's cell means of its stress samples in input cell order
    # (`woundsweep.physics.forms.cell_means`: the Cauchy stress, the Green-Lagrange strain,
    # J), stored with the stage's field so that exports show the solver's tensors.
    cell_tensors: dict[str, np.ndarray] | None = None


class JobOutcome(NamedTuple):
    """What `solve_job` did."""

    records: list[StageRecord]
    exit_code: int
    out: Path | None
    jit_time_s: float


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    k = int(np.searchsorted(cum, q * cum[-1], side="left"))
    return float(values[order][min(k, len(order) - 1)])


_STRESS_KEYS = (
    "p99_von_mises_kPa",
    "p99_von_mises_wound_kPa",
    "max_von_mises_kPa",
    "max_location_x_mm",
    "max_location_y_mm",
    "max_location_z_mm",
)


def code_nodal_p99(vertex_vm: np.ndarray, cell_vertices: np.ndarray) -> float:
    """The paper code's p99: unweighted over vertices, each with the value of the last cell
    holding it (``vertex_vm`` (cells, 4) at each cell's vertices, mesh order)."""
    n_nodes = int(cell_vertices.max()) + 1
    nodal = np.full(n_nodes, np.nan)
    flat_nodes = np.asarray(cell_vertices).ravel()
    # Fancy assignment keeps the last of repeated indices: the last cell in mesh order.
    nodal[flat_nodes] = np.asarray(vertex_vm, dtype=float).ravel()
    nodal = nodal[np.isfinite(nodal)]
    return float(np.percentile(nodal, 99)) if len(nodal) else math.nan


def stress_summary(
    vm: np.ndarray,
    volumes: np.ndarray,
    cell_nodes: np.ndarray,
    midpoints: np.ndarray,
    samples: StressSamples | None = None,
    corners: np.ndarray | None = None,
    vertex_vm: np.ndarray | None = None,
    near_wound: np.ndarray | None = None,
) -> dict[str, float]:
    """Volume-weighted, wound-local and nodal p99, maximum and its location (see the module
    docstring).

    ``vm`` are cell means; ``samples`` (with the cells' vertex coordinates ``corners``,
    (cells, 4, 3)) replace them for p99 and the maximum. Without samples each cell is one
    sample at its midpoint. A sample with det F <= 0 (a P2 cell inverted inside) has no
    stress and is left out; the stage's ``min_J`` reports it. ``vertex_vm`` (cells, 4) are
    the values at the cells' vertices (default: the cell means); ``near_wound`` (cells,) the
    cells of the wound-local p99 (None: no wound, NaN).
    """
    vm = np.asarray(vm, dtype=float)
    volumes = np.asarray(volumes, dtype=float)
    if vertex_vm is None:
        vertex_vm = np.repeat(vm[:, None], cell_nodes.shape[1], axis=1)
    nodal_p99 = code_nodal_p99(vertex_vm, cell_nodes)
    sampled = samples is not None and corners is not None
    if sampled:
        assert samples is not None  # sampled says so
        values = np.asarray(samples.values, dtype=float)
        weights = volumes[:, None] * np.asarray(samples.weights, dtype=float)[None, :]
    else:
        values, weights = vm[:, None], volumes[:, None]
    valid = np.isfinite(values)
    if sampled and samples.det_F is not None:  # type: ignore[union-attr]  # sampled: not None
        valid &= np.asarray(samples.det_F) > 0  # type: ignore[union-attr]
    if not valid.any():  # every sample inverted: no stress to report
        return {key: math.nan for key in _STRESS_KEYS} | {"p99_von_mises_nodal_kPa": nodal_p99}
    i, j = np.unravel_index(int(np.argmax(np.where(valid, values, -np.inf))), values.shape)
    if sampled:
        assert samples is not None and corners is not None  # sampled says so
        c = np.asarray(corners[i], dtype=float)
        where = c[0] + (c[1:] - c[0]).T @ np.asarray(samples.points[j], dtype=float)
    else:
        where = np.asarray(midpoints[i], dtype=float)
    wound_p99 = math.nan
    if near_wound is not None:
        local = valid & np.asarray(near_wound, dtype=bool)[:, None]
        if local.any():
            wound_p99 = _weighted_quantile(values[local], weights[local], 0.99)
    return {
        "p99_von_mises_kPa": _weighted_quantile(values[valid], weights[valid], 0.99),
        "p99_von_mises_nodal_kPa": nodal_p99,
        "p99_von_mises_wound_kPa": wound_p99,
        "max_von_mises_kPa": float(values[i, j]),
        "max_location_x_mm": float(where[0]),
        "max_location_y_mm": float(where[1]),
        "max_location_z_mm": float(where[2]),
    }


def _finite(x: float | int | None) -> float | int | None:
    """The number itself (ints stay ints), or None for None/NaN/inf (JSON null)."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return None
    return x if isinstance(x, int) else float(x)


def closure_columns(model: WoundModel, stage: int) -> tuple[dict[str, Any], LineLoads | None]:
    """The closure measures of the model's current state as store columns (NaN-free; none
    for an unwounded patch) and the line loads along the wound (`woundsweep.physics.closure`).
    Stage 1's wound is open by design: it gets no ``closed`` or ``interpenetrating`` flag."""
    line = model.closure_line
    if line is None:
        return {}, None
    m = line.measure(model.u)
    cols: dict[str, Any] = {key: _finite(v) for key, v in m.columns().items()}
    if stage >= 2:
        cols["closed"] = int(m.closed)
        # Mirrored zone points overlapping, or the audit's flank nodes inside the other side.
        found = (
            model.results[stage].diagnostics.get("audit_inside_nodes", 0)
            if stage in model.results
            else 0
        )
        cols["interpenetrating"] = int(m.interpenetrating or found > 0)
    closing = model.closing_forces if stage >= 2 else None
    return cols, line.line_loads(closing, model.contact_forces())


def _line_load_maxima(loads: LineLoads) -> dict[str, float]:
    """Per line load its largest value (mN/mm) and where along the wound it is (y, mm)."""
    out: dict[str, float] = {}
    for name, vals in (("closing", loads.closing_mN_per_mm), ("contact", loads.contact_mN_per_mm)):
        i = int(np.argmax(vals))
        out[f"{name}_line_load_max_mN_per_mm"] = float(vals[i])
        out[f"{name}_line_load_max_at_mm"] = float(loads.y_mm[i])
    return out


def run_stages(
    model: WoundModel,
    materials: JobMaterials,
    last_stage: int,
    echo: Callable[[StageRecord], None] | None = None,
) -> list[StageRecord]:
    """Run stages 1..last_stage on a `woundsweep.physics.WoundModel`. A stage runs when the
    stage before it ran and the stage it starts from (`schema.start_stage`) converged, so an
    unconverged stage 3 does not stop stages 4-6. Returns one record per stage
    1..last_stage (``not-run`` for a stage that could not run).
    """
    from .stages import run_stage

    model.set_materials(materials)
    d = model.domain
    dofs = d.n_dofs
    cells = len(d.cells)
    degree = int(d.degree)
    cell_input_order = np.argsort(d.cell_input)
    lines = profile_lines(d.X, wound_edge_x(d.points, d.facets, d.facet_tags))
    line_cells = locate_cells(d, lines.reshape(-1, 3)).reshape(lines.shape[:2])
    records: list[StageRecord] = []
    status: dict[int, str] = {0: StageStatus.CONVERGED}
    for k in range(1, last_stage + 1):
        ran = k == 1 or status[k - 1] != StageStatus.NOT_RUN
        if not ran or status[start_stage(k, model.closure_load)] != StageStatus.CONVERGED:
            status[k] = StageStatus.NOT_RUN
            not_run = StageResult(k, StageStatus.NOT_RUN, element_degree=degree)
            records.append(StageRecord(not_run, {}, None, None))
            continue
        out = run_stage(model, k)
        s = out.solve
        ok = s.status == StageStatus.CONVERGED
        vm = model.forms.von_mises_cells() if ok else None
        tensors: dict[str, np.ndarray] | None = None
        stats: dict[str, float] = {}
        min_J = d.min_det(model.u)
        if vm is not None:
            samples = model.forms.von_mises_samples()  # None on P1: the cells are the samples
            corners = None if samples is None else d.X[d.cell_vertices]
            stats = stress_summary(
                vm,
                d.volumes,
                d.cell_vertices,
                d.midpoints,
                samples,
                corners,
                model.forms.von_mises_vertices() if samples is not None else None,
                d.near_wound_cells(),
            )
            if samples is not None and samples.det_F is not None:
                min_J = min(min_J, float(samples.det_F.min()))
            if samples is not None:
                from .forms import cell_means

                means = cell_means(model.forms.stress_tensor_samples())
                tensors = {
                    name: a[cell_input_order].astype(np.float32) for name, a in means.items()
                }
        closure, loads = closure_columns(model, k) if ok else ({}, None)
        contact = {
            key: _finite(out.diagnostics[key])
            for key in ("n_penetrating", "max_penetration_mm", "contact_force_mN")
            if key in out.diagnostics
        }
        result = StageResult(
            stage=k,
            status=s.status,
            newton_iterations=int(s.iterations),
            time_s=float(out.time_s),
            min_J=_finite(min_J),
            residual_norm=_finite(s.residual_norm),
            dofs=dofs,
            cells=cells,
            element_degree=degree,
            **stats,  # type: ignore[arg-type]  # StageResult's float fields
            **contact,  # type: ignore[arg-type]  # its n_penetrating is an int
            **closure,
        )
        diagnostics = {
            "load_increments": int(s.increments),
            "load_cuts": int(s.cuts),
            "load_reached": float(s.load_reached),
            "assembly_time_s": float(s.assembly_time_s),
            "factor_time_s": float(s.factor_time_s),
        }
        diagnostics.update(
            {key: v for key, v in out.diagnostics.items() if key not in result._fields}
        )
        profiles = sample_profiles(line_cells, vm) if vm is not None else None
        if profiles is not None:
            diagnostics.update(line_maxima(lines, profiles))
        if loads is not None:
            diagnostics.update(_line_load_maxima(loads))
        rec = StageRecord(
            result,
            cast(StageDiagnostics, {key: _finite(v) for key, v in diagnostics.items()}),
            model.displacement_input().astype(np.float32) if ok else None,
            vm[cell_input_order].astype(np.float32) if vm is not None else None,
            profiles,
            loads,
            tensors,
        )
        records.append(rec)
        if echo is not None:
            echo(rec)
        status[k] = s.status
    return records


def write_output(
    path: str | Path,
    attrs: Mapping[str, Any],
    mesh: MeshData,
    records: list[StageRecord],
    first_stage: int = 1,
) -> None:
    """Write the job's solver file atomically (records before ``first_stage`` are left out)."""
    from ..store.solverfile import CLOSURE_LINE_DATASETS, write_solver_file
    from . import compat

    keep = [r for r in records if r.result.stage >= first_stage]
    reports = [StageReport(r.result, r.diagnostics) for r in keep]
    fields = {
        r.result.stage: (r.displacement_mm, r.von_mises_kPa)
        for r in keep
        if r.displacement_mm is not None and r.von_mises_kPa is not None
    }
    edge = wound_edge_x(mesh.points, mesh.facets, mesh.facet_tags)
    lines = profile_lines(mesh.points, edge).astype(np.float32)
    profiles: dict[int, dict[str, np.ndarray]] = {}
    for r in keep:
        k = r.result.stage
        if k not in fields:
            continue
        if r.profiles_kPa is not None:
            profiles.setdefault(k, {})["profile_von_mises_kPa"] = r.profiles_kPa.astype(np.float32)
            profiles[k]["profile_points_mm"] = lines
        if r.line_loads is not None:
            for name, data in zip(CLOSURE_LINE_DATASETS, r.line_loads):
                profiles.setdefault(k, {})[name] = np.asarray(data, dtype=np.float32)
        if r.cell_tensors is not None:
            profiles.setdefault(k, {}).update(r.cell_tensors)
    attrs = {**attrs, "dolfinx_version": compat.DOLFINX_VERSION}
    write_solver_file(path, attrs, mesh, reports, fields, profiles)


def job_model(
    run: Run, row: JobRow, mesh: MeshData, jit: dict[str, Any] | None = None
) -> tuple[WoundModel, JobMaterials]:
    """The `WoundModel` of a manifest row on ``mesh`` with the run's settings, and the job's
    materials (GeometryError for a mesh that does not fit the contract or was built for
    another element degree than the sweep's)."""
    from .materials import JobMaterials
    from .model import WoundModel

    job_index = int(row["job_index"])
    skin, angle = str(row["skin_type"]), float(row["orientation_deg"])
    if skin not in run.sweep.materials.skin_types:
        raise SolverError(f"job {job_index}: unknown skin type {skin!r}")
    # The size law spaces a mesh's nodes for its element: a P1 mesh solved as P2 (or the
    # reverse) is another discretisation than the sweep's.
    sized, degree = mesh.info.get("element_degree"), run.sweep.solver.element_degree
    if sized is not None and sized != degree:
        raise GeometryError(
            f"job {job_index}: the mesh was built for P{sized} elements, the sweep's are P{degree}"
        )
    materials = JobMaterials.from_sweep(run.sweep.materials, skin, angle)
    try:
        model = WoundModel(mesh, run.sweep.solver, run.sweep.stages, jit=jit)
    except ValueError as err:  # the mesh's tags or numbering do not fit the contract
        raise GeometryError(f"job {job_index}: unusable mesh: {err}") from None
    return model, materials


def solve_job(
    run_dir: str | Path,
    job_index: int,
    stages: tuple[int, int] = (1, 6),
    out: str | Path | None = None,
    echo: Callable[[StageRecord], None] | None = None,
    jit: dict[str, Any] | None = None,
    run: Run | None = None,
) -> JobOutcome:
    """Solve manifest job ``job_index`` of a run directory through ``stages`` (A, B).

    Stages 1..B run (a later stage starts from the earlier ones); results of A..B are
    reported and written to ``out`` (default ``RUN_DIR/solve/job_<N>.h5``).
    """
    from ..config.manifest import load_run
    from ..mesh.cache import get_mesh

    run = run if run is not None else load_run(run_dir)  # a caller's run: its sweep, checked
    row = run.job(job_index)
    mesh = get_mesh(run.run_dir, run.geometry(row)).mesh
    model, materials = job_model(run, row, mesh, jit)
    records = run_stages(model, materials, stages[1], echo=echo)
    reported = [r for r in records if r.result.stage >= stages[0]]
    ok = all(r.result.status == StageStatus.CONVERGED for r in records)
    path = Path(out) if out is not None else run.layout.solve_file(job_index)
    attrs = {
        "job_id": str(row["job_id"]),
        "job_index": int(job_index),
        "geometry_id": str(row["geometry_id"]),
        "jit_time_s": float(model.jit_time_s),
    }
    write_output(path, attrs, mesh, records, first_stage=stages[0])
    code = ExitCode.OK if ok else ExitCode.NOT_CONVERGED
    return JobOutcome(reported, code, path, model.jit_time_s)

"""ParaView files of a stored job: per stored stage a multiblock of the volume and the exterior
surface, a PVD series over the stages, the reference mesh, and a JSON description.

``DIR/job-<index>/`` holds

- ``job-<index>.pvd``: the series (timestep = stage) of ``job-<index>_stage<k>.vtm``, each a
  multiblock of two blocks, ``volume`` (``..._stage<k>_volume.vtu``, the tetrahedra) and
  ``surface`` (``..._stage<k>_surface.vtu``, the exterior triangles on their own nodes);
- ``job-<index>_mesh.vtu``: the reference mesh and its cell tags alone;
- ``job-<index>.json``: job id, units, every array with its unit and meaning, per-stage status
  and why a stage has no field;
- with ``xdmf=True``, ``job-<index>.xdmf`` + ``.h5``: the volume series in one HDF5 file.

Both blocks carry point data ``displacement_mm`` and cell data (`VOLUME_FIELDS`): the stored
von Mises (the cell mean of the solver's samples), ``inverted``, ``cell_tag`` and, computed as
the solver computes them (`tensor_source`), the Cauchy stress tensor, the principal stresses,
the Green-Lagrange strain and det F: on a P1 run from the stored displacement (`viz.mechanics`:
F is constant per cell, so these are the solver's own values and the von Mises of the exported
tensor is the stored one to float32 rounding); on a P2 run only where the fields file holds
the solver's cell means (`jobdata.SOLVER_CELL_DATASETS`), since the vertex values of a
quadratic field do not determine its stress. A cell where the solver's state has no stress
(det F <= 0, or a non-finite value) is marked ``inverted`` = 1 and its stresses written as 0:
no exported value is NaN or infinite. A surface triangle carries the values of the tetrahedron
it bounds, its facet tag, the closure zone, and (with the tensor) the normal traction and the
contact pressure on the wound's flanks (`SURFACE_FIELDS`). Every name carries its unit; the
units and how each array was computed are in ``job-<index>.json`` (and, for a reader of the
XML, in a comment of each VTU).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..core.schema import CELL_TAGS, FACET_TAGS, STAGE_NAMES, UNITS, WOUND_TAGS
from .html import CELL_MEAN_MAX, STRESS_LABELS
from .jobdata import JobFields
from .mechanics import CellMechanics, cell_mechanics
from .surface import ExteriorSurface, surface_of
from .vtkfiles import pvd, vtm, write_text, write_vtu

__all__ = [
    "SURFACE_FIELDS",
    "TENSOR_FIELDS",
    "TENSOR_SOURCES",
    "VOLUME_FIELDS",
    "export_job",
    "job_dir_name",
    "stage_cell_fields",
    "tensor_source",
]

# name -> (unit, meaning): the cell data of the volume block (and of the surface's triangles).
VOLUME_FIELDS: dict[str, tuple[str, str]] = {
    "von_mises_kPa": (
        "kPa",
        "von Mises stress of cauchy_stress_kPa where it is exported (P2: of the cell's mean "
        "tensor), else the cell mean of the solver's samples as stored (P1: the cell's "
        "constant value); 0 where inverted",
    ),
    "von_mises_sample_mean_kPa": (
        "kPa",
        "P2 with the solver's tensors: the cell mean of the solver's von Mises samples as "
        "stored (at least the von Mises of the mean tensor); 0 where inverted",
    ),
    "cauchy_stress_kPa": (
        "kPa",
        "Cauchy stress tensor (9 components, symmetric); 0 where inverted",
    ),
    "principal_stress_kPa": ("kPa", "principal Cauchy stresses, largest first; 0 where inverted"),
    "green_lagrange_strain": ("1", "Green-Lagrange strain E = (F^T F - I) / 2 (9 components)"),
    "det_F": ("1", "volume ratio J = det F"),
    "inverted": (
        "1",
        "1 where the solver's state has no stress in the cell (det F <= 0 or a non-finite "
        "value): its stresses are written as 0",
    ),
    "cell_tag": ("1", "1 dermis, 2 subcutis"),
}
# The arrays that need the stress tensor (left out when a stage has none, `tensor_source`).
TENSOR_FIELDS = (
    "cauchy_stress_kPa",
    "principal_stress_kPa",
    "green_lagrange_strain",
    "det_F",
    "normal_traction_kPa",
    "contact_pressure_kPa",
)
# How a stage's tensor arrays were computed (job-<index>.json, "stages"), by `tensor_source`.
TENSOR_SOURCES = {
    "displacement": (
        "from the stored displacement per tetrahedron (F = I + grad u, which on a P1 run is "
        "the solver's own, constant per cell) and the strain energy of physics.materials: the "
        "von Mises of cauchy_stress_kPa equals the stored von_mises_kPa to float32 rounding"
    ),
    "solver": (
        "the solver's cell means of its samples, read from the fields file as they are; "
        "von_mises_kPa is the von Mises of that mean tensor (at most the mean of the samples' "
        "von Mises, kept as von_mises_sample_mean_kPa)"
    ),
    "none": (
        "not exported: the store keeps a P2 field's vertex values only, and their linear "
        "interpolant is not the solver's state (its stresses contradict von_mises_kPa and it "
        "can be inverted where the solver's field is not)"
    ),
}
SURFACE_FIELDS: dict[str, tuple[str, str]] = {
    **VOLUME_FIELDS,
    "cell_tag": ("1", "the tag of the tetrahedron the triangle bounds"),
    "facet_tag": ("1", "11-18 as in woundsweep.core.schema.FACET_TAGS"),
    "closure_zone": ("1", "1 on the closure zone's wound triangles"),
    "normal_traction_kPa": ("kPa", "n . sigma . n on the deformed triangle (n outward)"),
    "contact_pressure_kPa": (
        "kPa",
        "-n . sigma . n where compressive on the wound's flanks (tags 17, 18), else 0",
    ),
}
POINT_FIELDS = {"displacement_mm": ("mm", "displacement from the reference mesh")}


def job_dir_name(job_index: int) -> str:
    return f"job-{int(job_index)}"


def _units(*tables: dict[str, tuple[str, str]]) -> dict[str, str]:
    return {k: u for t in tables for k, (u, _) in t.items()}


def tensor_source(jf: JobFields, stage: int) -> str:
    """How the stage's tensor arrays are computed, a key of `TENSOR_SOURCES`: ``solver``
    where the fields file holds the solver's cell means, ``displacement`` on a P1 run (or
    rows that name no element), ``none`` on a P2 run without them."""
    if stage in jf.cell_data:
        return "solver"
    if jf.element_degree is None or jf.element_degree == 1:
        return "displacement" if jf.materials is not None else "none"
    return "none"


def _mechanics(jf: JobFields, stage: int) -> CellMechanics:
    assert jf.materials is not None  # tensor_source says "displacement" only with them
    return cell_mechanics(
        jf.points, jf.cells, jf.cell_tags, jf.fields[stage][0], jf.materials,
        str(jf.job["skin_type"]), float(jf.job["orientation_deg"]),
    )  # fmt: skip


def _principal(sigma: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.linalg.eigvalsh(sigma)[:, ::-1])


def stage_cell_fields(jf: JobFields, stage: int) -> dict[str, np.ndarray]:
    """The stage's cell arrays (`VOLUME_FIELDS`, the tensor ones as `tensor_source` says),
    every value finite: a cell without stress is ``inverted`` = 1 with its stresses 0."""
    vm = np.asarray(jf.fields[stage][1], np.float32)
    bad = ~np.isfinite(vm)
    source = tensor_source(jf, stage)
    tensors: dict[str, np.ndarray] = {}
    if source == "displacement":
        m = _mechanics(jf, stage)
        sigma, E, J = m.cauchy_kPa, m.green_lagrange, m.det_F
    elif source == "solver":
        d = jf.cell_data[stage]
        sigma = d["cauchy_stress_kPa"].reshape(-1, 3, 3)
        E, J = d["green_lagrange_strain"].reshape(-1, 3, 3), d["det_F"]
    if source != "none":
        bad |= ~np.isfinite(sigma).all(axis=(1, 2)) | ~(J > 0)
        sigma = np.where(bad[:, None, None], 0.0, 0.5 * (sigma + sigma.transpose(0, 2, 1)))
        tensors = {
            "cauchy_stress_kPa": sigma,
            "principal_stress_kPa": _principal(sigma),
            "green_lagrange_strain": np.where(np.isfinite(E), E, 0.0),
            "det_F": np.where(np.isfinite(J), J, 0.0),
        }
    extra: dict[str, np.ndarray] = {}
    if source == "solver":
        dev = tensors["cauchy_stress_kPa"] - np.trace(tensors["cauchy_stress_kPa"], axis1=1,
                                                      axis2=2)[:, None, None] / 3 * np.eye(3)  # fmt: skip
        extra["von_mises_sample_mean_kPa"] = np.where(bad, np.float32(0), vm)
        vm = np.sqrt(1.5 * np.sum(dev * dev, axis=(1, 2))).astype(np.float32)
    return {
        "von_mises_kPa": np.where(bad, np.float32(0), vm),
        **extra,
        **tensors,
        "inverted": bad.astype(np.int32),
        "cell_tag": np.asarray(jf.cell_tags, np.int32),
    }


def _normals(jf: JobFields, owner: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Unit outward normals of the deformed exterior triangles."""
    x = jf.points + np.asarray(u, float)
    tri = x[jf.facets]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = x[jf.cells[owner]].mean(axis=1)
    n *= np.where(np.einsum("ij,ij->i", n, tri[:, 0] - centre) < 0, -1.0, 1.0)[:, None]
    return n / np.linalg.norm(n, axis=1)[:, None]


def _surface_fields(
    jf: JobFields, owner: np.ndarray, cell: dict[str, np.ndarray], u: np.ndarray
) -> dict[str, np.ndarray]:
    out = {k: v[owner] for k, v in cell.items()}
    out["facet_tag"] = jf.facet_tags.astype(np.int32)
    out["closure_zone"] = jf.zone.astype(np.int32)
    if "cauchy_stress_kPa" in cell:
        n = _normals(jf, owner, u)
        snn = np.einsum("ti,tij,tj->t", n, cell["cauchy_stress_kPa"][owner].astype(float), n)
        flank = np.isin(jf.facet_tags, WOUND_TAGS)
        out["normal_traction_kPa"] = snn
        out["contact_pressure_kPa"] = np.where(flank, np.maximum(-snn, 0.0), 0.0)
    return out


def _write_stage(jf: JobFields, d: Path, name: str, k: int, surf: ExteriorSurface) -> str:
    u = jf.fields[k][0]
    cell = stage_cell_fields(jf, k)
    vol, srf = f"{name}_stage{k}_volume.vtu", f"{name}_stage{k}_surface.vtu"
    u32 = np.asarray(u, np.float32)
    write_vtu(
        d / vol, jf.points, [("tetra", jf.cells)], {"displacement_mm": u32},
        {key: [v] for key, v in cell.items()}, _units(POINT_FIELDS, VOLUME_FIELDS),
    )  # fmt: skip
    sf = _surface_fields(jf, surf.owner, cell, u)
    write_vtu(
        d / srf, jf.points[surf.nodes], [("triangle", surf.triangles)],
        {"displacement_mm": u32[surf.nodes]}, {key: [v] for key, v in sf.items()},
        _units(POINT_FIELDS, SURFACE_FIELDS),
    )  # fmt: skip
    fname = f"{name}_stage{k}.vtm"
    write_text(d / fname, vtm([("volume", vol), ("surface", srf)]))
    return fname


def _write_xdmf(jf: JobFields, d: Path, name: str) -> str:
    import meshio

    class _Writer(meshio.xdmf.TimeSeriesWriter):
        """meshio's writer with its HDF5 file beside the XDMF file (meshio's own opens
        ``<stem>.h5`` in the working directory); the XDMF names it relative to itself."""

        def __enter__(self) -> _Writer:
            import h5py

            self.h5_filename = str(self.filename.with_suffix(".h5"))
            self.h5_file = h5py.File(self.h5_filename, "w")
            return self

    path = d / f"{name}.xdmf"
    with _Writer(path) as w:
        w.write_points_cells(jf.points, [("tetra", jf.cells)])
        for k in sorted(jf.fields):
            u = jf.fields[k][0]
            cell = stage_cell_fields(jf, k)
            w.write_data(
                k,
                point_data={"displacement_mm": np.asarray(u, np.float64)},
                cell_data={
                    key: [np.asarray(v, np.float64).reshape(len(v), -1).squeeze()]
                    for key, v in cell.items()
                },
            )
    return path.name


def _stage_numbers(jf: JobFields, stage: int) -> dict[str, Any]:
    """A stored stage's tensor source, inverted cells and its stress numbers, each named for
    what it is (`html.STRESS_LABELS`)."""
    if stage not in jf.fields:
        return {}
    cell = stage_cell_fields(jf, stage)
    row = next((r for r in jf.rows if int(r["stage"]) == stage), {})
    numbers = {key: _finite(row.get(key)) for key in STRESS_LABELS if key in row}
    numbers[CELL_MEAN_MAX] = float(cell["von_mises_kPa"].max())
    return {
        "tensor_source": tensor_source(jf, stage),
        "inverted_cells": int(cell["inverted"].sum()),
        "min_J": _finite(row.get("min_J")),
        "stress_kPa": numbers,
    }


def _finite(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if np.isfinite(f) else None


def export_job(jf: JobFields, out_dir: str | Path, xdmf: bool = False) -> dict[str, Any]:
    """Write the job's files under ``out_dir/job-<index>/``; returns its description.

    The description (also written as ``job-<index>.json``) lists the files, the exported
    stages, every array with its unit and, for each requested stage without a field, why.
    """
    name = job_dir_name(jf.job["job_index"])
    d = Path(out_dir) / name
    d.mkdir(parents=True, exist_ok=True)
    write_vtu(
        d / f"{name}_mesh.vtu", jf.points, [("tetra", jf.cells)], {},
        {"cell_tag": [jf.cell_tags.astype(np.int32)]}, _units(VOLUME_FIELDS),
    )  # fmt: skip
    surf = surface_of(jf.points, jf.cells, jf.facets, jf.zone)
    files = {k: _write_stage(jf, d, name, k, surf) for k in sorted(jf.fields)}
    write_text(d / f"{name}.pvd", pvd(sorted(files.items())))
    info: dict[str, Any] = {
        "job_id": jf.job["job_id"],
        "job_index": int(jf.job["job_index"]),
        "units": UNITS,
        "series": f"{name}.pvd",
        "reference_mesh": f"{name}_mesh.vtu",
        "blocks": {"volume": "tetrahedra", "surface": "exterior triangles"},
        "point_data": {k: {"unit": u, "meaning": m} for k, (u, m) in POINT_FIELDS.items()},
        "cell_data": {k: {"unit": u, "meaning": m} for k, (u, m) in SURFACE_FIELDS.items()},
        "cell_tags": dict(CELL_TAGS),
        "facet_tags": dict(FACET_TAGS),
        "element_degree": jf.element_degree,
        "tensor_sources": dict(TENSOR_SOURCES),
        "stress_numbers": dict(STRESS_LABELS),
        "xdmf": _write_xdmf(jf, d, name) if xdmf and jf.fields else None,
        "xdmf_data": f"{name}.h5" if xdmf and jf.fields else None,
        "stages": [
            {
                "stage": n.stage,
                "name": STAGE_NAMES.get(n.stage, ""),
                "status": n.status,
                "file": files.get(n.stage),
                "not_exported": n.reason or None,
                **_stage_numbers(jf, n.stage),
            }
            for n in jf.notes
        ],
    }
    write_text(d / f"{name}.json", json.dumps(info, indent=2) + "\n")
    return info

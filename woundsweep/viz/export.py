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
von Mises and, from the stored displacement (`viz.mechanics`), the Cauchy stress tensor, the
principal stresses, the Green-Lagrange strain and det F; a surface triangle carries the values
of the tetrahedron it bounds (no NaN anywhere), its facet tag, the closure zone, the normal
traction and the contact pressure on the wound's flanks (`SURFACE_FIELDS`). Every VTU names
the unit of each array in its field data (`vtkfiles.UNITS_ARRAY`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..core.schema import CELL_TAGS, FACET_TAGS, STAGE_NAMES, UNITS, WOUND_TAGS
from .jobdata import JobFields
from .mechanics import CellMechanics, cell_mechanics
from .surface import ExteriorSurface, surface_of
from .vtkfiles import pvd, vtm, write_text, write_vtu

__all__ = ["SURFACE_FIELDS", "VOLUME_FIELDS", "export_job", "job_dir_name"]

# name -> (unit, meaning): the cell data of the volume block (and of the surface's triangles).
VOLUME_FIELDS: dict[str, tuple[str, str]] = {
    "von_mises_kPa": ("kPa", "cellwise von Mises stress, as the solver stored it"),
    "cauchy_stress_kPa": ("kPa", "Cauchy stress tensor (9 components, symmetric)"),
    "principal_stress_kPa": ("kPa", "principal Cauchy stresses, largest first"),
    "green_lagrange_strain": ("1", "Green-Lagrange strain E = (F^T F - I) / 2 (9 components)"),
    "det_F": ("1", "volume ratio J = det F"),
    "cell_tag": ("1", "1 dermis, 2 subcutis"),
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


def _mechanics(jf: JobFields, stage: int) -> CellMechanics:
    if jf.materials is None:
        raise ValueError("the job's materials are unknown")
    return cell_mechanics(
        jf.points, jf.cells, jf.cell_tags, jf.fields[stage][0], jf.materials,
        str(jf.job["skin_type"]), float(jf.job["orientation_deg"]),
    )  # fmt: skip


def _cell_fields(m: CellMechanics, vm: np.ndarray, tags: np.ndarray) -> dict[str, np.ndarray]:
    return {
        "von_mises_kPa": np.asarray(vm, np.float32),
        "cauchy_stress_kPa": m.cauchy_kPa.astype(np.float32),
        "principal_stress_kPa": m.principal_kPa.astype(np.float32),
        "green_lagrange_strain": m.green_lagrange.astype(np.float32),
        "det_F": m.det_F.astype(np.float32),
        "cell_tag": np.asarray(tags, np.int32),
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
    n = _normals(jf, owner, u)
    snn = np.einsum("ti,tij,tj->t", n, cell["cauchy_stress_kPa"][owner].astype(float), n)
    flank = np.isin(jf.facet_tags, WOUND_TAGS)
    out["facet_tag"] = jf.facet_tags.astype(np.int32)
    out["closure_zone"] = jf.zone.astype(np.int32)
    out["normal_traction_kPa"] = snn.astype(np.float32)
    out["contact_pressure_kPa"] = np.where(flank, np.maximum(-snn, 0.0), 0.0).astype(np.float32)
    return out


def _write_stage(jf: JobFields, d: Path, name: str, k: int, surf: ExteriorSurface) -> str:
    u, vm = jf.fields[k]
    cell = _cell_fields(_mechanics(jf, k), vm, jf.cell_tags)
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

    path = d / f"{name}.xdmf"
    with meshio.xdmf.TimeSeriesWriter(path) as w:
        w.write_points_cells(jf.points, [("tetra", jf.cells)])
        for k in sorted(jf.fields):
            u, vm = jf.fields[k]
            cell = _cell_fields(_mechanics(jf, k), vm, jf.cell_tags)
            w.write_data(
                k,
                point_data={"displacement_mm": np.asarray(u, np.float64)},
                cell_data={
                    key: [np.asarray(v, np.float64).reshape(len(v), -1).squeeze()]
                    for key, v in cell.items()
                },
            )
    return path.name


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
        "derived_from": "the stored vertex displacement, cell by cell (F = I + grad u)",
        "xdmf": _write_xdmf(jf, d, name) if xdmf and jf.fields else None,
        "stages": [
            {
                "stage": n.stage,
                "name": STAGE_NAMES.get(n.stage, ""),
                "status": n.status,
                "file": files.get(n.stage),
                "not_exported": n.reason or None,
            }
            for n in jf.notes
        ],
    }
    write_text(d / f"{name}.json", json.dumps(info, indent=2) + "\n")
    return info

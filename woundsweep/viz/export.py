"""ParaView series of a stored job: one VTU per stored stage and a PVD that orders them.

``DIR/job-<index>/`` holds ``job-<index>.pvd`` (the series: timestep = stage number),
``job-<index>_stage<k>.vtu`` per stored stage, ``job-<index>_mesh.vtu`` (the reference mesh
and its tags alone) and ``job-<index>.json`` (job id, units, per-stage status and why a
stage has no field). Every VTU holds the reference mesh as two cell blocks, the tetrahedra
and the exterior triangles, with

- point data ``displacement_mm`` (3 components; Warp By Vector shows the deformed state),
- cell data ``von_mises_kPa`` (cellwise; NaN on the triangles), ``cell_tag`` (1 dermis,
  2 subcutis; 0 on triangles), ``facet_tag`` (11-18 as in `schema.FACET_TAGS`; 0 on
  tetrahedra) and ``closure_zone`` (1 on the closure zone's wound triangles),
The stage of a VTU is its PVD timestep (and in its name); units and the per-stage notes are
in the JSON. Files are written by meshio (binary, zlib), each atomically.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..core.fsutil import atomic_write
from ..core.schema import CELL_TAGS, FACET_TAGS, STAGE_NAMES, UNITS
from .jobdata import JobFields

__all__ = ["export_job", "job_dir_name"]


def job_dir_name(job_index: int) -> str:
    return f"job-{int(job_index)}"


def _mesh(jf: JobFields, stage: int | None) -> Any:
    import meshio

    n_tet, n_tri = len(jf.cells), len(jf.facets)
    u = jf.fields[stage][0] if stage is not None else np.zeros_like(jf.points)
    cell_data: dict[str, list[np.ndarray]] = {
        "cell_tag": [jf.cell_tags.astype(np.int32), np.zeros(n_tri, np.int32)],
        "facet_tag": [np.zeros(n_tet, np.int32), jf.facet_tags.astype(np.int32)],
        "closure_zone": [np.zeros(n_tet, np.int32), jf.zone.astype(np.int32)],
    }
    if stage is not None:
        vm = jf.fields[stage][1].astype(np.float32)
        cell_data["von_mises_kPa"] = [vm, np.full(n_tri, np.nan, np.float32)]
    return meshio.Mesh(
        jf.points,
        [("tetra", jf.cells), ("triangle", jf.facets)],
        point_data={"displacement_mm": np.asarray(u, np.float32)},
        cell_data=cell_data,
    )


def _write_vtu(path: Path, mesh: Any) -> None:
    import meshio

    def write(tmp: str) -> None:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression="zlib")

    atomic_write(path, write)


def _pvd(files: list[tuple[int, str]]) -> str:
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
    ]
    lines += [
        f'    <DataSet timestep="{k}" group="" part="0" file={quoteattr(name)}/>'
        for k, name in files
    ]
    lines += ["  </Collection>", "</VTKFile>", ""]
    return "\n".join(lines)


def export_job(jf: JobFields, out_dir: str | Path) -> dict[str, Any]:
    """Write the job's series under ``out_dir/job-<index>/``; returns its description.

    The description (also written as ``job-<index>.json``) lists the files, the exported
    stages and, for each requested stage without a field, the reason.
    """
    name = job_dir_name(jf.job["job_index"])
    d = Path(out_dir) / name
    d.mkdir(parents=True, exist_ok=True)
    _write_vtu(d / f"{name}_mesh.vtu", _mesh(jf, None))
    files = []
    for k in sorted(jf.fields):
        fname = f"{name}_stage{k}.vtu"
        _write_vtu(d / fname, _mesh(jf, k))
        files.append((k, fname))
    pvd = d / f"{name}.pvd"
    atomic_write(pvd, lambda tmp: Path(tmp).write_text(_pvd(files)))
    info = {
        "job_id": jf.job["job_id"],
        "job_index": int(jf.job["job_index"]),
        "units": UNITS,
        "series": pvd.name,
        "reference_mesh": f"{name}_mesh.vtu",
        "point_data": {"displacement_mm": "displacement (mm) from the reference mesh"},
        "cell_data": {
            "von_mises_kPa": "cellwise von Mises stress (kPa); NaN on triangles",
            "cell_tag": dict(CELL_TAGS),
            "facet_tag": dict(FACET_TAGS),
            "closure_zone": "1 on the closure zone's wound triangles",
        },
        "stages": [
            {
                "stage": n.stage,
                "name": STAGE_NAMES.get(n.stage, ""),
                "status": n.status,
                "file": f"{name}_stage{n.stage}.vtu" if n.stored else None,
                "not_exported": n.reason or None,
            }
            for n in jf.notes
        ],
    }
    text = json.dumps(info, indent=2) + "\n"
    atomic_write(d / f"{name}.json", lambda tmp: Path(tmp).write_text(text))
    return info

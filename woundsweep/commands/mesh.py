"""``woundsweep mesh RUN_DIR (--job N | --geometry ID | --all) [--out FILE.vtu]``."""

from __future__ import annotations

import statistics
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

import click
import numpy as np
import pandas as pd
from tqdm import tqdm

from ..config.manifest import JobRow, Run, load_run
from ..core.errors import GeometryError, StoreError
from ..core.fsutil import atomic_write, check_output_file
from ..core.schema import MeshData
from ..mesh.cache import CachedMesh, get_mesh

__all__ = ["cmd", "mesh_geometry", "write_vtu"]

_VTK_TETRA, _VTK_TRIANGLE = 10, 5


def write_vtu(path: str | Path, mesh: MeshData) -> None:
    """Write an ASCII VTK UnstructuredGrid (ParaView) holding the tets and the boundary facets.

    Cell data: ``cell_tag`` (1 dermis, 2 subcutis; 0 on facets) and ``facet_tag`` (11-17;
    0 on tets); threshold ``facet_tag >= 11`` in ParaView to see the tagged boundary.
    """
    n_tet, n_tri = len(mesh.cells), len(mesh.facets)
    connectivity = np.concatenate([mesh.cells.ravel(), mesh.facets.ravel()])
    offsets = np.concatenate([4 * np.arange(1, n_tet + 1), 4 * n_tet + 3 * np.arange(1, n_tri + 1)])
    types = np.concatenate(
        [np.full(n_tet, _VTK_TETRA, np.uint8), np.full(n_tri, _VTK_TRIANGLE, np.uint8)]
    )
    cell_tag = np.concatenate([mesh.cell_tags, np.zeros(n_tri, np.int32)])
    facet_tag = np.concatenate([np.zeros(n_tet, np.int32), mesh.facet_tags])

    def array(name: str, vtk_type: str, values: np.ndarray, fmt: str, comps: int = 1) -> str:
        body = " ".join(fmt % v for v in np.asarray(values).ravel())
        ncomp = f' NumberOfComponents="{comps}"' if comps > 1 else ""
        label = f' Name="{name}"' if name else ""
        return f'<DataArray type="{vtk_type}"{label}{ncomp} format="ascii">{body}</DataArray>\n'

    text = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64">\n<UnstructuredGrid>\n'
        f'<Piece NumberOfPoints="{len(mesh.points)}" NumberOfCells="{n_tet + n_tri}">\n'
        "<Points>\n" + array("", "Float64", mesh.points, "%.17g", 3) + "</Points>\n"
        "<Cells>\n"
        + array("connectivity", "Int64", connectivity, "%d")
        + array("offsets", "Int64", offsets, "%d")
        + array("types", "UInt8", types, "%d")
        + "</Cells>\n"
        '<CellData Scalars="cell_tag">\n'
        + array("cell_tag", "Int32", cell_tag, "%d")
        + array("facet_tag", "Int32", facet_tag, "%d")
        + "</CellData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n"
    )

    def _write(tmp: str) -> None:
        Path(tmp).write_text(text)

    atomic_write(path, _write)


def mesh_geometry(run: Run, row: JobRow | pd.Series) -> CachedMesh:
    """Build or reuse the mesh of the geometry of manifest ``row`` with the sweep's closure
    zone and element degree (errors name its job)."""
    # A Series is read by column name like a Mapping (pandas-stubs: not a Mapping).
    spec = run.geometry(cast("Mapping[str, Any]", row))  # GeometryError names the job
    try:
        return get_mesh(run.run_dir, spec)
    except GeometryError as err:
        raise GeometryError(f"job {int(row['job_index'])}: {err}") from None


def _jobs(rows: pd.DataFrame) -> str:
    idx = rows["job_index"].astype(int).tolist()
    return f"job {idx[0]}" if len(idx) == 1 else f"jobs {idx[0]}-{idx[-1]}"


def _line(gid: str, rows: pd.DataFrame, got: CachedMesh) -> str:
    info: dict[str, Any] = got.mesh.info
    when = "reused from cache (built in" if got.status == "cached" else f"{got.status} in"
    end = ")" if got.status == "cached" else ""
    return (
        f"geometry {gid} ({_jobs(rows)}): mesh {got.path.stem}, {info['cells']} cells, "
        f"{info['vertices']} vertices, "
        f"min SICN {info['min_quality']:.3f}, {when} {info['build_time_s']:.2f} s{end}"
    )


@click.command("mesh")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--job", "job", type=int, help="Mesh the geometry of this job index.")
@click.option("--geometry", "geometry_id", help="Mesh this geometry id (16 hex characters).")
@click.option("--all", "all_", is_flag=True, help="Mesh every geometry of the run.")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the mesh as VTU (ParaView), tags as cell data (--job/--geometry only).",
)
def cmd(
    run_dir: Path, job: int | None, geometry_id: str | None, all_: bool, out: Path | None
) -> None:
    """Build (or reuse from RUN_DIR/meshes/) the tetrahedral mesh of wound geometries.

    Each mesh is cached as meshes/<mesh id>.npz, the id a hash of everything that determines
    it (geometry, mesh size factor, closure zone, element degree, size law version). Prints
    the mesh id, cells, vertices, the minimum element quality (gmsh's minSICN) and the build time.
    With --all a failing geometry does not stop the others; failures are listed at the end
    (exit status 4).
    """
    if sum([job is not None, geometry_id is not None, all_]) != 1:
        raise click.UsageError("give exactly one of --job N, --geometry ID or --all")
    if out is not None and (all_ or out.suffix.lower() != ".vtu"):
        raise click.UsageError("--out takes a .vtu file and needs --job or --geometry")
    if out is not None:
        from ..store.paths import refuse_store_target

        refuse_store_target(run_dir, out, "--out")
        try:
            check_output_file(out)
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="--out") from None
    run = load_run(run_dir)
    man = run.manifest
    if all_:
        _mesh_all(run, man)
        return
    if job is not None:
        try:
            job_row = run.job(job)
        except StoreError as err:
            raise click.BadParameter(str(err), param_hint="--job") from None
        geometry_id = str(job_row["geometry_id"])
    rows = man[man["geometry_id"] == geometry_id]
    if rows.empty:
        raise click.BadParameter(
            f"no geometry {geometry_id!r} in {run_dir}", param_hint="--geometry"
        )
    row = job_row if job is not None else rows.iloc[0]
    got = mesh_geometry(run, row)
    if got.status == "rebuilt":
        click.echo(f"cached mesh rejected ({got.reason}); rebuilt", err=True)
    click.echo(_line(str(geometry_id), rows, got))
    if out is not None:
        write_vtu(out, got.mesh)
        click.echo(f"wrote {out}")


def _mesh_all(run: Run, man: pd.DataFrame) -> None:
    groups = list(man.groupby("geometry_id", sort=False))
    cells, quality, status, failures = [], [], {"built": 0, "rebuilt": 0, "cached": 0}, []
    for gid, rows in tqdm(groups, desc="meshing", unit="geometry", leave=False):
        try:
            got = mesh_geometry(run, rows.iloc[0])
        except GeometryError as err:
            failures.append(f"geometry {gid}: {err}")
            continue
        status[got.status] += 1
        cells.append(got.mesh.info["cells"])
        quality.append(got.mesh.info["min_quality"])
    done = len(groups) - len(failures)
    click.echo(
        f"{done} of {len(groups)} geometries meshed ({status['built']} built, "
        f"{status['rebuilt']} rebuilt, {status['cached']} from cache)"
    )
    if cells:
        click.echo(
            f"cells: min {min(cells)}, median {int(statistics.median(cells))}, max {max(cells)}; "
            f"min SICN {min(quality):.3f}"
        )
    for line in failures:
        click.echo(f"failed: {line}", err=True)
    if failures:
        raise GeometryError(f"{len(failures)} of {len(groups)} geometries failed (listed above)")

"""`woundsweep export`: the PVD/VTU series read back by VTK (not meshio, which wrote it) and
compared with the store's fields, the mesh cache's tags and the known fields of the fixture."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest
from viz_store import displacement, make_store, von_mises

from woundsweep.cli import main
from woundsweep.config.manifest import load_run
from woundsweep.config.paper import ClosureZone
from woundsweep.core.schema import DERMIS, SUBCUTIS
from woundsweep.mesh.cache import load_mesh, mesh_path
from woundsweep.viz.surface import closure_zone_facets

vtk = pytest.importorskip("vtk", reason="vtk (the independent VTU reader) is not installed")
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402

_TETRA, _TRIANGLE = 10, 5


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_store(tmp_path_factory.mktemp("viz") / "run")


def _read_vtu(path: Path) -> dict[str, np.ndarray]:
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    out = {
        "points": vtk_to_numpy(grid.GetPoints().GetData()),
        "types": np.array([grid.GetCellType(i) for i in range(grid.GetNumberOfCells())]),
        "conn": vtk_to_numpy(grid.GetCells().GetConnectivityArray()),
    }
    for data in (grid.GetPointData(), grid.GetCellData()):
        for i in range(data.GetNumberOfArrays()):
            out[data.GetArrayName(i)] = vtk_to_numpy(data.GetArray(i))
    return out


def _store_fields(run: Path, job_id: str) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    with h5py.File(run / "fields" / f"{job_id}.h5", "r") as f:
        return {
            int(g.split("_")[1]): (f[g]["displacement_mm"][()], f[g]["von_mises_kPa"][()])
            for g in f
            if g.startswith("stage_")
        }


def test_round_trip_read_by_vtk(store: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "exp"
    assert main(["export", str(store), "--job", "0", "--out", str(out)]) == 0
    assert "stages [1, 2, 3, 4, 5, 6]" in capsys.readouterr().out
    run = load_run(store)
    job = run.manifest[run.manifest["job_index"] == 0].iloc[0]
    mesh = load_mesh(mesh_path(store, job["geometry_id"]))
    stored = _store_fields(store, job["job_id"])
    assert sorted(stored) == [1, 2, 3, 4, 5, 6]

    pvd = ET.parse(out / "job-0" / "job-0.pvd").getroot()
    steps = [(int(d.get("timestep")), d.get("file")) for d in pvd.iter("DataSet")]
    assert [k for k, _ in steps] == [1, 2, 3, 4, 5, 6]
    n_tet, n_tri = len(mesh.cells), len(mesh.facets)
    zone = closure_zone_facets(mesh.facet_tags)
    for k, name in steps:
        got = _read_vtu(out / "job-0" / name)
        np.testing.assert_array_equal(got["points"], mesh.points)
        assert (got["types"] == _TETRA).sum() == n_tet and (
            got["types"] == _TRIANGLE
        ).sum() == n_tri
        conn = got["conn"]
        np.testing.assert_array_equal(conn[: 4 * n_tet].reshape(-1, 4), mesh.cells)
        np.testing.assert_array_equal(conn[4 * n_tet :].reshape(-1, 3), mesh.facets)
        # The store's float32 fields exactly, and the fixture's known fields to float32.
        u, vm = stored[k]
        np.testing.assert_array_equal(got["displacement_mm"], u)
        np.testing.assert_array_equal(got["von_mises_kPa"][:n_tet], vm)
        assert np.isnan(got["von_mises_kPa"][n_tet:]).all()
        np.testing.assert_allclose(
            got["displacement_mm"], displacement(mesh.points, k, 0), rtol=1e-6, atol=1e-7
        )
        np.testing.assert_allclose(
            got["von_mises_kPa"][:n_tet], von_mises(mesh.points, mesh.cells, k, 0), rtol=1e-6
        )
        np.testing.assert_array_equal(got["cell_tag"][:n_tet], mesh.cell_tags)
        assert set(np.unique(got["cell_tag"][:n_tet])) == {DERMIS, SUBCUTIS}
        np.testing.assert_array_equal(got["facet_tag"][n_tet:], mesh.facet_tags)
        np.testing.assert_array_equal(got["closure_zone"][n_tet:], zone.astype(np.int32))
    ref = _read_vtu(out / "job-0" / "job-0_mesh.vtu")
    assert not ref["displacement_mm"].any() and "von_mises_kPa" not in ref


def test_stages_not_kept_are_named(store: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "exp"
    assert main(["export", str(store), "--job", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "stages [3]" in text
    assert "stage 1 not kept by `run --fields final`" in text
    assert "stage 4 no field: the stage ended max-iterations" in text and "stage 6 not run" in text
    info = json.loads((out / "job-1" / "job-1.json").read_text())
    assert [s["stage"] for s in info["stages"] if s["file"]] == [3]
    assert info["units"] == "mm, kPa, mN, s"
    steps = [
        d.get("timestep") for d in ET.parse(out / "job-1" / "job-1.pvd").getroot().iter("DataSet")
    ]
    assert steps == ["3"]
    got = _read_vtu(out / "job-1" / "job-1_stage3.vtu")
    np.testing.assert_array_equal(
        got["displacement_mm"], _store_fields(store, info["job_id"])[3][0]
    )


def test_export_all_counts(store: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "all"
    assert main(["export", str(store), "--all", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "exported 3 jobs (7 stages)" in text
    assert "3 jobs of the manifest have no stored result yet" in text
    assert "2 stages not exported: not kept by `run --fields final`" in text
    assert "6 stages not exported: not kept by `run --fields none`" in text
    assert sorted(p.name for p in out.iterdir()) == ["job-0", "job-1", "job-2"]


def test_job_without_fields_gets_its_mesh(store: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "none"
    assert main(["export", str(store), "--job", "2", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "stages none" in text and "stage 6 not kept by `run --fields none`" in text
    assert list(ET.parse(out / "job-2" / "job-2.pvd").getroot().iter("DataSet")) == []
    job = load_run(store).manifest.iloc[2]
    mesh = load_mesh(mesh_path(store, job["geometry_id"]))
    got = _read_vtu(out / "job-2" / "job-2_mesh.vtu")
    np.testing.assert_array_equal(got["points"], mesh.points)
    np.testing.assert_array_equal(got["facet_tag"][len(mesh.cells) :], mesh.facet_tags)


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--job", "7"], "no job 7"),
        (["--job", "3"], "job 3 has no stored result"),
        (["--job", "0", "--all"], "exactly one of"),
        ([], "exactly one of"),
    ],
)
def test_bad_input_one_line_exit_2(store: Path, tmp_path: Path, capsys, args, needle) -> None:
    assert main(["export", str(store), *args, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1


@pytest.mark.fem
def test_closure_zone_matches_the_solver(store: Path) -> None:
    from woundsweep.physics.domain import WoundDomain

    run = load_run(store)
    job = run.manifest.iloc[0]
    mesh = load_mesh(mesh_path(store, job["geometry_id"]))
    dom = WoundDomain(mesh, ClosureZone())
    zone = np.concatenate([dom.zone_left_facets, dom.zone_right_facets])  # node numbering
    want = {tuple(sorted(f)) for f in dom.node_input[zone]}
    mask = closure_zone_facets(mesh.facet_tags)
    assert want and {tuple(sorted(f)) for f in mesh.facets[mask]} == want

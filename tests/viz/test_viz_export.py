"""`woundsweep export`: the PVD/VTU series read back by VTK (not meshio, which wrote it) and
compared with the store's fields, the mesh cache's tags and the known fields of the fixture."""

from __future__ import annotations

import json
import os
import re
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest
from viz_store import displacement, make_store, von_mises

from woundsweep.cli import main
from woundsweep.config.manifest import load_run
from woundsweep.config.paper import ClosureZone
from woundsweep.core.schema import DERMIS, SUBCUTIS, WOUND_TAGS
from woundsweep.mesh.cache import load_mesh, mesh_path
from woundsweep.viz.surface import closure_zone_facets, surface_of
from woundsweep.viz.vtkfiles import units_of

vtk = pytest.importorskip("vtk", reason="vtk (the independent VTU reader) is not installed")
from vtk_render import render_surface  # noqa: E402
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402

_TETRA, _TRIANGLE = 10, 5


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_store(tmp_path_factory.mktemp("viz") / "run")


def _read_grid(grid) -> dict[str, np.ndarray]:
    out = {
        "points": vtk_to_numpy(grid.GetPoints().GetData()),
        "types": np.array([grid.GetCellType(i) for i in range(grid.GetNumberOfCells())]),
        "conn": vtk_to_numpy(grid.GetCells().GetConnectivityArray()),
    }
    for data in (grid.GetPointData(), grid.GetCellData()):
        for i in range(data.GetNumberOfArrays()):
            out[data.GetArrayName(i)] = vtk_to_numpy(data.GetArray(i))
    return out


def _read_vtu(path: Path) -> dict[str, np.ndarray]:
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    return _read_grid(reader.GetOutput())


def _read_vtm(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """The multiblock as ParaView opens it: block name -> its grid's arrays."""
    reader = vtk.vtkXMLMultiBlockDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    mb = reader.GetOutput()
    return {
        mb.GetMetaData(i).Get(vtk.vtkCompositeDataSet.NAME()): _read_grid(mb.GetBlock(i))
        for i in range(mb.GetNumberOfBlocks())
    }


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
    mesh = load_mesh(mesh_path(store, run.geometry(job).mesh_id))
    stored = _store_fields(store, job["job_id"])
    assert sorted(stored) == [1, 2, 3, 4, 5, 6]

    pvd = ET.parse(out / "job-0" / "job-0.pvd").getroot()
    steps = [(int(d.get("timestep")), d.get("file")) for d in pvd.iter("DataSet")]
    assert [k for k, _ in steps] == [1, 2, 3, 4, 5, 6]
    assert all(name.endswith(".vtm") for _, name in steps)
    zone = closure_zone_facets(mesh.facet_tags)
    surf = surface_of(mesh.points, mesh.cells, mesh.facets, zone)
    for k, name in steps:
        blocks = _read_vtm(out / "job-0" / name)
        assert sorted(blocks) == ["surface", "volume"]
        vol, srf = blocks["volume"], blocks["surface"]
        np.testing.assert_array_equal(vol["points"], mesh.points)
        assert (vol["types"] == _TETRA).all() and len(vol["types"]) == len(mesh.cells)
        np.testing.assert_array_equal(vol["conn"].reshape(-1, 4), mesh.cells)
        assert (srf["types"] == _TRIANGLE).all() and len(srf["types"]) == len(mesh.facets)
        # The surface's own nodes are the facets' nodes, in the same triangles.
        np.testing.assert_array_equal(
            srf["points"][srf["conn"].reshape(-1, 3)], mesh.points[mesh.facets]
        )
        # The store's float32 fields exactly, and the fixture's known fields to float32.
        u, vm = stored[k]
        np.testing.assert_array_equal(vol["displacement_mm"], u)
        np.testing.assert_array_equal(vol["von_mises_kPa"], vm)
        np.testing.assert_allclose(
            vol["displacement_mm"], displacement(mesh.points, k, 0), rtol=1e-6, atol=1e-7
        )
        np.testing.assert_allclose(
            vol["von_mises_kPa"], von_mises(mesh.points, mesh.cells, k, 0), rtol=1e-6
        )
        np.testing.assert_array_equal(vol["cell_tag"], mesh.cell_tags)
        assert set(np.unique(vol["cell_tag"])) == {DERMIS, SUBCUTIS}
        # Each triangle carries its tetrahedron's values: no NaN face anywhere.
        for key in ("von_mises_kPa", "cauchy_stress_kPa", "principal_stress_kPa", "det_F"):
            assert np.isfinite(srf[key]).all(), key
            np.testing.assert_array_equal(srf[key], vol[key][surf.owner])
        np.testing.assert_array_equal(srf["displacement_mm"], u[surf.nodes])
        np.testing.assert_array_equal(srf["facet_tag"], mesh.facet_tags)
        np.testing.assert_array_equal(srf["closure_zone"], zone.astype(np.int32))
        # Units ride along in a comment of each VTU, one per array.
        vol_units = units_of((out / "job-0" / f"job-0_stage{k}_volume.vtu").read_text("latin-1"))
        srf_units = units_of((out / "job-0" / f"job-0_stage{k}_surface.vtu").read_text("latin-1"))
        assert vol_units["cauchy_stress_kPa"] == "kPa" and vol_units["det_F"] == "1"
        assert srf_units["displacement_mm"] == "mm"
        assert set(srf_units) == {k for k in srf if k not in ("points", "types", "conn")}
        # Derived fields against the solver's own constitutive law (physics.materials).
        _check_derived(vol, mesh, u, job, run)
        flank = np.isin(mesh.facet_tags, WOUND_TAGS)
        assert (srf["contact_pressure_kPa"][~flank] == 0).all()
        np.testing.assert_allclose(
            srf["contact_pressure_kPa"][flank],
            np.maximum(-srf["normal_traction_kPa"][flank], 0),
            rtol=1e-6,
        )
    ref = _read_vtu(out / "job-0" / "job-0_mesh.vtu")
    assert "displacement_mm" not in ref and "von_mises_kPa" not in ref
    np.testing.assert_array_equal(ref["cell_tag"], mesh.cell_tags)


def _check_derived(vol: dict, mesh, u: np.ndarray, job, run) -> None:
    from woundsweep.physics.materials import JobMaterials, first_piola

    mats = JobMaterials.from_sweep(run.sweep.materials, job["skin_type"], job["orientation_deg"])
    rng = np.random.default_rng(1)
    for c in rng.choice(len(mesh.cells), 12, replace=False):
        X = mesh.points[mesh.cells[c]]
        x = X + u[mesh.cells[c]].astype(float)
        F = (x[1:] - x[0]).T @ np.linalg.inv((X[1:] - X[0]).T)
        J = np.linalg.det(F)
        mat = mats.dermis if mesh.cell_tags[c] == DERMIS else mats.subcutis
        sigma = first_piola(mat, F) @ F.T / J
        np.testing.assert_allclose(vol["det_F"][c], J, rtol=1e-5)
        np.testing.assert_allclose(
            vol["green_lagrange_strain"][c].reshape(3, 3), 0.5 * (F.T @ F - np.eye(3)), atol=1e-6
        )
        np.testing.assert_allclose(
            vol["cauchy_stress_kPa"][c].reshape(3, 3), 0.5 * (sigma + sigma.T), rtol=1e-4, atol=1e-4
        )
        np.testing.assert_allclose(
            vol["principal_stress_kPa"][c],
            np.sort(np.linalg.eigvalsh(sigma))[::-1],
            rtol=1e-4,
            atol=1e-4,
        )


def test_surface_render_has_no_nan_faces(store: Path, tmp_path: Path) -> None:
    """ParaView's default view of the export, through VTK offscreen: the surface block
    coloured by von Mises, every face drawn in a colour of the map (no NaN colour)."""
    out = tmp_path / "exp"
    assert main(["export", str(store), "--job", "0", "--out", str(out)]) == 0
    png = tmp_path / "export-surface.png"
    stats = render_surface(out / "job-0" / "job-0_stage6.vtm", png)
    assert stats["nan_cells"] == 0 and stats["cells"] > 100
    assert stats["nan_pixels"] == 0, stats
    assert stats["coloured_fraction"] > 0.15, stats
    dest = os.environ.get("WOUNDSWEEP_SCREENSHOTS")
    if dest:
        Path(dest).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(png, Path(dest) / png.name)


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
    got = _read_vtm(out / "job-1" / "job-1_stage3.vtm")["volume"]
    np.testing.assert_array_equal(
        got["displacement_mm"], _store_fields(store, info["job_id"])[3][0]
    )


def test_export_all_counts(store: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "all"
    assert main(["export", str(store), "--all", "--out", str(out)]) == 0
    text, err = capsys.readouterr()
    assert re.fullmatch(r"export: 3 jobs \(7 stages\) in \d+\.\d s", err.splitlines()[-1]), err
    assert "exported 3 jobs (7 stages)" in text
    assert "3 jobs of the manifest have no stored result yet" in text
    assert "2 stages not exported: not kept by `run --fields final`" in text
    assert "6 stages not exported: not kept by `run --fields none`" in text
    assert sorted(p.name for p in out.iterdir()) == ["job-0", "job-1", "job-2"]


def test_job_without_fields_gets_its_mesh(store: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "none"
    assert main(["export", str(store), "--job", "2", "--out", str(out)]) == 0
    text, err = capsys.readouterr()
    assert re.fullmatch(r"export: job 2 in \d+\.\d s", err.splitlines()[-1]), err
    assert "stages none" in text and "stage 6 not kept by `run --fields none`" in text
    assert list(ET.parse(out / "job-2" / "job-2.pvd").getroot().iter("DataSet")) == []
    run = load_run(store)
    job = run.manifest.iloc[2]
    mesh = load_mesh(mesh_path(store, run.geometry(job).mesh_id))
    got = _read_vtu(out / "job-2" / "job-2_mesh.vtu")
    np.testing.assert_array_equal(got["points"], mesh.points)
    np.testing.assert_array_equal(got["conn"].reshape(-1, 4), mesh.cells)


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--job", "7"], "no job 7"),
        (["--job", "3"], "job 3 has no stored result"),
        (["--job", "0", "--all"], "exactly one of"),
        ([], "exactly one of"),
        (["--result", "nosuch.h5"], "nosuch.h5"),
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
    mesh = load_mesh(mesh_path(store, run.geometry(job).mesh_id))
    dom = WoundDomain(mesh, ClosureZone(), run.sweep.solver.element_degree)
    zone = np.concatenate([dom.zone_left_facets, dom.zone_right_facets])  # node numbering
    want = {tuple(sorted(f)) for f in dom.node_input[zone]}
    mask = closure_zone_facets(mesh.facet_tags)
    assert want and {tuple(sorted(f)) for f in mesh.facets[mask]} == want


def test_render_check_sees_nan_faces(store: Path, tmp_path: Path) -> None:
    """The render check can fail: half the surface's von Mises set to NaN shows up as NaN
    pixels (what a surface that carried NaN triangles looked like)."""
    out = tmp_path / "exp"
    assert main(["export", str(store), "--job", "0", "--out", str(out)]) == 0
    path = out / "job-0" / "job-0_stage6_surface.vtu"
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    vm = grid.GetCellData().GetArray("von_mises_kPa")
    for i in range(0, vm.GetNumberOfTuples(), 2):
        vm.SetValue(i, float("nan"))
    writer = vtk.vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(grid)
    writer.Write()
    stats = render_surface(out / "job-0" / "job-0_stage6.vtm", tmp_path / "nan.png")
    assert stats["nan_cells"] > 100 and stats["nan_pixels"] > 1000, stats


def test_an_inverted_cell_has_no_stress_and_no_error() -> None:
    """A cell whose vertex interpolant is inverted (possible for a P2 field) gets NaN stress
    and principal stresses; its neighbours keep theirs."""
    from woundsweep.config.paper import Materials
    from woundsweep.viz.mechanics import cell_mechanics

    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    u = np.zeros_like(X)
    u[0] = 0.6  # vertex 0 (in cell 0 only) pushed through the opposite face x + y + z = 1
    tags = np.array([DERMIS, SUBCUTIS], dtype=np.int32)
    m = cell_mechanics(X, cells, tags, u, Materials.table2(), "normal", 0.0)
    assert m.det_F[0] < 0 and np.isnan(m.cauchy_kPa[0]).all() and np.isnan(m.principal_kPa[0]).all()
    assert np.isfinite(m.cauchy_kPa[1]).all() and np.isfinite(m.principal_kPa[1]).all()

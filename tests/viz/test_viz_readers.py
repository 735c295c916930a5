"""Every file `woundsweep export` writes opens in meshio, pyvista and VTK (.vtu, .vtm, .pvd,
.xdmf + .h5), every exported value is finite, and the exported stresses agree with the solver's
von Mises (`viz.export.stage_cell_fields`)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from viz_store import make_store

from woundsweep.cli import main
from woundsweep.config.manifest import load_run
from woundsweep.core.schema import DERMIS
from woundsweep.viz.export import TENSOR_FIELDS, export_job, stage_cell_fields
from woundsweep.viz.jobdata import open_job
from woundsweep.viz.vtkfiles import units_of

meshio = pytest.importorskip("meshio")
pv = pytest.importorskip("pyvista", reason="pyvista (a reader under test) is not installed")
vtk = pytest.importorskip("vtk", reason="vtk (a reader under test) is not installed")


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The viz store's job 0 (six stages) exported with --xdmf from another working
    directory: (run, job directory)."""
    base = tmp_path_factory.mktemp("readers")
    run = make_store(base / "run")
    cwd = base / "elsewhere"
    cwd.mkdir()
    old = os.getcwd()
    os.chdir(cwd)
    try:
        assert main(["export", str(run), "--job", "0", "--out", str(base / "exp"), "--xdmf"]) == 0
    finally:
        os.chdir(old)
    assert list(cwd.iterdir()) == []  # nothing lands in the working directory
    return run, base / "exp" / "job-0"


def _vtk_read(path: Path):
    kind = {
        ".vtu": vtk.vtkXMLUnstructuredGridReader,
        ".vtm": vtk.vtkXMLMultiBlockDataReader,
        ".pvd": None,
        ".xdmf": vtk.vtkXdmfReader,
    }[path.suffix]
    assert kind is not None
    reader = kind()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return reader.GetOutputDataObject(0)


def test_every_vtu_reads_in_meshio_pyvista_and_vtk(exported) -> None:
    _, d = exported
    vtus = sorted(d.glob("*.vtu"))
    assert len(vtus) == 13  # six stages x (volume, surface) + the reference mesh
    for path in vtus:
        m = meshio.read(path)  # raised SystemExit on VTK's String field data
        g = pv.read(path)
        grid = _vtk_read(path)
        assert len(m.points) == g.n_points == grid.GetNumberOfPoints() > 0
        assert sum(len(c.data) for c in m.cells) == g.n_cells == grid.GetNumberOfCells()
        assert set(m.cell_data) == set(g.cell_data.keys())
        assert set(units_of(path.read_text("latin-1"))) == set(g.point_data.keys()) | set(
            g.cell_data.keys()
        )


def test_multiblocks_series_and_xdmf_read(exported) -> None:
    _, d = exported
    for vtm in sorted(d.glob("*.vtm")):
        mb = pv.read(vtm)
        assert list(mb.keys()) == ["volume", "surface"]
        assert _vtk_read(vtm).GetNumberOfBlocks() == 2
    series = pv.get_reader(str(d / "job-0.pvd"))
    assert series.time_values == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    series.set_active_time_value(6.0)
    assert list(series.read()[0].keys()) == ["volume", "surface"]  # the step's multiblock
    # XDMF: the HDF5 beside it (referenced by its bare name), read by meshio, pyvista and VTK.
    assert (d / "job-0.h5").is_file()
    assert "job-0.h5:/" in (d / "job-0.xdmf").read_text()
    with meshio.xdmf.TimeSeriesReader(d / "job-0.xdmf") as r:
        points, _ = r.read_points_cells()
        assert r.num_steps == 6
        t, point_data, cell_data = r.read_data(5)
    assert t == 6.0 and point_data["displacement_mm"].shape == points.shape
    assert "von_mises_kPa" in cell_data and "inverted" in cell_data
    xd = pv.read(d / "job-0.xdmf")
    assert xd.n_blocks >= 1
    out = _vtk_read(d / "job-0.xdmf")  # the mesh and the time series' grid
    grid = out.GetBlock(out.GetNumberOfBlocks() - 1)
    assert grid.GetNumberOfPoints() == len(points)
    data = grid.GetCellData()
    assert "von_mises_kPa" in {data.GetArrayName(i) for i in range(data.GetNumberOfArrays())}


def test_every_exported_value_is_finite(exported) -> None:
    _, d = exported
    for path in sorted(d.glob("*.vtu")):
        g = pv.read(path)
        for name in [*g.point_data.keys(), *g.cell_data.keys()]:
            assert np.isfinite(np.asarray(g[name], float)).all(), (path.name, name)


def _consistent(run: Path):
    """Job 0 with its stored von Mises replaced by what a P1 solve stores for its stored
    displacement: the batched law of viz.mechanics, checked on 16 cells against the solver's
    own (physics.materials)."""
    from woundsweep.physics.materials import JobMaterials, first_piola, von_mises
    from woundsweep.viz.mechanics import cell_mechanics

    jf = open_job(run, 0)
    job = jf.job
    sweep = load_run(run).sweep
    mats = JobMaterials.from_sweep(sweep.materials, job["skin_type"], job["orientation_deg"])
    fields = {}
    for k, (u, _) in jf.fields.items():
        m = cell_mechanics(
            jf.points, jf.cells, jf.cell_tags, u, sweep.materials, job["skin_type"],
            job["orientation_deg"],
        )  # fmt: skip
        for c in np.random.default_rng(k).choice(len(jf.cells), 16, replace=False):
            mat = mats.dermis if jf.cell_tags[c] == DERMIS else mats.subcutis
            F = m.F[c]
            assert von_mises(first_piola(mat, F), F) == pytest.approx(m.von_mises_kPa[c], rel=1e-9)
        fields[k] = (u, m.von_mises_kPa.astype(np.float32))
    return jf._replace(fields=fields)


def _vm(sigma: np.ndarray) -> np.ndarray:
    s = sigma.reshape(-1, 3, 3).astype(float)
    dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("mij,mij->m", dev, dev))


def test_von_mises_of_the_exported_tensor_is_the_exported_von_mises(exported, tmp_path) -> None:
    """P1: in every cell of every stage, within 1e-6 relative, read back by pyvista."""
    run, _ = exported
    jf = _consistent(run)
    export_job(jf, tmp_path)
    for k in jf.fields:
        g = pv.read(tmp_path / "job-0" / f"job-0_stage{k}_volume.vtu")
        vm, mine = np.asarray(g["von_mises_kPa"], float), _vm(np.asarray(g["cauchy_stress_kPa"]))
        assert (g["inverted"] == 0).all()
        assert np.max(np.abs(mine - vm) / vm) < 1e-6
    # The synthetic store's own von Mises is not the displacement's: the check can fail.
    g = pv.read(exported[1] / "job-0_stage6_volume.vtu")
    assert np.max(np.abs(_vm(g["cauchy_stress_kPa"]) / g["von_mises_kPa"] - 1)) > 1e-2


def test_inverted_and_non_finite_cells_are_marked_not_written(exported) -> None:
    run, _ = exported
    jf = open_job(run, 0)
    u, vm = jf.fields[6]
    vm = vm.copy()
    vm[3] = np.nan  # the solver stored no stress here
    u = u.copy()
    c = jf.cells[10]
    u[c[0]] = (jf.points[c[1:]].mean(axis=0) - jf.points[c[0]]) * 3  # vertex 0 through its face
    cells = stage_cell_fields(jf._replace(fields={6: (u, vm)}), 6)
    assert cells["inverted"][3] == 1 and cells["inverted"][10] == 1
    assert cells["von_mises_kPa"][3] == 0 and not cells["cauchy_stress_kPa"][10].any()
    assert all(np.isfinite(v).all() for v in cells.values())
    assert cells["inverted"].sum() < 0.05 * len(jf.cells)


def test_p2_without_the_solvers_tensor_exports_no_derived_stress(exported, tmp_path) -> None:
    """A P2 run's vertex displacement does not give its stress: the tensors are left out and
    job-N.json says why; with the solver's cell means in the fields file they are exported."""
    run, _ = exported
    jf = open_job(run, 0)
    p2 = jf._replace(rows=[{**r, "element_degree": 2} for r in jf.rows])
    info = export_job(p2, tmp_path / "a")
    g = pv.read(tmp_path / "a" / "job-0" / "job-0_stage6_surface.vtu")
    assert not set(TENSOR_FIELDS) & set(g.cell_data.keys())
    assert "von_mises_kPa" in g.cell_data.keys()
    stage6 = next(s for s in info["stages"] if s["stage"] == 6)
    assert stage6["tensor_source"] == "none" and "not exported" in info["tensor_sources"]["none"]
    sigma = np.zeros((len(jf.cells), 3, 3))
    sigma[:, 0, 0] = jf.fields[6][1]  # uniaxial: von Mises = sigma_xx
    E, J = np.zeros_like(sigma), np.ones(len(jf.cells))
    data = {6: {"cauchy_stress_kPa": sigma, "green_lagrange_strain": E, "det_F": J}}
    info = export_job(p2._replace(cell_data=data), tmp_path / "b")
    g = pv.read(tmp_path / "b" / "job-0" / "job-0_stage6_volume.vtu")
    np.testing.assert_allclose(_vm(g["cauchy_stress_kPa"]), g["von_mises_kPa"], rtol=1e-6)
    described = json.loads((tmp_path / "b" / "job-0" / "job-0.json").read_text())
    assert next(s for s in described["stages"] if s["stage"] == 6)["tensor_source"] == "solver"
    assert set(described["stress_numbers"]) >= {"p99_von_mises_kPa", "max_von_mises_kPa"}

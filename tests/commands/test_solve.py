"""`woundsweep solve`: stress statistics, exit statuses, output file, JIT reuse."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_run import generate_run

from woundsweep.core.errors import SolverError
from woundsweep.core.schema import StageResult, parse_stage_range
from woundsweep.physics.job import stress_summary

SMALL_SWEEP = {
    "name": "solve-test",
    "grid": {
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
        "wound_width_factor": [0.3],
        "mesh_size_factor": [0.3],
        "skin_type": ["stiff", "soft"],
        "orientation_deg": [0, 45],
    },
    "shapes": {"cylindrical": {"wound_aspect_factor": [0]}, "wedge": {"wound_depth_factor": [0.3]}},
    "solver": {"element_degree": 1},
}


# -- statistics (no DOLFINx) ------------------------------------------------------------------


def test_volume_weighted_p99() -> None:
    vm = np.arange(1.0, 101.0)  # 100 cells
    vol = np.ones(100)
    one_tet = np.array([[0, 1, 2, 3]] * 100)
    mid = np.zeros((100, 3))
    assert stress_summary(vm, vol, one_tet, mid)["p99_von_mises_kPa"] == 99.0
    # With the top cell holding 2 of 101 volume units, cells below it hold only 98%.
    vol[-1] = 2.0
    assert stress_summary(vm, vol, one_tet, mid)["p99_von_mises_kPa"] == 100.0
    # Many tiny cells of high stress (a finely meshed corner) do not move it.
    vm2 = np.r_[np.full(90, 5.0), np.full(10, 500.0)]
    vol2 = np.r_[np.full(90, 1.0), np.full(10, 1e-4)]
    assert stress_summary(vm2, vol2, one_tet, mid)["p99_von_mises_kPa"] == 5.0


def test_nodal_p99_max_and_location() -> None:
    # Two tets sharing face (1, 2, 3). The paper code's nodal values: each vertex takes the
    # last cell's value (0 -> 1; the shared ones and 4 -> 3), unweighted.
    cells = np.array([[0, 1, 2, 3], [4, 1, 2, 3]])
    vm = np.array([1.0, 3.0])
    vol = np.array([1.0, 3.0])
    mid = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    s = stress_summary(vm, vol, cells, mid)
    assert s["p99_von_mises_nodal_kPa"] == pytest.approx(np.percentile([1, 3, 3, 3, 3], 99))
    # Values at the vertices (a P2 cell's stress varies in it): the last cell's at each.
    at_vertices = np.array([[1.0, 2.0, 3.0, 4.0], [9.0, 5.0, 6.0, 7.0]])
    s = stress_summary(vm, vol, cells, mid, vertex_vm=at_vertices)
    assert s["p99_von_mises_nodal_kPa"] == pytest.approx(np.percentile([1, 5, 6, 7, 9], 99))
    # No wound: no wound-local p99; the cells within reach of one: theirs.
    assert np.isnan(s["p99_von_mises_wound_kPa"])
    near = stress_summary(vm, vol, cells, mid, near_wound=np.array([True, False]))
    assert near["p99_von_mises_wound_kPa"] == 1.0
    assert s["max_von_mises_kPa"] == 3.0
    assert (s["max_location_x_mm"], s["max_location_y_mm"], s["max_location_z_mm"]) == (
        0.4,
        0.5,
        0.6,
    )


def test_p99_and_maximum_over_samples() -> None:
    from woundsweep.physics.forms import StressSamples

    # Two cells of volume 1 and 3, two samples each holding half of its cell.
    cells = np.array([[0, 1, 2, 3], [4, 1, 2, 3]])
    vol = np.array([1.0, 3.0])
    mid = np.zeros((2, 3))
    points = np.array([[0.1, 0.2, 0.3], [0.25, 0.25, 0.25]])
    samples = StressSamples(np.array([[10.0, 50.0], [20.0, 30.0]]), np.array([0.5, 0.5]), points)
    corners = np.array([np.eye(4)[:, :3], 2.0 * np.eye(4)[:, :3] + 1.0])
    s = stress_summary(np.array([30.0, 25.0]), vol, cells, mid, samples, corners)
    # Volumes: 10 -> 0.5, 20 -> 1.5, 30 -> 1.5, 50 -> 0.5 of 4: below 50 lies 87.5 %.
    assert s["p99_von_mises_kPa"] == 50.0
    assert s["max_von_mises_kPa"] == 50.0
    # The largest sample is cell 0's second point: corner 0 + edges . (0.25, 0.25, 0.25).
    want = corners[0, 0] + (corners[0, 1:] - corners[0, 0]).T @ points[1]
    assert [s[f"max_location_{a}_mm"] for a in "xyz"] == pytest.approx(want.tolist())
    # The nodal p99 still comes from the cell means.
    assert (
        s["p99_von_mises_nodal_kPa"]
        == stress_summary(np.array([30.0, 25.0]), vol, cells, mid)["p99_von_mises_nodal_kPa"]
    )
    # Shares 0.999 / 0.001 per cell: 10 and 20 now hold 3.996 of 4 (99.9 %), so p99 is 20.
    samples2 = samples._replace(weights=np.array([0.999, 0.001]))
    assert (
        stress_summary(np.array([30.0, 25.0]), vol, cells, mid, samples2, corners)[
            "p99_von_mises_kPa"
        ]
        == 20.0
    )


def test_samples_without_stress_are_left_out() -> None:
    """A sample with det F <= 0 (or no finite value) holds no stress: p99 and the maximum
    come from the others; with none left they are NaN."""
    from woundsweep.physics.forms import StressSamples

    cells = np.array([[0, 1, 2, 3], [4, 1, 2, 3]])
    vol, mid = np.array([1.0, 1.0]), np.zeros((2, 3))
    corners = np.array([np.eye(4)[:, :3]] * 2)
    points = np.array([[0.1, 0.2, 0.3], [0.25, 0.25, 0.25]])
    values = np.array([[10.0, 900.0], [20.0, np.nan]])
    det_F = np.array([[0.9, -0.1], [0.8, 0.7]])
    s = stress_summary(
        np.array([1.0, 2.0]),
        vol,
        cells,
        mid,
        StressSamples(values, np.ones(2) / 2, points, det_F),
        corners,
    )
    assert s["max_von_mises_kPa"] == 20.0 and s["p99_von_mises_kPa"] == 20.0
    none = StressSamples(values, np.ones(2) / 2, points, -np.ones((2, 2)))
    s = stress_summary(np.array([1.0, 2.0]), vol, cells, mid, none, corners)
    assert math.isnan(s["p99_von_mises_kPa"]) and math.isnan(s["max_von_mises_kPa"])


def test_parse_stage_range() -> None:
    assert parse_stage_range("1-3") == (1, 3)
    assert parse_stage_range("2") == (2, 2)
    assert parse_stage_range("4-6") == (4, 6)
    for bad in ("0-2", "3-1", "x", "1-7", "1-2-3"):
        with pytest.raises(SolverError):
            parse_stage_range(bad, SolverError)


def test_stage_result_fields_match_the_design_contract() -> None:
    from woundsweep.store.reader import STAGE_FIELDS

    assert set(StageResult._fields) == {"stage", "status", *STAGE_FIELDS}


# -- the command ------------------------------------------------------------------------------


def _run_dir(tmp_path: Path, solver: dict | None = None) -> Path:
    """A run of SMALL_SWEEP with ``solver`` over its solver section."""
    return generate_run(
        {**SMALL_SWEEP, "solver": {**SMALL_SWEEP["solver"], **(solver or {})}}, tmp_path
    )


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run_dir(tmp_path_factory.mktemp("solve"))


def test_job_geometry_takes_the_sweeps_element_degree(tmp_path: Path) -> None:
    """A P2 sweep's meshes are P2 meshes (edges twice as long); the mesh cache tells them apart."""
    from woundsweep.config.manifest import load_run

    for degree in (1, 2):
        (tmp_path / str(degree)).mkdir()
        run = load_run(_run_dir(tmp_path / str(degree), {"element_degree": degree}))
        assert run.geometry(run.job(0)).element_degree == degree


@pytest.mark.fem
def test_solve_writes_the_design_output(run_dir: Path, capsys: pytest.CaptureFixture) -> None:
    import h5py

    from woundsweep.cli import main
    from woundsweep.config.manifest import load_run
    from woundsweep.store.solverfile import read_solver_file

    out = run_dir / "job0.h5"
    assert main(["solve", str(run_dir), "--job", "0", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "converged" in text and text.count("converged") == 6
    row = load_run(run_dir).manifest.iloc[0]
    with h5py.File(out, "r") as f:
        assert f.attrs["job_id"] == row["job_id"] and f.attrs["units"] == "mm, kPa, mN, s"
        rows = json.loads(f.attrs["stage_results"])
        n_points, n_cells = len(f["mesh/points"]), len(f["mesh/cells"])
        for k in range(1, 7):
            assert f[f"stage_{k}/displacement_mm"].shape == (n_points, 3)
            assert f[f"stage_{k}/von_mises_kPa"].shape == (n_cells,)
            assert f[f"stage_{k}/displacement_mm"].dtype == np.float32
        u2 = f["stage_2/displacement_mm"][:]
        pts = f["mesh/points"][:]
    assert [r["status"] for r in rows] == ["converged"] * 6
    assert all(set(StageResult._fields) <= set(r) for r in rows)
    # Contact measures exist for the contact stages only.
    for r in rows:
        has = [
            r[k] is not None for k in ("n_penetrating", "max_penetration_mm", "contact_force_mN")
        ]
        assert has == [r["stage"] >= 4] * 3
    assert rows[0]["cells"] == n_cells and rows[0]["dofs"] == 3 * n_points
    # The written displacement is in the input point order: zone edges meet at x = w/2.
    w = float(row["wound_width_mm"])
    wound_top = (np.abs(pts[:, 2]) < 1e-12) & (np.abs(pts[:, 1]) < 1e-12)
    rim = wound_top & (np.abs(np.abs(pts[:, 0] - w / 2) - w / 2) < 1e-9)
    assert rim.sum() == 2
    np.testing.assert_allclose(pts[rim, 0] + u2[rim, 0], w / 2, atol=1e-5)  # float32 output
    # The store accepts the file.
    got = read_solver_file(out, str(row["job_id"]), (1, 6))
    assert sorted(got.stages) == [1, 2, 3, 4, 5, 6]


@pytest.mark.fem
def test_unconverged_stage_exits_3_and_later_stages_are_not_run(tmp_path: Path) -> None:
    import h5py

    from woundsweep.cli import main

    run = _run_dir(tmp_path, solver={"max_iterations": 1, "max_load_cuts": 0})
    out = tmp_path / "fail.h5"
    assert main(["solve", str(run), "--job", "0", "--out", str(out)]) == 3
    with h5py.File(out, "r") as f:
        rows = json.loads(f.attrs["stage_results"])
        groups = set(f.keys())
    assert [r["status"] for r in rows] == ["max-iterations"] + ["not-run"] * 5
    assert groups == {"mesh"}  # unconverged states are not written as fields


def test_invalid_requests_exit_2(run_dir: Path, capsys: pytest.CaptureFixture) -> None:
    from woundsweep.cli import main

    assert main(["solve", str(run_dir), "--job", "0", "--stages", "1-7"]) == 2
    assert "expected A-B" in capsys.readouterr().err
    assert main(["solve", str(run_dir / "nope"), "--job", "0"]) == 2


@pytest.mark.fem
def test_unknown_job_exits_2(run_dir: Path, capsys: pytest.CaptureFixture) -> None:
    from woundsweep.cli import main

    assert main(["solve", str(run_dir), "--job", "999"]) == 2
    assert "999" in capsys.readouterr().err


def test_fault_switch_fires_before_solving(run_dir: Path) -> None:
    env = dict(os.environ, WOUNDSWEEP_FAULT="exit:7@1")
    cmd = [sys.executable, "-m", "woundsweep", "solve", str(run_dir), "--stages", "1-3"]
    assert subprocess.run([*cmd, "--job", "1"], env=env, capture_output=True).returncode == 7
    # Another job is untouched by a targeted fault (it fails later, on the bad stage range).
    res = subprocess.run([*cmd[:-1], "1-7", "--job", "2"], env=env, capture_output=True)
    assert res.returncode == 2


# -- JIT reuse --------------------------------------------------------------------------------


def _different_job(run_dir: Path) -> int:
    from woundsweep.config.manifest import load_run

    m = load_run(run_dir).manifest
    first = m.iloc[0]
    other = m[
        (m["geometry_id"] != first["geometry_id"])
        & (m["skin_type"] != first["skin_type"])
        & (m["orientation_deg"] != first["orientation_deg"])
    ]
    return int(other.iloc[0]["job_index"])


@pytest.mark.fem
def test_second_job_with_other_parameters_compiles_nothing(
    run_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every parameter is a Constant: another geometry, skin type and orientation reuse the
    compiled forms (counted at FFCx's compile step, which a cache hit never reaches)."""
    import ffcx.codegeneration.jit as ffcx_jit

    from woundsweep.physics.job import solve_job

    compiled: list[str] = []
    real = ffcx_jit._compile_objects

    def spy(decl, ufl_objects, names, module_name, *args, **kwargs):
        compiled.append(module_name)
        return real(decl, ufl_objects, names, module_name, *args, **kwargs)

    monkeypatch.setattr(ffcx_jit, "_compile_objects", spy)
    first = solve_job(run_dir, 0, (1, 3), tmp_path / "a.h5")
    assert first.exit_code == 0
    compiled.clear()
    second = solve_job(run_dir, _different_job(run_dir), (1, 3), tmp_path / "b.h5")
    assert second.exit_code == 0
    assert compiled == []


@pytest.mark.fem
@pytest.mark.slow
def test_cold_cache_compiles_each_form_once_per_machine(run_dir: Path, tmp_path: Path) -> None:
    """Fresh processes on an empty JIT cache: the first job compiles, a second job with other
    parameters compiles nothing (no form, the Jacobian included, gets a new hash)."""
    cache = tmp_path / "xdg"
    env = dict(os.environ, XDG_CACHE_HOME=str(cache), OPENBLAS_NUM_THREADS="1")
    base = [sys.executable, "-m", "woundsweep", "solve", str(run_dir), "--stages", "1-2"]

    def modules() -> set[str]:
        return {p.name for p in (cache / "fenics").glob("libffcx_*.so")}

    res = subprocess.run([*base, "--job", "0", "--out", str(tmp_path / "a.h5")], env=env)
    assert res.returncode == 0
    after_first = modules()
    # Residual, tangent, von Mises, and the contact stages' potential.
    assert len([m for m in after_first if m.startswith("libffcx_forms")]) == 4
    job = str(_different_job(run_dir))
    res = subprocess.run([*base, "--job", job, "--out", str(tmp_path / "b.h5")], env=env)
    assert res.returncode == 0
    assert modules() == after_first

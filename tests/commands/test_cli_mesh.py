"""`woundsweep mesh` through the console entry point: --job, --geometry, --all, --out, bad input."""

from __future__ import annotations

import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_run import ws as run_ws

from woundsweep.config.manifest import load_run
from woundsweep.core.schema import CELL_TAGS, FACET_TAGS
from woundsweep.mesh.cache import load_mesh

LINE = re.compile(
    r"^geometry ([0-9a-f]{16}) \(jobs? [\d-]+\): mesh ([0-9a-f]{16}), (\d+) cells, (\d+) "
    r"vertices, min SICN (0\.\d+), (built in|reused from cache \(built in) [\d.]+ s\)?$"
)


def ws(*args: str) -> subprocess.CompletedProcess[str]:
    return run_ws(*args, timeout=300)


@pytest.fixture(scope="module")
def run_dir(demo_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the demo run (the mesh commands write its mesh cache)."""
    rd = tmp_path_factory.mktemp("mesh") / "run"
    shutil.copytree(demo_run, rd)
    return rd


def manifest(rd: Path) -> pd.DataFrame:
    return pd.read_parquet(rd / "manifest.parquet")


def mesh_ids(rd: Path) -> pd.Series:
    """Each job's mesh id (it names the job's cached mesh)."""
    run = load_run(rd)
    return run.manifest.apply(lambda row: run.geometry(row).mesh_id, axis=1)


def test_job_builds_then_geometry_reuses(run_dir: Path) -> None:
    man = manifest(run_dir)
    gid = man.loc[man["job_index"] == 5, "geometry_id"].item()
    mid = mesh_ids(run_dir)[5]
    res = ws("mesh", str(run_dir), "--job", "5")
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert len(lines) == 1  # nothing from gmsh on stdout
    m = LINE.match(lines[0])
    assert m and m.group(1) == gid and m.group(2) == mid and m.group(6) == "built in"
    cells, vertices = int(m.group(3)), int(m.group(4))
    cached = load_mesh(run_dir / "meshes" / f"{mid}.npz")
    assert (len(cached.cells), len(cached.points)) == (cells, vertices)

    again = ws("mesh", str(run_dir), "--geometry", gid)
    assert again.returncode == 0, again.stderr
    m2 = LINE.match(again.stdout.strip())
    assert m2 and m2.group(6).startswith("reused from cache") and int(m2.group(3)) == cells


def test_out_writes_a_vtu_with_tags(run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "mesh.vtu"
    res = ws("mesh", str(run_dir), "--job", "0", "--out", str(out))
    assert res.returncode == 0, res.stderr
    mesh = load_mesh(run_dir / "meshes" / f"{mesh_ids(run_dir)[0]}.npz")
    piece = ET.parse(out).getroot().find("UnstructuredGrid/Piece")
    n_tet, n_tri = len(mesh.cells), len(mesh.facets)
    assert int(piece.get("NumberOfPoints")) == len(mesh.points)
    assert int(piece.get("NumberOfCells")) == n_tet + n_tri

    def data(path: str, name: str | None = None) -> np.ndarray:
        for node in piece.iterfind(path):
            if name is None or node.get("Name") == name:
                return np.array(node.text.split(), dtype=float)
        raise AssertionError(f"{path} {name} missing")

    np.testing.assert_array_equal(data("Points/DataArray").reshape(-1, 3), mesh.points)
    conn = data("Cells/DataArray", "connectivity").astype(np.int64)
    offsets = data("Cells/DataArray", "offsets").astype(np.int64)
    types = data("Cells/DataArray", "types").astype(int)
    assert offsets[-1] == len(conn) == 4 * n_tet + 3 * n_tri
    np.testing.assert_array_equal(conn[: 4 * n_tet].reshape(-1, 4), mesh.cells)
    np.testing.assert_array_equal(conn[4 * n_tet :].reshape(-1, 3), mesh.facets)
    assert set(types[:n_tet]) == {10} and set(types[n_tet:]) == {5}
    cell_tag = data("CellData/DataArray", "cell_tag").astype(int)
    facet_tag = data("CellData/DataArray", "facet_tag").astype(int)
    assert set(cell_tag[:n_tet]) == set(CELL_TAGS.values())
    assert set(facet_tag[n_tet:]) == set(FACET_TAGS.values())
    np.testing.assert_array_equal(facet_tag[n_tet:], mesh.facet_tags)


def test_corrupt_cached_file_is_rebuilt(run_dir: Path) -> None:
    gid = manifest(run_dir).loc[8, "geometry_id"]
    assert ws("mesh", str(run_dir), "--geometry", gid).returncode == 0
    path = run_dir / "meshes" / f"{mesh_ids(run_dir)[8]}.npz"
    path.write_bytes(path.read_bytes()[:1000])
    res = ws("mesh", str(run_dir), "--geometry", gid)
    assert res.returncode == 0, res.stderr
    assert "rejected" in res.stderr and "rebuilt in" in res.stdout
    load_mesh(path)  # valid again


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--job", "9999"], "no job 9999"),
        (["--geometry", "deadbeefdeadbeef"], "no geometry"),
        ([], "exactly one of"),
        (["--job", "0", "--all"], "exactly one of"),
        (["--all", "--out", "x.vtu"], "--out"),
        (["--job", "0", "--out", "x.stl"], "--out"),
    ],
)
def test_bad_selection_is_one_line_exit_2(run_dir: Path, args: list[str], needle: str) -> None:
    res = ws("mesh", str(run_dir), *args)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and needle in res.stderr and "Traceback" not in res.stderr


def test_not_a_run_dir(tmp_path: Path) -> None:
    res = ws("mesh", str(tmp_path), "--job", "0")
    assert res.returncode == 2 and "not a run directory" in res.stderr


@pytest.fixture
def broken_run(run_dir: Path, tmp_path: Path) -> Path:
    """A copy of the demo run whose first wedge geometry has its apex below the bottom (a
    manifest consistent in itself: derived lengths and ids recomputed, as load_run checks)."""
    from woundsweep.config.manifest import _derive, canonical_hash
    from woundsweep.config.sweep import GEOMETRY_KEYS

    rd = tmp_path / "broken"
    shutil.copytree(run_dir, rd, ignore=shutil.ignore_patterns("meshes"))
    man = manifest(rd)
    first_wedge = man.loc[man["wound_shape"] == "wedge", "geometry_id"].iloc[0]
    hit = man["geometry_id"] == first_wedge
    man.loc[hit, "wound_depth_factor"] = 99.0 / man.loc[hit, "total_thickness_mm"]
    man = _derive(man)
    keys = [*GEOMETRY_KEYS, "skin_type", "orientation_deg"]
    rows = man[keys].to_dict("records")
    man["job_id"] = [canonical_hash(r) for r in rows]
    man["geometry_id"] = [canonical_hash({k: r[k] for k in GEOMETRY_KEYS}) for r in rows]
    man.to_parquet(rd / "manifest.parquet", index=False)
    return rd


def broken_jobs(rd: Path) -> pd.DataFrame:
    man = manifest(rd)
    return man[np.isclose(man["wound_depth_mm"], 99.0)]


def test_bad_geometry_names_job_and_parameter(broken_run: Path) -> None:
    job = int(broken_jobs(broken_run)["job_index"].iloc[-1])
    res = ws("mesh", str(broken_run), "--job", str(job))
    assert res.returncode == 4
    assert res.stderr.count("\n") == 1
    assert f"job {job}: wound_depth_mm=99 reaches the bottom of the patch" in res.stderr


def test_all_reports_failures_at_the_end_without_stopping(broken_run: Path) -> None:
    res = ws("mesh", str(broken_run), "--all")
    assert res.returncode == 4
    man = manifest(broken_run)
    n_geom = man["geometry_id"].nunique()
    assert f"{n_geom - 1} of {n_geom} geometries meshed" in res.stdout
    bad_gid = broken_jobs(broken_run)["geometry_id"].iloc[0]
    failed = [ln for ln in res.stderr.splitlines() if ln.startswith("failed:")]
    assert len(failed) == 1 and bad_gid in failed[0] and "wound_depth_mm" in failed[0]
    assert f"1 of {n_geom} geometries failed" in res.stderr.splitlines()[-1]
    built = {p.stem for p in (broken_run / "meshes").glob("*.npz")}
    run = load_run(broken_run)
    good = run.manifest[run.manifest["geometry_id"] != bad_gid].to_dict("records")
    assert built == {run.geometry(row).mesh_id for row in good}
    # the progress bar goes to stderr, stdout holds only the summary
    assert "meshing" in res.stderr and len(res.stdout.splitlines()) == 2

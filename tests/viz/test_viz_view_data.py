"""The view's data beyond the surface (the mid-section cut, the profile lines, the element)
and the results of `woundsweep solve` read by `view` and `export` (no DOLFINx: the solver
files are written with `write_solver_file` and known fields)."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest
from viz_store import displacement, make_store, von_mises

from woundsweep.cli import main
from woundsweep.config.manifest import load_run
from woundsweep.core.diagnostics import StageReport
from woundsweep.core.schema import PROFILE_LINES
from woundsweep.mesh.cache import load_mesh, mesh_path
from woundsweep.store.identity import result_fingerprint
from woundsweep.store.solverfile import stamp_fingerprint, write_solver_file
from woundsweep.viz.surface import plane_slice


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_store(tmp_path_factory.mktemp("viewdata") / "run")


def _arr(b64: str, dtype: str) -> np.ndarray:
    return np.frombuffer(base64.b64decode(b64), dtype=dtype)


def _data(html: Path) -> dict:
    text = html.read_text()
    return json.loads(re.search(r'id="wsdata">(.*?)</script>', text, re.S).group(1))


def _solver_file(run: Path, job_index: int, path: Path, lines: int = 3) -> dict[int, np.ndarray]:
    """A solver file for a pending job: stages 1-2 converged, known fields and ``lines``
    profile lines (more than `PROFILE_LINES` stand for lines added later)."""
    r = load_run(run)
    job = r.job(job_index)
    mesh = load_mesh(mesh_path(run, r.geometry(job).mesh_id))
    n = len(mesh.cells)
    fields, extra, profiles = {}, {}, {}
    for k in (1, 2):
        u = displacement(mesh.points, k, job_index).astype(np.float32)
        vm = von_mises(mesh.points, mesh.cells, k, job_index).astype(np.float32)
        fields[k] = (u, vm)
        t = np.linspace(0.0, 1.0, 100)
        pts = np.stack([np.c_[t * (i + 1), 0 * t, -t] for i in range(lines)]).astype(np.float32)
        vals = np.stack([10.0 * k + i + t for i in range(lines)]).astype(np.float32)
        extra[k] = {"profile_von_mises_kPa": vals, "profile_points_mm": pts}
        profiles[k] = vals
    rows = [
        {"stage": k, "status": "converged", "cells": n, "dofs": 300, "newton_iterations": 4,
         "p99_von_mises_kPa": float(np.percentile(fields[k][1], 99)), "time_s": 1.0,
         "element_degree": 2}
        for k in (1, 2)
    ]  # fmt: skip
    attrs = {"job_id": job["job_id"], "job_index": job_index, "geometry_id": job["geometry_id"]}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_solver_file(path, attrs, mesh, [StageReport.from_row(r) for r in rows], fields, extra)
    stamp_fingerprint(path, result_fingerprint(r.sweep, job))  # as `woundsweep solve` does
    return profiles


def test_view_reads_solve_output_and_plots_every_stored_line(
    run: Path, tmp_path: Path, capsys
) -> None:
    # Job 3 has no stored result; `solve RUN --job 3` would write RUN/solve/job_3.h5.
    assert main(["view", str(run), "--job", "3", "--out", str(tmp_path / "a.html")]) == 2
    assert "no stored result" in capsys.readouterr().err
    profiles = _solver_file(run, 3, run / "solve" / "job_3.h5", lines=4)
    out = tmp_path / "v3.html"
    assert main(["view", str(run), "--job", "3", "--out", str(out)]) == 0
    assert "job 3: stages [1, 2] (from " in capsys.readouterr().out
    data = _data(out)
    assert [s["stage"] for s in data["stages"]] == [1, 2]
    assert data["element"].startswith("P2")  # the file's rows name the element, not the sweep
    for s in data["stages"]:
        names = [line["name"] for line in s["lines"]]
        assert names == [*PROFILE_LINES, "line_3"]  # a line beyond the three is shown too
        for i, line in enumerate(s["lines"]):
            np.testing.assert_allclose(line["von_mises_kPa"], profiles[s["stage"]][i], rtol=1e-6)
            # Running length from the first point: the i-th line is sqrt((i+1)^2 + 1) long.
            assert line["s_mm"][0] == 0 and line["s_mm"][-1] == pytest.approx(
                np.hypot(i + 1, 1), rel=1e-4
            )


def test_view_and_export_of_a_file_given_with_result(run: Path, tmp_path: Path, capsys) -> None:
    h5 = tmp_path / "elsewhere" / "j4.h5"
    _solver_file(run, 4, h5)
    out = tmp_path / "v4.html"
    assert main(["view", str(run), "--result", str(h5), "--out", str(out)]) == 0
    assert _data(out)["job_index"] == 4
    exp = tmp_path / "exp"
    assert main(["export", str(run), "--result", str(h5), "--out", str(exp)]) == 0
    assert "job 4: stages [1, 2]" in capsys.readouterr().out
    assert (exp / "job-4" / "job-4_stage2.vtm").is_file()
    # The file names its job: another --job is refused, in one line.
    assert main(["view", str(run), "--job", "5", "--result", str(h5), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds job 4, not job 5" in err[0]


def test_cut_lies_in_the_mid_plane_and_covers_the_section(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "v0.html"
    assert main(["view", str(run), "--job", "0", "--out", str(out)]) == 0
    data = _data(out)
    r = load_run(run)
    job = r.manifest.iloc[0]
    mesh = load_mesh(mesh_path(run, r.geometry(job).mesh_id))
    cut = data["cut"]
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    assert cut["y_mm"] == pytest.approx(0.5 * (lo[1] + hi[1]))
    xyz = np.c_[_arr(cut["x"], "<f4"), _arr(cut["y"], "<f4"), _arr(cut["z"], "<f4")]
    a, b, t = _arr(cut["a"], "<i4"), _arr(cut["b"], "<i4"), _arr(cut["t"], "<f4")
    p = (1 - t)[:, None] * xyz[a] + t[:, None] * xyz[b]
    np.testing.assert_allclose(p[:, 1], cut["y_mm"], atol=1e-5)
    tri = p[_arr(cut["tri"], "<i4").reshape(-1, 3)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    # The section of the wedge patch by the plane: the box's x-z rectangle less the wedge's
    # triangular opening (width w at the surface, depth d), planar faces meshed exactly.
    w, d = float(job["wound_width_mm"]), float(job["wound_depth_mm"])
    box = (hi[0] - lo[0]) * (hi[2] - lo[2])
    assert area.sum() == pytest.approx(box - 0.5 * w * d, rel=1e-6)
    # Each cut triangle is coloured by its tetrahedron's von Mises.
    for s in data["stages"]:
        vm = von_mises(mesh.points, mesh.cells, s["stage"], 0)
        got = _arr(s["cut_vm"], "<f4")
        assert len(got) == len(tri) and set(np.round(got, 3)) <= set(
            np.round(vm.astype(np.float32), 3)
        )
    assert data["element"].startswith("P1")


def test_plane_slice_of_one_tetrahedron() -> None:
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    cells = np.array([[0, 1, 2, 3]])
    one = plane_slice(pts, cells, 1, 0.5)  # node 2 alone above: a triangle, half-way edges
    assert one.triangles.shape == (1, 3) and np.allclose(one.edge_t, 0.5)
    # Nodes 2, 3 above, 0, 1 below: a quadrilateral as two triangles.
    quad = plane_slice(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]], float), cells, 1, 0.5)
    assert quad.triangles.shape == (2, 3) and len(quad.edge_a) == 4

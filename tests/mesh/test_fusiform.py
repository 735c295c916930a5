"""The fusiform excision: closed forms, its mesh (volume, rim, zone, symmetry, tags), the sweep
file's keys, and one job through the six stages."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_run import ROOT, ws

from woundsweep.config.fusiform import FLOOR_RISE, lens
from woundsweep.config.geometry import GeometrySpec
from woundsweep.config.manifest import expand
from woundsweep.config.sweep import load_sweep
from woundsweep.core.errors import GeometryError
from woundsweep.core.schema import (
    CELL_TAGS,
    DERMIS,
    FACET_TAGS,
    TOP,
    WOUND,
    WOUND_TAGS,
    WOUND_ZONE,
    X_MAX,
    X_MIN,
    Y_MAX,
    Y_MIN,
)
from woundsweep.mesh.build import build_mesh, signed_volumes
from woundsweep.physics.profiles import profile_lines, wound_edge_x

DEMO = ROOT / "sweeps" / "fusiform-demo.yaml"
# t_d, t_s, L, w, l, d: a 3:1 excision 2.1 mm deep through a 1.5 mm dermis.
SIZES = (1.5, 1.5, 6.0, 3.0, 9.0, 2.1)


def spec(m: float, y_fraction: float = 1.0, depth_fraction: float = 0.5) -> GeometrySpec:
    """The excision's P1 mesh parameters (the finer node spacing)."""
    return GeometrySpec.fusiform(
        *SIZES, m, zone_y_fraction=y_fraction, zone_depth_fraction=depth_fraction, element_degree=1
    )


@pytest.fixture(scope="module")
def meshes():
    return {m: build_mesh(spec(m)) for m in (0.3, 0.7)}


# -- closed forms against quadrature ------------------------------------------------------------


@pytest.mark.parametrize("ratio", [1.5, 3.0, 4.0])
def test_closed_forms_match_quadrature(ratio: float) -> None:
    w, d = 2.0, 1.7
    g = lens(ratio * w, w, d, 0.0)
    y = np.linspace(-g.a, g.a, 400_001)
    b = np.array([g.half_width(t) for t in y])
    assert b[0] == 0 and b[-1] == 0 and b.max() == pytest.approx(w / 2)
    assert g.area() == pytest.approx(np.trapz(2 * b, y), rel=1e-6)
    # Volume: the depth below the outline, d at the long axis rising by FLOOR_RISE d at b = w/2.
    depth_integral = 2 * d * b - FLOOR_RISE * d / (w / 2) * b**2
    assert g.volume() == pytest.approx(np.trapz(depth_integral, y), rel=1e-6)
    rim = 2 * np.hypot(np.diff(b), np.diff(y)).sum()
    assert g.rim_length() == pytest.approx(rim, rel=1e-6)
    # Apex angle from the outline's slope at the apex: twice its angle to the long axis.
    dy = 1e-7 * g.a
    slope = g.half_width(g.a - dy) / dy
    assert g.apex_angle_deg == pytest.approx(2 * math.degrees(math.atan(slope)), rel=1e-4)


def test_apex_angle_of_three_to_one_is_74_degrees() -> None:
    # Moody et al. 2001: two arcs at 3:1 meet at 73.7 degrees, not the textbooks' 30.
    assert lens(3.0, 1.0, 1.0, 0.0).apex_angle_deg == pytest.approx(73.74, abs=0.01)


def test_distance_is_zero_in_the_cavity_and_grows_away() -> None:
    g = spec(0.5).lens()
    assert g.distance(g.x_c, 0.0, -0.5) == 0.0
    assert g.distance(g.x_c - g.b - 1.0, 0.0, 0.0) == pytest.approx(1.0)
    assert g.distance(g.x_c, g.a + 2.0, 0.0) == pytest.approx(2.0)
    assert g.distance(g.x_c, 0.0, -g.d - 0.4) == pytest.approx(0.4)


# -- the mesh ---------------------------------------------------------------------------------


def _edges(facets: np.ndarray) -> set[tuple[int, int]]:
    e = np.sort(np.concatenate([facets[:, [0, 1]], facets[:, [1, 2]], facets[:, [2, 0]]]), axis=1)
    return set(map(tuple, e.tolist()))


def _cavity_volume(mesh) -> float:
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    return float(np.prod(hi - lo) - signed_volumes(mesh.points, mesh.cells).sum())


def _rim_length(mesh) -> float:
    top = _edges(mesh.facets[mesh.facet_tags == TOP])
    wound = _edges(mesh.facets[np.isin(mesh.facet_tags, WOUND_TAGS)])
    rim = np.array(sorted(top & wound))
    p = mesh.points
    return float(np.linalg.norm(p[rim[:, 0]] - p[rim[:, 1]], axis=1).sum())


def test_volume_and_rim_against_closed_form(meshes) -> None:
    g = spec(0.3).lens()
    errors = {}
    for m, mesh in meshes.items():
        vol = _cavity_volume(mesh) / g.volume() - 1
        rim = _rim_length(mesh) / g.rim_length() - 1
        # Chords inside the arcs: the mesh's cavity and rim are slightly smaller.
        assert -0.01 < vol < 0 and -0.002 < rim < 0, (m, vol, rim)
        errors[m] = (vol, rim)
    assert abs(errors[0.7][0]) < abs(errors[0.3][0])  # the chords' error falls with refinement
    assert abs(errors[0.7][1]) < abs(errors[0.3][1])


def test_patch_extends_L_beyond_the_wound(meshes) -> None:
    t_d, t_s, L, w, length, _ = SIZES
    mesh = meshes[0.3]
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    np.testing.assert_allclose(lo, [-L, -(L + length / 2), -(t_d + t_s)])
    np.testing.assert_allclose(hi, [L + w, L + length / 2, 0.0])


def test_tags_present_and_layers_split_at_the_dermis(meshes) -> None:
    mesh = meshes[0.3]
    assert set(FACET_TAGS.values()) <= set(np.unique(mesh.facet_tags))
    assert set(CELL_TAGS.values()) == set(np.unique(mesh.cell_tags))
    z = mesh.points[mesh.cells].mean(axis=1)[:, 2]
    t_d = SIZES[0]
    assert np.all((z > -t_d) == (mesh.cell_tags == DERMIS))
    # The floor (below the walls' lowest point) is wound, never zone.
    floor_z = -(1 - FLOOR_RISE) * SIZES[5]
    fz = mesh.points[mesh.facets].mean(axis=1)[:, 2]
    assert np.any((mesh.facet_tags == WOUND) & (fz < floor_z))
    assert not np.any((mesh.facet_tags == WOUND_ZONE) & (fz < floor_z))


def _canonical(points: np.ndarray) -> np.ndarray:
    return points[np.lexsort(np.round(points, 9).T[::-1])]


def test_mesh_is_mirror_symmetric(meshes) -> None:
    mesh = meshes[0.3]
    p = mesh.points
    x_c = SIZES[3] / 2
    mirror_x = p * [-1, 1, 1] + [2 * x_c, 0, 0]
    mirror_y = p * [1, -1, 1]
    # 2 x_c - x is exact up to one rounding of the sum.
    np.testing.assert_allclose(_canonical(mirror_x), _canonical(p), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(_canonical(mirror_y), _canonical(p))
    zone = p[np.unique(mesh.facets[mesh.facet_tags == WOUND_ZONE])]
    image = _canonical(zone * [-1, 1, 1] + [2 * x_c, 0, 0])
    np.testing.assert_allclose(image, _canonical(zone), rtol=0, atol=1e-12)
    for a, b in ((X_MIN, X_MAX), (Y_MIN, Y_MAX)):
        assert np.sum(mesh.facet_tags == a) == np.sum(mesh.facet_tags == b)


@pytest.mark.parametrize("y_fraction", [1.0, 0.5])
def test_zone_is_the_walls_upper_part_over_its_length(y_fraction: float) -> None:
    s = spec(0.5, y_fraction=y_fraction)
    mesh = build_mesh(s)
    g = s.lens()
    tri = mesh.points[mesh.facets[mesh.facet_tags == WOUND_ZONE]]
    z_min = -s.zone_depth_fraction * s.wound_depth_mm
    y_max = y_fraction * g.a
    assert tri[..., 2].min() == pytest.approx(z_min) and tri[..., 2].max() == 0.0
    assert np.abs(tri[..., 1]).max() == pytest.approx(y_max)
    # Walls are vertical: the zone's area is the outline's length within |y| <= y_max times
    # the zone depth (the facets are chords of the arcs: slightly less).
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    exact = 4 * g.radius * math.asin(y_max / g.radius) * -z_min
    assert -0.002 < area.sum() / exact - 1 < 0


def test_profile_lines_start_at_the_excisions_edge(meshes) -> None:
    mesh = meshes[0.3]
    edge = wound_edge_x(mesh.points, mesh.facets, mesh.facet_tags)
    assert edge == 0.0  # x_c - w/2: the bounding-box rule would put it at l/2
    lines = profile_lines(mesh.points, edge)
    assert np.all(lines[0][:, 0] == edge) and np.all(lines[1][:, 0] == edge)
    wedge = build_mesh(GeometrySpec.wedge(1, 1, 4, 1.2, 0.6, 0.3))
    assert wound_edge_x(wedge.points, wedge.facets, wedge.facet_tags) is None  # the bbox rule


def test_cells_grow_with_the_mesh_size_factor(meshes) -> None:
    assert meshes[0.7].info["cells"] > 1.5 * meshes[0.3].info["cells"]


def test_trench_cache_keys_have_no_length() -> None:
    wedge = GeometrySpec.wedge(1, 1, 4, 1.2, 0.6, 0.3)
    assert "wound_length_mm" not in wedge.to_dict()
    assert spec(0.3).to_dict()["wound_length_mm"] == SIZES[4]


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"wound_length_mm": 3.0}, "longer than the width"),
        ({"zone_depth_fraction": 0.8}, "must be below 0.75"),
        ({"wound_depth_mm": 3.0}, "reaches the bottom"),
    ],
)
def test_bad_fusiform_geometry(change: dict, words: str) -> None:
    params = {**spec(0.3).to_dict(), **change}
    with pytest.raises(GeometryError, match=words):
        GeometrySpec(**params)


# -- the sweep file ---------------------------------------------------------------------------


def test_demo_sweep_expands_with_the_length_columns() -> None:
    df = expand(load_sweep(DEMO))
    assert list(df["orientation_deg"]) == [0.0, 45.0, 90.0]
    assert df["geometry_id"].nunique() == 1
    row = df.iloc[0]
    assert row["wound_length_mm"] == pytest.approx(
        row["wound_length_factor"] * row["wound_width_mm"]
    )
    assert row["wound_depth_mm"] == pytest.approx(
        row["wound_depth_factor"] * row["total_thickness_mm"]
    )
    assert math.isnan(row["wound_aspect_factor"])


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda d: d["shapes"]["fusiform"].update(wound_length_factor=[1]), "wound_length_factor"),
        (lambda d: d["shapes"]["fusiform"].pop("wound_depth_factor"), "shapes.fusiform"),
        (lambda d: d["stages"]["closure_zone"].update(depth_fraction=0.9), "zone_depth_fraction"),
    ],
)
def test_bad_fusiform_sweep_is_one_line_exit_2(edit, key: str, tmp_path: Path) -> None:
    doc = yaml.safe_load(DEMO.read_text())
    edit(doc)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    res = ws("generate", str(path), "--out", str(tmp_path / "run"))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "woundsweep: error" in lines[0]


# -- one job through the stages ---------------------------------------------------------------


@pytest.mark.fem
def test_fusiform_job_closes_through_six_stages(tmp_path: Path) -> None:
    from woundsweep.cli import main
    from woundsweep.store.reader import read_results

    run_dir = tmp_path / "run"
    assert main(["generate", str(DEMO), "--out", str(run_dir)]) == 0
    assert main(["run", str(run_dir), "--workers", "1", "--fields", "none"]) == 0
    rows = read_results(run_dir)
    job = rows[rows["orientation_deg"] == 45.0]  # oblique: the stiff axis not mirror-symmetric
    assert sorted(job["stage"]) == [1, 2, 3, 4, 5, 6]
    assert set(rows["status"]) == {"converged"}
    later = rows[rows["stage"] >= 2]
    assert (later["closed"] == 1).all()
    assert (later["closure_gap_max_per_w"] <= 0.05).all()
    # The stage-2 closure pulls both flanks toward the mid-plane (opposite x-forces), equal in
    # size at 0 and 90 degrees, where the material is mirror-symmetric about x = x_c.
    s2 = rows[rows["stage"] == 2].set_index("orientation_deg")
    left, right = s2["closure_force_left_mN"], s2["closure_force_right_mN"]
    assert (left > 0).all()
    for t in (0.0, 90.0):
        assert -right[t] == pytest.approx(left[t], rel=1e-6)
    # Clinically, a wound along the Langer line (orientation 90) closes with less force than
    # one across it (orientation 0).
    assert left[90.0] < left[45.0] < left[0.0]

"""woundsweep.mesh: analytic volumes and areas, tags, symmetry, size law, determinism, errors."""

from __future__ import annotations

import functools
import hashlib
import math
import subprocess
import sys

import gmsh
import numpy as np
import pandas as pd
import pytest

from woundsweep.config.geometry import GeometrySpec
from woundsweep.core.errors import GeometryError
from woundsweep.core.schema import CELL_TAGS, FACET_TAGS, TAGS, WOUND_TAGS
from woundsweep.mesh.build import MeshData, build_mesh, zone_limits
from woundsweep.mesh.sizing import PAPER_CELL_CAP, SIZE_LAW, mesh_size_mm, size_scale, wound_size

# Coarse but varied: both shapes, wounds inside the dermis, touching the interface
# (cylinder tangent to it, wedge apex on it) and cutting into the subcutis. P1 meshes: the
# finer of the two elements' node spacings.
SPECS = {
    "cyl-a0.2-dermis": GeometrySpec.cylindrical(1.0, 1.0, 2.0, 1.0, 0.2, 0.5, element_degree=1),
    "cyl-a0-tangent": GeometrySpec.cylindrical(1.0, 1.0, 4.0, 2.0, 0.0, 0.3, element_degree=1),
    "cyl-a0.1-subcutis": GeometrySpec.cylindrical(0.5, 1.0, 1.5, 1.5, 0.1, 0.3, element_degree=1),
    "wedge-dermis": GeometrySpec.wedge(2.0, 1.0, 3.0, 1.5, 0.9, 0.3, element_degree=1),
    "wedge-apex-on-interface": GeometrySpec.wedge(1.0, 1.0, 2.0, 1.0, 1.0, 0.5, element_degree=1),
    "wedge-subcutis": GeometrySpec.wedge(1.0, 2.0, 3.0, 2.4, 2.1, 0.3, element_degree=1),
}


@pytest.fixture(scope="module")
def meshes() -> dict[str, MeshData]:
    return {name: build_mesh(spec) for name, spec in SPECS.items()}


# ---------------------------------------------------------------- independent reference formulas


def wound_area_below(spec: GeometrySpec, c: float) -> float:
    """Cross-section area (xz) of the wound below the level z = c <= 0."""
    w, d = spec.wound_width_mm, spec.wound_depth_mm
    if spec.shape == "wedge":
        return w * max(d + c, 0.0) ** 2 / (2 * d)  # width w (1 + z/d) at height z
    a = spec.wound_aspect_factor
    R, zc = math.hypot(w / 2, a * w), a * w
    h = zc - c  # distance from the axis down to the chord
    if h >= R:
        return 0.0
    return R * R * math.acos(h / R) - h * math.sqrt(R * R - h * h)  # circular segment


def layer_volumes(spec: GeometrySpec) -> tuple[float, float]:
    L, w, t_d, t_s = (
        spec.patch_half_length_mm,
        spec.wound_width_mm,
        spec.dermal_thickness_mm,
        spec.subcutis_thickness_mm,
    )
    face = (2 * L + w) * 2 * L
    below_interface = wound_area_below(spec, -t_d)
    dermis = face * t_d - (wound_area_below(spec, 0.0) - below_interface) * 2 * L
    return dermis, face * t_s - below_interface * 2 * L


def wound_surface_area(spec: GeometrySpec) -> float:
    w, d, L = spec.wound_width_mm, spec.wound_depth_mm, spec.patch_half_length_mm
    if spec.shape == "wedge":
        return 2 * math.hypot(w / 2, d) * 2 * L
    a = spec.wound_aspect_factor
    R = math.hypot(w / 2, a * w)
    return 2 * R * math.acos(a * w / R) * 2 * L  # arc below the chord at z = 0


def tet_volumes(mesh: MeshData) -> np.ndarray:
    p = mesh.points[mesh.cells]
    return (
        np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6
    )


def tri_areas(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p = points[tris]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def exterior_faces(cells: np.ndarray) -> set[tuple[int, ...]]:
    """Faces belonging to exactly one tetrahedron, as sorted vertex triples."""
    faces = np.sort(cells[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
    uniq, counts = np.unique(faces, axis=0, return_counts=True)
    return {tuple(f) for f in uniq[counts == 1]}


# ---------------------------------------------------------------- tests


def test_tag_integers_are_the_documented_ones() -> None:
    assert dict(CELL_TAGS) == {"dermis": 1, "subcutis": 2}
    assert dict(FACET_TAGS) == {
        "x_min": 11, "x_max": 12, "y_min": 13, "y_max": 14, "bottom": 15, "top": 16, "wound": 17,
        "wound_zone": 18,
    }  # fmt: skip
    assert TAGS["dermis"] == 1 and TAGS["wound"] == 17


@pytest.mark.parametrize("name", list(SPECS))
def test_layer_volumes_match_analytic(meshes: dict[str, MeshData], name: str) -> None:
    spec, mesh = SPECS[name], meshes[name]
    vol = tet_volumes(mesh)
    dermis, subcutis = layer_volumes(spec)
    got_d = vol[mesh.cell_tags == CELL_TAGS["dermis"]].sum()
    got_s = vol[mesh.cell_tags == CELL_TAGS["subcutis"]].sum()
    assert got_d == pytest.approx(dermis, rel=5e-3)
    assert got_s == pytest.approx(subcutis, rel=5e-3)


@pytest.mark.parametrize("name", list(SPECS))
def test_wound_surface_area_matches_analytic(meshes: dict[str, MeshData], name: str) -> None:
    spec, mesh = SPECS[name], meshes[name]
    wound = mesh.facets[np.isin(mesh.facet_tags, WOUND_TAGS)]
    assert tri_areas(mesh.points, wound).sum() == pytest.approx(wound_surface_area(spec), rel=1e-2)


@pytest.mark.parametrize("name", list(SPECS))
def test_facets_cover_the_exterior_exactly_once(meshes: dict[str, MeshData], name: str) -> None:
    mesh = meshes[name]
    tagged = [tuple(f) for f in np.sort(mesh.facets, axis=1)]
    assert len(tagged) == len(set(tagged))  # no facet twice
    assert set(tagged) == exterior_faces(mesh.cells)


@pytest.mark.parametrize("name", list(SPECS))
def test_each_facet_tag_lies_on_its_surface(meshes: dict[str, MeshData], name: str) -> None:
    spec, mesh = SPECS[name], meshes[name]
    L, T, w = spec.patch_half_length_mm, spec.total_thickness_mm, spec.wound_width_mm
    planes = {"x_min": (0, -L), "x_max": (0, L + w), "y_min": (1, -L), "y_max": (1, L),
              "bottom": (2, -T), "top": (2, 0.0)}  # fmt: skip
    for name_, (axis, value) in planes.items():
        tris = mesh.facets[mesh.facet_tags == FACET_TAGS[name_]]
        assert len(tris) > 0
        np.testing.assert_allclose(mesh.points[tris][..., axis], value, atol=1e-12 * (L + T))
    # Wound facets (closure zone included): vertices on the cylinder / on a flank plane.
    tris = mesh.facets[np.isin(mesh.facet_tags, WOUND_TAGS)]
    p = mesh.points[np.unique(tris)]
    if spec.shape == "cylindrical":
        a = spec.wound_aspect_factor
        R = math.hypot(w / 2, a * w)
        np.testing.assert_allclose(np.hypot(p[:, 0] - w / 2, p[:, 2] - a * w), R, rtol=1e-6)
    else:
        # |x - w/2| = (w/2) (1 + z/d) on the flanks
        d = spec.wound_depth_mm
        np.testing.assert_allclose(
            np.abs(p[:, 0] - w / 2), w / 2 * (1 + p[:, 2] / d), atol=1e-6 * w
        )
    assert p[:, 2].min() == pytest.approx(-spec.wound_depth_mm, abs=1e-12 * T)


@pytest.mark.parametrize("name", list(SPECS))
def test_mesh_is_valid_conforming_and_compact(meshes: dict[str, MeshData], name: str) -> None:
    spec, mesh = SPECS[name], meshes[name]
    assert mesh.points.dtype == np.float64 and mesh.points.shape[1] == 3
    assert mesh.cells.dtype == np.int64 and mesh.facets.dtype == np.int64
    assert mesh.cell_tags.dtype == np.int32 and mesh.facet_tags.dtype == np.int32
    # every node used, numbered 0..n-1, no duplicated coordinates
    assert np.array_equal(np.unique(mesh.cells), np.arange(len(mesh.points)))
    assert len(np.unique(mesh.points, axis=0)) == len(mesh.points)
    vol = tet_volumes(mesh)
    assert vol.min() > 1e-6 * vol.mean()  # positively oriented, none degenerate
    assert 0 < mesh.info["min_quality"] <= 1
    assert mesh.info["cells"] == len(mesh.cells) and mesh.info["vertices"] == len(mesh.points)
    # Layers meshed apart: no cell straddles the interface, and the interface faces seen from
    # the dermis are exactly those seen from the subcutis (shared nodes, conforming).
    t_d, eps = spec.dermal_thickness_mm, 1e-12 * spec.total_thickness_mm
    z = mesh.points[:, 2][mesh.cells]
    derm = mesh.cell_tags == CELL_TAGS["dermis"]
    assert z[derm].min() >= -t_d - eps and z[~derm].max() <= -t_d + eps

    def interface_faces(cells: np.ndarray) -> set[tuple[int, ...]]:
        f = np.sort(cells[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
        on = np.all(np.abs(mesh.points[f][..., 2] + t_d) <= eps, axis=1)
        return {tuple(x) for x in f[on]}

    top_of_sub, bottom_of_derm = (
        interface_faces(mesh.cells[~derm]),
        interface_faces(mesh.cells[derm]),
    )
    assert top_of_sub == bottom_of_derm and top_of_sub
    # The interface area is the patch minus the wound's width at z = -t_d.
    L, w = spec.patch_half_length_mm, spec.wound_width_mm
    tri = np.array(sorted(top_of_sub))
    if spec.shape == "wedge":
        gap = w * max(0.0, 1 - t_d / spec.wound_depth_mm)
    else:
        a = spec.wound_aspect_factor
        R, zc = math.hypot(w / 2, a * w), a * w
        gap = 2 * math.sqrt(max(0.0, R * R - (zc + t_d) ** 2))
    assert tri_areas(mesh.points, tri).sum() == pytest.approx((2 * L + w - gap) * 2 * L, rel=5e-3)


@pytest.mark.parametrize("name", list(SPECS))
def test_node_cloud_is_mirror_symmetric(meshes: dict[str, MeshData], name: str) -> None:
    # The quarter x <= w/2, y >= 0 is meshed and mirrored, so symmetry about x = w/2 (and
    # y = 0) holds to rounding: every mirrored node has a node within 1e-9 of the patch size,
    # and the facet tags map onto each other (x_min <-> x_max).
    spec, mesh = SPECS[name], meshes[name]
    w, scale = spec.wound_width_mm, spec.patch_half_length_mm
    mirrored = mesh.points.copy()
    mirrored[:, 0] = w - mirrored[:, 0]
    nearest = np.array(
        [
            np.min(np.linalg.norm(mesh.points - q, axis=1))
            for q in mirrored[:: max(1, len(mirrored) // 600)]
        ]
    )
    assert nearest.max() < 1e-9 * scale
    # whole-set comparison after rounding well below the mesh size
    key = lambda p: {tuple(r) for r in np.round(p / scale, 7)}  # noqa: E731
    assert key(mirrored) == key(mesh.points)
    x_min = tri_areas(mesh.points, mesh.facets[mesh.facet_tags == FACET_TAGS["x_min"]]).sum()
    x_max = tri_areas(mesh.points, mesh.facets[mesh.facet_tags == FACET_TAGS["x_max"]]).sum()
    assert x_min == pytest.approx(x_max, rel=1e-12)
    assert x_min == pytest.approx(2 * spec.patch_half_length_mm * spec.total_thickness_mm, rel=1e-9)


def test_identical_parameters_give_identical_meshes(meshes: dict[str, MeshData]) -> None:
    name = "wedge-subcutis"
    again = build_mesh(SPECS[name])
    for field in ("points", "cells", "cell_tags", "facets", "facet_tags"):
        assert np.array_equal(getattr(again, field), getattr(meshes[name], field)), field


def test_identical_meshes_across_processes(meshes: dict[str, MeshData]) -> None:
    name = "cyl-a0.2-dermis"
    code = (
        "import hashlib, sys\n"
        "from woundsweep.mesh.build import build_mesh\n"
        "from woundsweep.config.geometry import GeometrySpec\n"
        "m = build_mesh(GeometrySpec.cylindrical(1.0, 1.0, 2.0, 1.0, 0.2, 0.5, element_degree=1))\n"
        "h = hashlib.sha256()\n"
        "for a in m[:5]: h.update(a.tobytes())\n"
        "print(h.hexdigest())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    here = hashlib.sha256()
    for arr in meshes[name][:5]:
        here.update(arr.tobytes())
    assert out.stdout.strip() == here.hexdigest()


@pytest.mark.parametrize(
    "make",
    [
        lambda m: GeometrySpec.cylindrical(1.0, 1.0, 2.0, 1.6, 0.1, m, element_degree=1),
        lambda m: GeometrySpec.wedge(0.5, 1.0, 2.25, 1.2, 1.05, m, element_degree=1),
    ],
)
def test_larger_mesh_size_factor_gives_strictly_more_cells(make) -> None:
    cells = [build_mesh(make(m)).info["cells"] for m in (0.3, 0.5, 0.7)]
    assert cells[0] < cells[1] < cells[2]


def test_size_law_is_finer_in_dermis_near_wound_and_with_larger_factor() -> None:
    spec = GeometrySpec.cylindrical(1.0, 2.0, 9.0, 2.7, 0.1, 0.5, element_degree=1)
    finer = GeometrySpec.cylindrical(1.0, 2.0, 9.0, 2.7, 0.1, 0.7, element_degree=1)
    x_far = -6.0
    # coarser with depth, dermis finer than subcutis
    dermis = [mesh_size_mm(spec, x_far, 0.0, z) for z in (-0.01, -0.5, -0.99)]
    subcutis = [mesh_size_mm(spec, x_far, 0.0, z) for z in (-1.5, -2.0, -2.5, -2.99)]
    assert max(dermis) < subcutis[0] < subcutis[1] <= subcutis[2] <= subcutis[3]  # L/4 caps
    assert subcutis[-1] > 1.5 * max(dermis)
    # finer near the wound than far from it, at every depth
    for z in (-0.1, -0.5, -1.5):
        assert mesh_size_mm(spec, -0.05, 0.0, z) < mesh_size_mm(spec, x_far, 0.0, z)
    # larger factor: smaller everywhere
    for x, z in [(-0.05, -0.1), (-3.0, -1.0), (x_far, -2.9)]:
        assert mesh_size_mm(finer, x, 0.0, z) < mesh_size_mm(spec, x, 0.0, z)


def test_size_law_sets_node_spacing_so_p2_edges_are_twice_p1s() -> None:
    p1 = GeometrySpec.cylindrical(1.0, 2.0, 9.0, 2.7, 0.1, 0.5, element_degree=1)
    p2 = GeometrySpec(**(p1.to_dict() | {"element_degree": 2}))
    for x, z in [(-0.05, -0.1), (-3.0, -1.0), (-6.0, -2.9), (1.3, -0.2)]:
        assert mesh_size_mm(p2, x, 0.0, z) == pytest.approx(2.0 * mesh_size_mm(p1, x, 0.0, z))


def test_mesh_cells_are_smaller_in_dermis_than_in_subcutis(meshes: dict[str, MeshData]) -> None:
    mesh = meshes["wedge-dermis"]
    vol = tet_volumes(mesh)
    derm = mesh.cell_tags == CELL_TAGS["dermis"]
    assert np.median(vol[derm]) < np.median(vol[~derm])


def _paper_row(manifest, **where):
    sel = manifest
    for key, value in where.items():
        sel = (
            sel[np.isclose(sel[key], value)]
            if not isinstance(value, str)
            else sel[sel[key] == value]
        )
    return sel.drop_duplicates("geometry_id")


def test_cell_cap_holds_for_extreme_paper_geometries(paper: pd.DataFrame) -> None:
    finest = paper[paper["mesh_size_factor"] == paper["mesh_size_factor"].max()]
    picks = [
        # largest patch relative to the dermis, narrowest (finest-meshed) wound, deepest wedge
        _paper_row(
            finest,
            subcutis_thickness_factor=2,
            patch_size_factor=3,
            wound_width_factor=0.3,
            dermal_thickness_mm=4.0,
        ),  # fmt: skip
        # thinnest skin, smallest patch, narrow deep wedge
        _paper_row(
            finest,
            subcutis_thickness_factor=0.5,
            patch_size_factor=1,
            wound_width_factor=0.3,
            dermal_thickness_mm=0.5,
        ),  # fmt: skip
    ]
    rows = [r for _, r in pd.concat(picks).iterrows()]
    rows = [r for r in rows if r["wound_shape"] == "wedge" and r["wound_depth_factor"] == 0.7
            or r["wound_shape"] == "cylindrical" and r["wound_aspect_factor"] == 0.0]  # fmt: skip
    assert len(rows) == 4
    for row in rows:
        spec = GeometrySpec.from_row(row, None, 1)  # P1: the finer mesh
        info = build_mesh(spec).info
        assert info["cells"] < PAPER_CELL_CAP, spec.describe()
        assert info["min_quality"] > 0


def test_gmsh_prints_nothing_and_respects_a_callers_session(capfd: pytest.CaptureFixture) -> None:
    spec = SPECS["cyl-a0.2-dermis"]
    build_mesh(spec)
    assert capfd.readouterr().out == ""
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.model.add("callers-model")
        build_mesh(spec)
        assert gmsh.isInitialized() and gmsh.model.getCurrent() == "callers-model"
    finally:
        gmsh.finalize()
    assert not gmsh.isInitialized()


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("make", "param"),
    [
        (lambda: GeometrySpec.wedge(1.0, 1.0, 1.0, 2.5, 0.5, 0.5), "wound_width_mm"),  # w > 2L
        (lambda: GeometrySpec.wedge(1.0, 1.0, 3.0, 1.0, 2.0, 0.5), "wound_depth_mm"),  # d = T
        (lambda: GeometrySpec.wedge(1.0, 1.0, 3.0, 1.0, 2.5, 0.5), "wound_depth_mm"),  # below
        (lambda: GeometrySpec.wedge(-1.0, 1.0, 3.0, 1.0, 0.5, 0.5), "dermal_thickness_mm"),
        (lambda: GeometrySpec.wedge(1.0, 0.0, 3.0, 1.0, 0.5, 0.5), "subcutis_thickness_mm"),
        (lambda: GeometrySpec.wedge(1.0, 1.0, math.nan, 1.0, 0.5, 0.5), "patch_half_length_mm"),
        (lambda: GeometrySpec.wedge(1.0, 1.0, 3.0, 1.0, 0.5, 0.0), "mesh_size_factor"),
        (lambda: GeometrySpec.cylindrical(1.0, 1.0, 3.0, 1.0, -0.1, 0.5), "wound_aspect_factor"),
        (lambda: GeometrySpec("cylindrical", 1.0, 1.0, 3.0, 1.0, 0.2, 0.1, 0.5), "wound_depth_mm"),
        (lambda: GeometrySpec("cone", 1.0, 1.0, 3.0, 1.0, 0.2, None, 0.5), "shape"),
    ],
)
def test_bad_geometry_is_a_one_line_error_naming_the_parameter(make, param: str) -> None:
    with pytest.raises(GeometryError) as exc:
        make()
    msg = str(exc.value)
    assert param in msg and "\n" not in msg


def test_from_row_reads_manifest_columns_and_names_the_job() -> None:
    row = {
        "job_index": 17, "wound_shape": "wedge", "dermal_thickness_mm": 1.0,
        "subcutis_thickness_mm": 1.0, "patch_half_length_mm": 2.0, "wound_width_mm": 1.0,
        "wound_depth_mm": 0.6, "wound_aspect_factor": math.nan, "mesh_size_factor": 0.3,
    }  # fmt: skip
    spec = GeometrySpec.from_row(row)
    assert spec == GeometrySpec.wedge(1.0, 1.0, 2.0, 1.0, 0.6, 0.3)
    with pytest.raises(GeometryError, match=r"^job 17: wound_depth_mm=2\.5 reaches the bottom"):
        GeometrySpec.from_row(row | {"wound_depth_mm": 2.5})
    cyl = GeometrySpec.from_row(
        row | {"wound_shape": "cylindrical", "wound_aspect_factor": 0.0, "wound_depth_mm": 0.5}
    )
    assert cyl.wound_radius_mm == pytest.approx(0.5)


def _edge_lengths_near(mesh: MeshData, near) -> np.ndarray:
    """Mean edge length (mm) of the cells whose centroid satisfies ``near(x, y, z)``."""
    p = mesh.points[mesh.cells]
    c = p.mean(axis=1)
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    edges = np.mean([np.linalg.norm(p[:, i] - p[:, j], axis=1) for i, j in pairs], axis=0)
    sel = near(c[:, 0], c[:, 1], c[:, 2])
    assert sel.sum() >= 5
    return edges[sel]


def test_the_law_refines_a_wedges_apex_and_the_zone_border_in_the_mesh() -> None:
    """The built mesh is finer at a wedge's apex (a re-entrant edge) than on its flank away
    from it, by the law's ratio there, and finer at the closure zone's border than in the
    dermis away from the wound; a cylinder's floor line (its notch root) gets the same ratio."""
    # the apex 0.8 mm deep, w = 2 mm
    spec = GeometrySpec.wedge(1.0, 1.0, 4.0, 2.0, 0.8, 0.7, element_degree=1)
    mesh = build_mesh(spec)
    w, d = spec.wound_width_mm, spec.wound_depth_mm
    r = 0.15

    def near(x0, z0):
        return lambda x, y, z: np.hypot(x - x0, z - z0) < r

    # the flank's midpoint, 0.45 mm from the apex, and a point just outside it in the dermis
    xm, zm = w / 4, -d / 2
    apex = _edge_lengths_near(mesh, near(w / 2, -d))
    flank = _edge_lengths_near(mesh, near(xm - 0.15, zm))
    assert np.median(apex) < 0.75 * np.median(flank)
    # the closure zone's border on the flank against the dermis half a patch away
    y_max, _ = zone_limits(spec)
    border = _edge_lengths_near(
        mesh, lambda x, y, z: (np.hypot(x - xm, z - zm) < 0.3) & (np.abs(y - y_max) < 0.3)
    )
    far = _edge_lengths_near(mesh, lambda x, y, z: (x < -spec.patch_half_length_mm / 2) & (z > -1))
    assert np.median(border) < 0.5 * np.median(far)
    # the law itself: h_w on the flank, the apex's fraction of it at the apex
    h = functools.partial(mesh_size_mm, spec)
    assert h(xm, 0.0, zm) / size_scale(0.7, 1) == pytest.approx(wound_size(spec), rel=1e-12)
    assert h(w / 2, 0.0, -d) / h(xm, 0.0, zm) == pytest.approx(SIZE_LAW["floor_per_wound"])
    cyl = GeometrySpec.cylindrical(1.0, 1.0, 4.0, 2.0, 0.1, 0.7, element_degree=1)
    bottom = -cyl.wound_depth_mm
    assert mesh_size_mm(cyl, w / 2, 0.0, bottom) / size_scale(0.7, 1) == pytest.approx(
        SIZE_LAW["floor_per_wound"] * wound_size(cyl), rel=1e-12
    )

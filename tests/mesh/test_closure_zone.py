"""The closure zone is meshed geometry: its area, its border as mesh edges, its use in the model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from woundsweep.config.geometry import GeometrySpec
from woundsweep.core.errors import GeometryError
from woundsweep.core.schema import WOUND, WOUND_ZONE
from woundsweep.mesh.build import MeshData, build_mesh


def exact_zone_area(spec: GeometrySpec) -> float:
    """Both flanks' zone area from the closed forms (not from the mesh module)."""
    w, d, L = spec.wound_width_mm, spec.wound_depth_mm, spec.patch_half_length_mm
    y_len = 2 * spec.zone_y_fraction * L  # |y| <= y_fraction L
    z_min = -spec.zone_depth_fraction * d
    if spec.shape == "wedge":
        strip = math.hypot(w / 2, d) * spec.zone_depth_fraction  # planar flank, z in [z_min, 0]
    else:
        a = spec.wound_aspect_factor
        R, zc = math.hypot(w / 2, a * w), a * w
        # arc length between the surface and z_min: angles from the downward vertical
        strip = R * (math.acos(zc / R) - math.acos((zc - z_min) / R))
    return 2 * strip * y_len


def tri_areas(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p = points[tris]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def shape_spec(shape: str, m: float, **zone: float) -> GeometrySpec:
    # The demo patch (t_d = 1, T = 2, L = 4, w = 1.2); the wedge is as deep as the cylinder.
    # P1 meshes (the finer node spacing).
    if shape == "cylindrical":
        spec = GeometrySpec.cylindrical(1.0, 1.0, 4.0, 1.2, 0.0, m, element_degree=1)
    else:
        spec = GeometrySpec.wedge(1.0, 1.0, 4.0, 1.2, 0.6, m, element_degree=1)
    return GeometrySpec(**(spec.to_dict() | zone))


FACTORS = (0.3, 0.5, 0.7, 1.0)


@pytest.fixture(scope="module")
def meshes() -> dict[tuple[str, float], MeshData]:
    return {(s, m): build_mesh(shape_spec(s, m)) for s in ("cylindrical", "wedge") for m in FACTORS}


@pytest.mark.parametrize("m", (0.3, 0.7))
@pytest.mark.parametrize("shape", ["cylindrical", "wedge"])
def test_p2_meshes_zone_area_is_exact_within_one_percent(shape: str, m: float) -> None:
    """P2 meshes (edges twice as long) still carry the zone as geometry."""
    spec = GeometrySpec(**(shape_spec(shape, m).to_dict() | {"element_degree": 2}))
    mesh = build_mesh(spec)
    area = tri_areas(mesh.points, mesh.facets[mesh.facet_tags == WOUND_ZONE]).sum()
    assert area == pytest.approx(exact_zone_area(spec), rel=1e-2)
    assert mesh.info["cells"] < build_mesh(shape_spec(shape, m)).info["cells"]


@pytest.mark.parametrize("m", FACTORS)
@pytest.mark.parametrize("shape", ["cylindrical", "wedge"])
def test_zone_area_is_exact_within_one_percent(meshes, shape: str, m: float) -> None:
    mesh, spec = meshes[shape, m], shape_spec(shape, m)
    area = tri_areas(mesh.points, mesh.facets[mesh.facet_tags == WOUND_ZONE]).sum()
    assert area == pytest.approx(exact_zone_area(spec), rel=1e-2)
    if shape == "wedge":  # planar flanks: the facets tile the strip exactly
        assert area == pytest.approx(exact_zone_area(spec), rel=1e-9)


def border_check(mesh: MeshData, spec: GeometrySpec) -> None:
    """Every zone facet edge is shared by two zone facets or lies on a border line (|y| = y_max,
    z = z_min or the skin surface), and every vertex of a zone facet is inside the zone."""
    L, d = spec.patch_half_length_mm, spec.wound_depth_mm
    y_max, z_min = spec.zone_y_fraction * L, -spec.zone_depth_fraction * d
    tol = 1e-9 * L
    zone = mesh.facets[mesh.facet_tags == WOUND_ZONE]
    p = mesh.points
    assert (np.abs(p[zone, 1]) <= y_max + tol).all() and (p[zone, 2] >= z_min - tol).all()
    edges = np.sort(zone[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    assert count.max() <= 2
    border = uniq[count == 1]
    a, b = p[border[:, 0]], p[border[:, 1]]
    on_y = (np.abs(np.abs(a[:, 1]) - y_max) < tol) & (np.abs(np.abs(b[:, 1]) - y_max) < tol)
    on_y &= np.sign(a[:, 1]) == np.sign(b[:, 1])
    on_z = (np.abs(a[:, 2] - z_min) < tol) & (np.abs(b[:, 2] - z_min) < tol)
    on_top = (np.abs(a[:, 2]) < tol) & (np.abs(b[:, 2]) < tol)
    assert (on_y | on_z | on_top).all()
    # All four kinds of border are present, and the y and z borders are shared with wound
    # facets outside the zone (the mesh is conforming across the border).
    assert on_y.any() and on_z.any() and on_top.any()
    rest = mesh.facets[mesh.facet_tags == WOUND]
    rest_edges = {tuple(e) for e in np.sort(rest[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), 1)}
    assert {tuple(e) for e in border[on_y | on_z]} <= rest_edges


@pytest.mark.parametrize("m", [0.3, 1.0])
@pytest.mark.parametrize("shape", ["cylindrical", "wedge"])
def test_zone_border_is_made_of_mesh_edges(meshes, shape: str, m: float) -> None:
    border_check(meshes[shape, m], shape_spec(shape, m))


@pytest.mark.parametrize(
    ("base", "depth_fraction", "rel"),
    [
        # a wedge into the subcutis: the interface (z = -1) splits the zone; z_min = -1.26
        (GeometrySpec.wedge(1.0, 1.0, 3.0, 1.5, 1.8, 0.4, element_degree=1), 0.7, 1e-9),
        # a cylinder into the subcutis (interface z = -0.5, z_min = -0.554)
        (GeometrySpec.cylindrical(0.5, 1.0, 1.5, 1.5, 0.1, 0.3, element_degree=1), 0.9, 1e-2),
    ],
    ids=["wedge", "cylinder"],
)
def test_zone_below_the_layer_interface(
    base: GeometrySpec, depth_fraction: float, rel: float
) -> None:
    zone = {"y_fraction": 0.5, "depth_fraction": depth_fraction}
    spec = GeometrySpec(
        **base.to_dict() | {"zone_y_fraction": 0.5, "zone_depth_fraction": depth_fraction}
    )
    assert -depth_fraction * spec.wound_depth_mm < -spec.dermal_thickness_mm
    mesh = build_mesh(spec)
    border_check(mesh, spec)
    area = tri_areas(mesh.points, mesh.facets[mesh.facet_tags == WOUND_ZONE]).sum()
    assert area == pytest.approx(exact_zone_area(spec), rel=rel)
    assert mesh.info["closure_zone"] == zone


def test_whole_wound_as_zone_leaves_no_rest() -> None:
    # Fractions 1: nothing to imprint, the whole wound surface is the zone.
    spec = GeometrySpec(
        **GeometrySpec.cylindrical(1.0, 1.0, 2.0, 1.0, 0.2, 0.3).to_dict()
        | {"zone_y_fraction": 1.0, "zone_depth_fraction": 1.0}
    )
    mesh = build_mesh(spec)
    assert (mesh.facet_tags == WOUND).sum() == 0 and (mesh.facet_tags == WOUND_ZONE).sum() > 0


@pytest.mark.parametrize("bad", [0.0, 1.5, math.nan])
def test_zone_fraction_outside_zero_one_is_a_geometry_error(bad: float) -> None:
    with pytest.raises(GeometryError, match="zone_depth_fraction"):
        GeometrySpec(
            **GeometrySpec.wedge(1, 1, 2, 1, 0.5, 0.5).to_dict() | {"zone_depth_fraction": bad}
        )


def test_from_row_takes_the_sweeps_zone() -> None:
    from woundsweep.config.paper import ClosureZone

    row = {
        "wound_shape": "wedge", "dermal_thickness_mm": 1.0, "subcutis_thickness_mm": 1.0,
        "patch_half_length_mm": 2.0, "wound_width_mm": 1.0, "wound_depth_mm": 0.6,
        "wound_aspect_factor": math.nan, "mesh_size_factor": 0.3,
    }  # fmt: skip
    spec = GeometrySpec.from_row(row, ClosureZone(0.5, 0.25))
    assert (spec.zone_y_fraction, spec.zone_depth_fraction) == (0.5, 0.25)
    assert GeometrySpec.from_row(row) == GeometrySpec.wedge(1.0, 1.0, 2.0, 1.0, 0.6, 0.3)
    assert "zone=0.5,0.25" in spec.describe()
    p2 = GeometrySpec.from_row(row, None, 2)
    assert p2.element_degree == 2 and p2.describe().endswith(" P2")
    for bad in (0, 3, 1.5, True):
        with pytest.raises(GeometryError, match="element_degree"):
            GeometrySpec.from_row(row, None, bad)

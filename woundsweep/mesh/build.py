"""Tetrahedral mesh of a `GeometrySpec` with gmsh + numpy (no DOLFINx): ``build_mesh -> MeshData``.

gmsh meshes one quarter (x <= w/2, y >= 0; the layer interface is conforming through an OCC
fragment, and the closure zone's border lines are imprinted on the wound face, so the zone is a
union of whole facets, tagged WOUND_ZONE) under the size law of `woundsweep.mesh.sizing`, and the quarter is mirrored about
x = w/2 and y = 0 in numpy. The mesh is therefore exactly mirror-symmetric, which the closure
boundary condition at x = w/2 relies on, and it costs a quarter of a full build. Cell and
facet tags and the `MeshData` record are those of `woundsweep.core.schema`. The fusiform excision's quarter is built by
`woundsweep.mesh.fusiform`; its patch extends L beyond the wound along y too.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import gmsh
import numpy as np

from ..config.geometry import GeometrySpec, wound_distance_mm
from ..core.errors import GeometryError
from ..core.schema import (
    BOTTOM,
    DERMIS,
    SUBCUTIS,
    TOP,
    WOUND,
    WOUND_ZONE,
    X_MAX,
    X_MIN,
    Y_MAX,
    Y_MIN,
    MeshData,
)
from .fusiform import fusiform_quarter
from .sizing import (
    MESH_LAW_VERSION,
    SIZE_LAW,
    check_cell_cap,
    mesh_size_mm,
    size_scale,
    wound_size,
)

__all__ = ["MeshData", "build_mesh", "edge_length_near_mm", "signed_volumes"]


# gmsh keeps global state: one build at a time per process.
_GMSH_LOCK = threading.Lock()

_GMSH_OPTIONS = {
    "General.Terminal": 0,  # nothing on stdout: CLI output stays clean
    "General.Verbosity": 1,
    "General.NumThreads": 1,  # determinism: single-threaded meshing
    "Mesh.MaxNumThreads1D": 1,
    "Mesh.MaxNumThreads2D": 1,
    "Mesh.MaxNumThreads3D": 1,
    "Mesh.RandomSeed": 1,
    "Mesh.Algorithm": 6,  # Frontal-Delaunay surfaces
    "Mesh.Algorithm3D": 1,  # Delaunay volumes (HXT would be multi-threaded)
    "Mesh.ElementOrder": 1,
    "Mesh.Optimize": 1,
    "Mesh.OptimizeNetgen": 1,  # lifts the worst cells well above Delaunay's slivers
    # The size callback alone decides the sizes.
    "Mesh.MeshSizeExtendFromBoundary": 0,
    "Mesh.MeshSizeFromPoints": 0,
    "Mesh.MeshSizeFromCurvature": 0,
}


@contextmanager
def _gmsh_model(name: str) -> Iterator[None]:
    """A fresh gmsh model; initialises/finalises gmsh unless the caller already did."""
    with _GMSH_LOCK:
        owner = not gmsh.isInitialized()
        if owner:
            gmsh.initialize(readConfigFiles=False, interruptible=False)
        try:
            for key, value in _GMSH_OPTIONS.items():
                gmsh.option.setNumber(key, value)
            gmsh.model.add(name)
            try:
                yield
            finally:
                gmsh.model.remove()
        finally:
            if owner:
                gmsh.finalize()


def _quarter_geometry(spec: GeometrySpec) -> None:
    """OCC model of the quarter x <= w/2, y >= 0 with two conforming layer volumes."""
    if spec.shape == "fusiform":
        fusiform_quarter(spec)
        return
    occ = gmsh.model.occ
    t_d, T, L = spec.dermal_thickness_mm, spec.total_thickness_mm, spec.patch_half_length_mm
    w, d = spec.wound_width_mm, spec.wound_depth_mm
    xc = w / 2
    dermis = occ.addBox(-L, 0.0, -t_d, L + xc, L, t_d)
    subcutis = occ.addBox(-L, 0.0, -T, L + xc, L, T - t_d)
    # The tool overshoots the box in y and above the surface so that no tool face is
    # coplanar with a box face (the cut stays transversal).
    over = 0.1 * L
    if spec.shape == "cylindrical":
        # Disk in the xz-plane whose parametrisation seam points up (+z), i.e. above the
        # skin, never on the wound surface.
        R = spec.wound_radius_mm
        disk = occ.addDisk(xc, -over, spec.wound_axis_z_mm, R, R, zAxis=[0, 1, 0], xAxis=[0, 0, 1])
        section = (2, disk)
    else:
        rise = 0.25 * T  # flanks continued above the surface
        spread = rise * xc / d
        pts = [
            occ.addPoint(-spread, -over, rise),
            occ.addPoint(w + spread, -over, rise),
            occ.addPoint(xc, -over, -d),
        ]
        lines = [occ.addLine(pts[i], pts[(i + 1) % 3]) for i in range(3)]
        section = (2, occ.addPlaneSurface([occ.addCurveLoop(lines)]))
    extruded = occ.extrude([section], 0.0, L + 2 * over, 0.0)
    tool = [dt for dt in extruded if dt[0] == 3]
    cut, _ = occ.cut([(3, dermis), (3, subcutis)], tool)
    if len(cut) != 2:
        raise GeometryError(f"the wound cut gave {len(cut)} volumes instead of 2")
    # One fragment makes the layer interface conforming and imprints the zone's border.
    occ.fragment(cut[:1], cut[1:] + _zone_border(spec))
    occ.synchronize()


def zone_limits(spec: GeometrySpec) -> tuple[float, float]:
    """The closure zone's bounds: |y| <= y_max (mm) and z >= z_min (mm)."""
    return (
        spec.zone_y_fraction * spec.wound_half_length_mm,
        -spec.zone_depth_fraction * spec.wound_depth_mm,
    )


def _flank_x(spec: GeometrySpec, z: float) -> float:
    """x of the quarter's (left) flank at depth z."""
    xc = spec.wound_width_mm / 2
    if spec.shape == "cylindrical":
        R, zc = spec.wound_radius_mm, spec.wound_axis_z_mm
        return xc - math.sqrt(max(R * R - (z - zc) ** 2, 0.0))
    return xc * (-z / spec.wound_depth_mm)  # from (0, 0) down to the apex (xc, -d)


def _zone_border(spec: GeometrySpec) -> list[tuple[int, int]]:
    """Curves of the zone's border on the quarter's wound face: the section at y = y_max from
    the surface down to z_min, and the line z = z_min from y = 0 to y_max (each omitted where
    it falls on an edge the face already has: the y = L face, the apex, the layer interface)."""
    occ = gmsh.model.occ
    L, T, t_d = spec.patch_half_length_mm, spec.total_thickness_mm, spec.dermal_thickness_mm
    y_max, z_min = zone_limits(spec)
    x_min = _flank_x(spec, z_min)
    tol = 1e-9 * max(L, T)
    curves = []
    if y_max < L - tol:
        # The section y = y_max, split where it crosses the layer interface.
        levels = [0.0] + ([-t_d] if z_min < -t_d - tol else []) + [z_min]
        pts = [occ.addPoint(_flank_x(spec, z), y_max, z) for z in levels]
        if spec.shape == "cylindrical":
            axis = occ.addPoint(spec.wound_width_mm / 2, y_max, spec.wound_axis_z_mm)
            curves += [occ.addCircleArc(a, axis, b) for a, b in zip(pts, pts[1:])]
        else:
            curves += [occ.addLine(a, b) for a, b in zip(pts, pts[1:])]
    if spec.zone_depth_fraction < 1 and abs(z_min + t_d) > tol:
        a = occ.addPoint(x_min, 0.0, z_min)
        b = occ.addPoint(x_min, y_max, z_min)
        curves.append(occ.addLine(a, b))
    return [(1, c) for c in curves]


def _classify(spec: GeometrySpec) -> tuple[dict[int, int], dict[int, int], dict[int, tuple]]:
    """Volume tag -> cell tag; surface tag -> facet tag (exterior only); planes to snap."""
    t_d, T, L = spec.dermal_thickness_mm, spec.total_thickness_mm, spec.patch_half_length_mm
    xc = spec.wound_width_mm / 2
    tol = 1e-7 * max(L, T)
    vols: dict[int, int] = {}
    for _, tag in gmsh.model.getEntities(3):
        # OCC bounding boxes are padded by the boolean tolerances: use centres of mass.
        z_com = gmsh.model.occ.getCenterOfMass(3, tag)[2]
        vols[tag] = DERMIS if z_com > -t_d else SUBCUTIS
    if sorted(vols.values()) != [DERMIS, SUBCUTIS]:
        raise GeometryError(f"expected one dermis and one subcutis volume, got {vols}")
    # (axis, value) -> facet tag; None marks interior planes (symmetry, layer interface).
    planes = {
        (0, -L): X_MIN,
        (0, xc): None,
        (1, 0.0): None,
        (1, spec.patch_half_length_y_mm): Y_MAX,
        (2, 0.0): TOP,
        (2, -T): BOTTOM,
        (2, -t_d): None,
    }
    surfaces: dict[int, int] = {}
    snap: dict[int, tuple[int, float]] = {}
    for _, tag in gmsh.model.getEntities(2):
        hit = None
        if gmsh.model.getType(2, tag) == "Plane":
            lo, hi = gmsh.model.getParametrizationBounds(2, tag)
            normal = np.abs(gmsh.model.getNormal(tag, [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2]))
            axis = int(np.argmax(normal))
            com = gmsh.model.occ.getCenterOfMass(2, tag)
            if normal[axis] > 1 - 1e-9:
                hit = next(
                    (key for key in planes if key[0] == axis and abs(com[axis] - key[1]) < tol),
                    None,
                )
        if hit is not None:
            snap[tag] = hit
            if planes[hit] is not None:
                surfaces[tag] = planes[hit]  # type: ignore[assignment]  # not None: tested above
        else:
            surfaces[tag] = WOUND  # the only curved or slanted faces
    return vols, surfaces, snap


# gmsh element type, nodes per element, error message (``{}``: the types gmsh produced).
_TETRAHEDRA = (4, 4, "gmsh produced element types {}, not tetrahedra")
_TRIANGLES = (2, 3, "gmsh produced surface element types {}")


def _elements(
    dim: int, entities: Mapping[int, int], index: np.ndarray, kind: tuple[int, int, str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Connectivity (node indices), tags and gmsh element tags of the entities' elements."""
    gmsh_type, width, error = kind
    conns, tags, element_tags = [], [], []
    for entity, tag in sorted(entities.items()):
        types, elements, nodes = gmsh.model.mesh.getElements(dim, entity)
        if list(types) != [gmsh_type]:
            raise GeometryError(error.format(list(types)))
        conn = index[np.asarray(nodes[0], dtype=np.int64).reshape(-1, width)]
        conns.append(conn)
        tags.append(np.full(len(conn), tag, dtype=np.int32))
        element_tags.append(elements[0])
    return np.concatenate(conns), np.concatenate(tags), np.concatenate(element_tags)


def _extract(
    spec: GeometrySpec,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Arrays of the meshed quarter, node coordinates on planes snapped exactly."""
    vols, surfaces, snap = _classify(spec)
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    index = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    index[node_tags] = np.arange(len(node_tags))
    # Snap nodes of planar faces onto their plane (gmsh maps them through OCC's
    # parametrisation, which can be one ulp off): mirroring and face location need exact values.
    for tag, (axis, value) in snap.items():
        on, _, _ = gmsh.model.mesh.getNodes(2, tag, includeBoundary=True)
        coords[index[on], axis] = value
    cells, cell_tags, element_tags = _elements(3, vols, index, _TETRAHEDRA)
    facets, facet_tags, _ = _elements(2, surfaces, index, _TRIANGLES)
    facet_tags = _tag_zone(spec, coords, facets, facet_tags)
    quality = gmsh.model.mesh.getElementQualities(element_tags, "minSICN")
    return coords, cells, cell_tags, facets, facet_tags, float(np.min(quality))


def _tag_zone(
    spec: GeometrySpec, coords: np.ndarray, facets: np.ndarray, facet_tags: np.ndarray
) -> np.ndarray:
    """Retag the quarter's wound facets inside the closure zone WOUND_ZONE.

    The zone's border is imprinted, so no facet straddles it: a facet with a vertex beyond
    the border by more than rounding and another inside is a GeometryError."""
    y_max, z_min = zone_limits(spec)
    tol = 1e-9 * max(spec.patch_half_length_mm, spec.total_thickness_mm)
    p = coords[facets]
    inside = (p[..., 1] <= y_max + tol) & (p[..., 2] >= z_min - tol)
    outside = (p[..., 1] >= y_max - tol) | (p[..., 2] <= z_min + tol)
    wound = facet_tags == WOUND
    zone = wound & inside.all(axis=1)
    if (wound & ~zone & ~outside.all(axis=1)).any():
        raise GeometryError("a wound facet straddles the closure zone's border")
    tags = facet_tags.copy()
    tags[zone] = WOUND_ZONE
    return tags


def _mirror(
    points: np.ndarray,
    cells: np.ndarray,
    cell_tags: np.ndarray,
    facets: np.ndarray,
    facet_tags: np.ndarray,
    axis: int,
    plane: float,
    swap: Mapping[int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Append the mirror image about ``coordinate[axis] = plane``; nodes on it are shared."""
    on = points[:, axis] == plane
    off = np.flatnonzero(~on)
    image = np.arange(len(points), dtype=np.int64)
    image[off] = len(points) + np.arange(len(off))
    mirrored = points[off].copy()
    mirrored[:, axis] = 2 * plane - mirrored[:, axis]
    # Swapping two vertices restores the orientation a reflection reverses.
    new_cells = image[cells][:, [1, 0, 2, 3]]
    new_facets = image[facets][:, [1, 0, 2]]
    new_ftags = facet_tags.copy()
    for old, new in swap.items():
        new_ftags[facet_tags == old] = new
    return (
        np.vstack([points, mirrored]),
        np.vstack([cells, new_cells]),
        np.concatenate([cell_tags, cell_tags]),
        np.vstack([facets, new_facets]),
        np.concatenate([facet_tags, new_ftags]),
    )


def signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The signed volume of each tetrahedron (negative where its vertices are left-handed)."""
    p = points[cells]
    return (
        np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
        / 6.0
    )


def edge_length_near_mm(mesh: MeshData, spec: GeometrySpec, within_mm: float = 1.0) -> float:
    """The median over the cells whose centroid lies within ``within_mm`` of the wound's
    surface of their mean edge length (mm): the element size where the wound's loads act.
    (gmsh keeps a mesh finer than its size field where the layers are thinner than it, so
    the realised size is measured, not read from the law.)"""
    X = np.asarray(mesh.points)
    corners = np.asarray(mesh.cells)[:, :4]
    centroid = X[corners].mean(axis=1)
    if spec.shape == "fusiform":
        distance = spec.lens().distance
        dist = np.array([distance(*c) for c in centroid])
    else:
        dist = np.array([wound_distance_mm(spec, c[0], c[2]) for c in centroid])
    near = dist < within_mm
    if not near.any():
        raise GeometryError(f"{spec.describe()}: no cell within {within_mm:g} mm of the wound")
    pairs = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
    p = X[corners[near]]
    edges = np.mean([np.linalg.norm(p[:, i] - p[:, j], axis=1) for i, j in pairs], axis=0)
    return float(np.median(edges))


def build_mesh(spec: GeometrySpec) -> MeshData:
    """Mesh ``spec`` with gmsh (deterministic: same spec, bit-identical arrays).

    Raises GeometryError when the geometry cannot be built or meshed.
    """
    check_cell_cap(spec)  # before gmsh: a patch too large for any mesh is refused at once
    start = time.perf_counter()
    try:
        with _gmsh_model("woundsweep"):
            _quarter_geometry(spec)
            gmsh.model.mesh.setSizeCallback(
                lambda dim, tag, x, y, z, lc: mesh_size_mm(spec, x, y, z)
            )
            gmsh.model.mesh.generate(3)
            gmsh.model.mesh.removeSizeCallback()
            points, cells, cell_tags, facets, facet_tags, min_q = _extract(spec)
    except GeometryError as err:
        raise GeometryError(f"{spec.describe()}: {err}") from None
    except Exception as err:  # gmsh raises bare Exceptions with its last error message
        msg = " ".join(str(err).split()) or type(err).__name__
        raise GeometryError(f"{spec.describe()}: gmsh failed: {msg}") from None
    points, cells, cell_tags, facets, facet_tags = _mirror(
        points, cells, cell_tags, facets, facet_tags, 0, spec.wound_width_mm / 2, {X_MIN: X_MAX}
    )
    points, cells, cell_tags, facets, facet_tags = _mirror(
        points, cells, cell_tags, facets, facet_tags, 1, 0.0, {Y_MAX: Y_MIN}
    )
    # Keep only nodes used by cells (all of them in practice), in their existing order.
    used = np.unique(cells)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    points, cells, facets = points[used], renumber[cells], renumber[facets]
    if (facets < 0).any():
        raise GeometryError(f"{spec.describe()}: a boundary facet uses a node of no cell")
    vol = signed_volumes(points, cells)
    flip = vol < 0
    cells[flip] = cells[flip][:, [1, 0, 2, 3]]
    vol = np.abs(vol)
    if vol.min() <= 1e-9 * vol.mean() or min_q <= 0:
        raise GeometryError(
            f"{spec.describe()}: degenerate or inverted cell (min SICN {min_q:.3g})"
        )
    s = size_scale(spec.mesh_size_factor, spec.element_degree)
    info = {
        "cells": int(len(cells)),
        "vertices": int(len(points)),
        "facets": int(len(facets)),
        "min_quality": min_q,
        "quality_measure": "minSICN",
        "build_time_s": time.perf_counter() - start,
        "mesh_law_version": MESH_LAW_VERSION,
        "size_scale": s,
        "wound_size_mm": s * wound_size(spec),
        "dermis_size_mm": s * SIZE_LAW["layer_per_dermis"] * spec.dermal_thickness_mm,
        "size_law": dict(SIZE_LAW),
        "closure_zone": {
            "y_fraction": spec.zone_y_fraction,
            "depth_fraction": spec.zone_depth_fraction,
        },
        "element_degree": spec.element_degree,
        "gmsh_version": gmsh.__version__,
    }
    return MeshData(
        points,
        cells.astype(np.int64),
        cell_tags.astype(np.int32),
        facets.astype(np.int64),
        facet_tags.astype(np.int32),
        info,
    )

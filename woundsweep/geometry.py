"""Two-layer skin patch with a wound along y, meshed with gmsh (gmsh + numpy, no DOLFINx).

Coordinates in mm, z up, skin surface at z = 0 (docs/design.md): the patch is
x in [-L, L + w], y in [-L, L], z in [-T, 0]; the dermis (epidermis + dermis) is
z in [-t_d, 0] and the subcutis lies below it. The wound runs the whole y-length, centred on
x = w/2:

- cylindrical: a cylinder along y with its axis at (x = w/2, z = a w) and radius
  R = sqrt((w/2)^2 + (a w)^2), so the opening at the surface is w and the depth is R - a w;
- wedge: an isosceles triangular prism, width w at the surface, apex at z = -d.

Meshing: gmsh meshes one quarter (x <= w/2, y >= 0; the layer interface is conforming
through an OCC fragment) and the quarter is mirrored about x = w/2 and y = 0 in numpy. The
mesh is therefore exactly mirror-symmetric, which the closure boundary condition at
x = w/2 relies on, and it costs a quarter of a full build.

Mesh size law (version ``MESH_LAW_VERSION``), with D the distance (mm) from the wound
surface, zeta = max(0, -z - t_d) / t_d the depth below the layer interface in dermal
thicknesses, m the mesh size factor and s = (0.5 / m)^(2/3)::

    h = s * min(h_w + 0.5 D,  (0.7 t_d + 0.1 D) (1 + 0.75 zeta),  L / 4),
    h_w = min(t_d / 3, w / 6)

All lengths scale with the geometry, so the cell count depends (up to OCC's absolute
tolerances) only on the dimensionless factors; every term scales with s, so a larger factor
gives a uniformly finer field. Fine at the wound (h_w resolves both the dermis and the wound
width), graded away from it, finer in the dermis than in the subcutis, coarser with depth,
and never coarser than s L / 4 (eight cells along the wound length at m = 0.5). Measured on the 1,296 paper geometries
(benchmarks/bench_geometry.py --all): min / median / max cells 2.6k / 4.5k / 8.4k at
m = 0.3, 4.6k / 7.4k / 15.1k at m = 0.5, 6.8k / 11.6k / 24.6k at m = 0.7; the count rises
strictly with m for every geometry. Minimum SICN is 0.053 over the grid; the few meshes below
0.1 are cylinders whose bottom is tangent to (or within 2% of) the layer interface, where the
dermis between wound and subcutis thins to a cusp.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from types import MappingProxyType
from typing import Any, NamedTuple

import gmsh
import numpy as np

from .errors import GeometryError

__all__ = [
    "BOTTOM",
    "CELL_TAGS",
    "DERMIS",
    "FACET_TAGS",
    "MESH_LAW_VERSION",
    "PAPER_CELL_CAP",
    "SHAPES",
    "SIZE_LAW",
    "SUBCUTIS",
    "TAGS",
    "TOP",
    "WOUND",
    "X_MAX",
    "X_MIN",
    "Y_MAX",
    "Y_MIN",
    "GeometrySpec",
    "MeshData",
    "build_mesh",
    "mesh_size_mm",
    "wound_distance_mm",
]

# Tag integers are part of the contract (docs/design.md).
DERMIS, SUBCUTIS = 1, 2
X_MIN, X_MAX, Y_MIN, Y_MAX, BOTTOM, TOP, WOUND = 11, 12, 13, 14, 15, 16, 17
CELL_TAGS: Mapping[str, int] = MappingProxyType({"dermis": DERMIS, "subcutis": SUBCUTIS})
FACET_TAGS: Mapping[str, int] = MappingProxyType(
    {
        "x_min": X_MIN,
        "x_max": X_MAX,
        "y_min": Y_MIN,
        "y_max": Y_MAX,
        "bottom": BOTTOM,
        "top": TOP,
        "wound": WOUND,
    }
)
TAGS: Mapping[str, int] = MappingProxyType({**CELL_TAGS, **FACET_TAGS})

SHAPES = ("cylindrical", "wedge")
# Bumped whenever the geometry or the size law changes: cached meshes of another version
# are rebuilt.
MESH_LAW_VERSION = 1
# The paper omitted models above 40,000 cells; the size law keeps every paper geometry below.
PAPER_CELL_CAP = 40_000

# Constants of the size law in the module docstring.
SIZE_LAW: Mapping[str, float] = MappingProxyType(
    {
        "reference_factor": 0.5,  # m at which s = 1
        "factor_exponent": 2.0 / 3.0,  # s = (0.5 / m) ** exponent
        "wound_per_dermis": 1.0 / 3.0,  # h_w <= t_d / 3
        "wound_per_width": 1.0 / 6.0,  # h_w <= w / 6
        "wound_growth": 0.5,  # dh/dD near the wound
        "layer_per_dermis": 0.7,  # dermis size away from the wound, in t_d
        "layer_growth": 0.1,  # slow lateral coarsening far from the wound
        "depth_growth": 0.75,  # relative growth per t_d below the interface
        "patch_fraction": 0.25,  # h <= L / 4
    }
)


@dataclass(frozen=True)
class GeometrySpec:
    """Geometric parameters of one mesh (mm); validated on construction.

    ``wound_aspect_factor`` is the cylinder's a (None for a wedge); for a cylinder
    ``wound_depth_mm`` must equal R - a w. ``mesh_size_factor`` in (0, 1]: larger is finer.
    """

    shape: str
    dermal_thickness_mm: float
    subcutis_thickness_mm: float
    patch_half_length_mm: float
    wound_width_mm: float
    wound_depth_mm: float
    wound_aspect_factor: float | None
    mesh_size_factor: float

    def __post_init__(self) -> None:
        _validate(self)

    @classmethod
    def cylindrical(
        cls,
        dermal_thickness_mm: float,
        subcutis_thickness_mm: float,
        patch_half_length_mm: float,
        wound_width_mm: float,
        wound_aspect_factor: float,
        mesh_size_factor: float,
    ) -> GeometrySpec:
        """A cylindrical wound; the depth follows from the width and the aspect factor."""
        w, a = float(wound_width_mm), float(wound_aspect_factor)
        depth = math.hypot(w / 2, a * w) - a * w
        return cls(
            "cylindrical",
            dermal_thickness_mm,
            subcutis_thickness_mm,
            patch_half_length_mm,
            w,
            depth,
            a,
            mesh_size_factor,
        )

    @classmethod
    def wedge(
        cls,
        dermal_thickness_mm: float,
        subcutis_thickness_mm: float,
        patch_half_length_mm: float,
        wound_width_mm: float,
        wound_depth_mm: float,
        mesh_size_factor: float,
    ) -> GeometrySpec:
        """A wedge wound of the given width at the surface and apex depth."""
        return cls(
            "wedge",
            dermal_thickness_mm,
            subcutis_thickness_mm,
            patch_half_length_mm,
            wound_width_mm,
            wound_depth_mm,
            None,
            mesh_size_factor,
        )

    @classmethod
    def from_row(cls, row: Mapping[str, Any] | Any) -> GeometrySpec:
        """Build from a manifest row (pandas Series or dict with the manifest columns).

        Errors name the job (``job_index``) when the row has one.
        """
        get = row.get
        shape = get("wound_shape", get("shape"))
        aspect = get("wound_aspect_factor")
        try:
            aspect = None if aspect is None or math.isnan(float(aspect)) else float(aspect)
            if shape == "wedge":
                aspect = None  # the manifest leaves the other shape's factor NaN
            return cls(
                str(shape),
                _num(get("dermal_thickness_mm")),
                _num(get("subcutis_thickness_mm")),
                _num(get("patch_half_length_mm")),
                _num(get("wound_width_mm")),
                _num(get("wound_depth_mm")),
                aspect,
                _num(get("mesh_size_factor")),
            )
        except (GeometryError, TypeError, ValueError) as err:
            job = get("job_index")
            where = f"job {int(job)}: " if job is not None else ""
            raise GeometryError(where + str(err)) from None

    @property
    def total_thickness_mm(self) -> float:
        return self.dermal_thickness_mm + self.subcutis_thickness_mm

    @property
    def wound_radius_mm(self) -> float:
        """Cylinder radius (NaN for a wedge)."""
        if self.wound_aspect_factor is None:
            return math.nan
        w, a = self.wound_width_mm, self.wound_aspect_factor
        return math.hypot(w / 2, a * w)

    @property
    def wound_axis_z_mm(self) -> float:
        """Height of the cylinder axis above the surface (NaN for a wedge)."""
        if self.wound_aspect_factor is None:
            return math.nan
        return self.wound_aspect_factor * self.wound_width_mm

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def describe(self) -> str:
        """One-line summary for messages."""
        a = self.wound_aspect_factor
        aspect = f" a={a:g}" if a is not None else ""
        return (
            f"{self.shape} t_d={self.dermal_thickness_mm:g} t_s={self.subcutis_thickness_mm:g} "
            f"L={self.patch_half_length_mm:g} w={self.wound_width_mm:g} "
            f"d={self.wound_depth_mm:.4g}{aspect} m={self.mesh_size_factor:g}"
        )


class MeshData(NamedTuple):
    """A first-order tetrahedral mesh: arrays in mm, tags as in ``CELL_TAGS``/``FACET_TAGS``."""

    points: np.ndarray  # (n, 3) float64, every node used by a cell, no duplicates
    cells: np.ndarray  # (m, 4) int64, positively oriented
    cell_tags: np.ndarray  # (m,) int32
    facets: np.ndarray  # (k, 3) int64, each exterior triangle once
    facet_tags: np.ndarray  # (k,) int32
    info: dict[str, Any]


def _num(value: Any) -> float:
    if value is None:
        raise ValueError("missing a geometric column")
    return float(value)


def _validate(spec: GeometrySpec) -> None:
    """Raise GeometryError with a one-line reason naming the offending parameter."""
    if spec.shape not in SHAPES:
        raise GeometryError(f"shape={spec.shape!r} is not one of {', '.join(SHAPES)}")
    for name in (
        "dermal_thickness_mm",
        "subcutis_thickness_mm",
        "patch_half_length_mm",
        "wound_width_mm",
        "wound_depth_mm",
    ):
        v = getattr(spec, name)
        if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise GeometryError(f"{name}={v!r} must be a positive length in mm")
    m = spec.mesh_size_factor
    if not isinstance(m, (int, float)) or not math.isfinite(m) or not 0 < m <= 1:
        raise GeometryError(f"mesh_size_factor={m!r} must be in (0, 1] (larger is finer)")
    w, L, T = spec.wound_width_mm, spec.patch_half_length_mm, spec.total_thickness_mm
    if w > 2 * L:
        raise GeometryError(
            f"wound_width_mm={w:g} is wider than the patch (2 * patch_half_length_mm = {2 * L:g})"
        )
    if spec.shape == "cylindrical":
        a = spec.wound_aspect_factor
        if a is None or not math.isfinite(a) or a < 0:
            raise GeometryError(f"wound_aspect_factor={a!r} must be >= 0 for a cylindrical wound")
        expected = math.hypot(w / 2, a * w) - a * w
        if abs(spec.wound_depth_mm - expected) > 1e-6 * w:
            raise GeometryError(
                f"wound_depth_mm={spec.wound_depth_mm:g} does not match the cylinder "
                f"(sqrt((w/2)^2 + (a w)^2) - a w = {expected:g})"
            )
    elif spec.wound_aspect_factor is not None:
        raise GeometryError("wound_aspect_factor must be None for a wedge wound")
    if spec.wound_depth_mm >= T:
        raise GeometryError(
            f"wound_depth_mm={spec.wound_depth_mm:g} reaches the bottom of the patch "
            f"(total thickness {T:g} mm)"
        )


# ---------------------------------------------------------------------------- size law


def wound_distance_mm(spec: GeometrySpec, x: float, z: float) -> float:
    """Distance from (x, z) to the wound surface (the wound is uniform in y); 0 inside it."""
    xc = spec.wound_width_mm / 2
    if spec.shape == "cylindrical":
        return max(math.hypot(x - xc, z - spec.wound_axis_z_mm) - spec.wound_radius_mm, 0.0)
    # Nearest of the two flanks, segments from the surface edges to the apex (xc, -d).
    d = spec.wound_depth_mm
    best = math.inf
    for x0 in (0.0, spec.wound_width_mm):
        vx, vz = xc - x0, -d
        t = min(1.0, max(0.0, ((x - x0) * vx + z * vz) / (vx * vx + vz * vz)))
        best = min(best, math.hypot(x - x0 - t * vx, z - t * vz))
    return best


def _size_scale(mesh_size_factor: float) -> float:
    return (SIZE_LAW["reference_factor"] / mesh_size_factor) ** SIZE_LAW["factor_exponent"]


def _wound_size(spec: GeometrySpec) -> float:
    return min(
        SIZE_LAW["wound_per_dermis"] * spec.dermal_thickness_mm,
        SIZE_LAW["wound_per_width"] * spec.wound_width_mm,
    )


def mesh_size_mm(spec: GeometrySpec, x: float, y: float, z: float) -> float:
    """Target edge length (mm) at a point: the size law of the module docstring."""
    del y  # the wound and the layers are uniform along y
    t_d = spec.dermal_thickness_mm
    dist = wound_distance_mm(spec, x, z)
    zeta = max(0.0, -z - t_d) / t_d
    near = _wound_size(spec) + SIZE_LAW["wound_growth"] * dist
    layer = (SIZE_LAW["layer_per_dermis"] * t_d + SIZE_LAW["layer_growth"] * dist) * (
        1.0 + SIZE_LAW["depth_growth"] * zeta
    )
    cap = SIZE_LAW["patch_fraction"] * spec.patch_half_length_mm
    return _size_scale(spec.mesh_size_factor) * min(near, layer, cap)


# ---------------------------------------------------------------------------- gmsh

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
    occ.fragment(cut[:1], cut[1:])
    occ.synchronize()


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
        (1, L): Y_MAX,
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
                surfaces[tag] = planes[hit]
        else:
            surfaces[tag] = WOUND  # the only curved or slanted faces
    return vols, surfaces, snap


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
    cells, cell_tags, element_tags = [], [], []
    for vol, ctag in sorted(vols.items()):
        types, tags, nodes = gmsh.model.mesh.getElements(3, vol)
        if list(types) != [4]:
            raise GeometryError(f"gmsh produced element types {list(types)}, not tetrahedra")
        conn = index[np.asarray(nodes[0], dtype=np.int64).reshape(-1, 4)]
        cells.append(conn)
        cell_tags.append(np.full(len(conn), ctag, dtype=np.int32))
        element_tags.append(tags[0])
    facets, facet_tags = [], []
    for surf, ftag in sorted(surfaces.items()):
        types, _, nodes = gmsh.model.mesh.getElements(2, surf)
        if list(types) != [2]:
            raise GeometryError(f"gmsh produced surface element types {list(types)}")
        conn = index[np.asarray(nodes[0], dtype=np.int64).reshape(-1, 3)]
        facets.append(conn)
        facet_tags.append(np.full(len(conn), ftag, dtype=np.int32))
    quality = gmsh.model.mesh.getElementQualities(np.concatenate(element_tags), "minSICN")
    return (
        coords,
        np.concatenate(cells),
        np.concatenate(cell_tags),
        np.concatenate(facets),
        np.concatenate(facet_tags),
        float(np.min(quality)),
    )


# ---------------------------------------------------------------------------- numpy


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


def _signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    p = points[cells]
    return (
        np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
        / 6.0
    )


def build_mesh(spec: GeometrySpec) -> MeshData:
    """Mesh ``spec`` with gmsh (deterministic: same spec, bit-identical arrays).

    Raises GeometryError when the geometry cannot be built or meshed.
    """
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
    vol = _signed_volumes(points, cells)
    flip = vol < 0
    cells[flip] = cells[flip][:, [1, 0, 2, 3]]
    vol = np.abs(vol)
    if vol.min() <= 1e-9 * vol.mean() or min_q <= 0:
        raise GeometryError(
            f"{spec.describe()}: degenerate or inverted cell (min SICN {min_q:.3g})"
        )
    s = _size_scale(spec.mesh_size_factor)
    info = {
        "cells": int(len(cells)),
        "vertices": int(len(points)),
        "facets": int(len(facets)),
        "min_quality": min_q,
        "quality_measure": "minSICN",
        "build_time_s": time.perf_counter() - start,
        "mesh_law_version": MESH_LAW_VERSION,
        "size_scale": s,
        "wound_size_mm": s * _wound_size(spec),
        "dermis_size_mm": s * SIZE_LAW["layer_per_dermis"] * spec.dermal_thickness_mm,
        "size_law": dict(SIZE_LAW),
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

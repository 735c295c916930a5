"""The mesh size law (version ``MESH_LAW_VERSION``): target edge length at a point (pure Python).

With D the distance (mm) from the wound surface (for the fusiform excision `Lens.distance`:
in plan to its outline, combined with the height below its floor), D_f the distance from a
trench's floor line (a wedge's apex, a cylinder's deepest line; x = w / 2, z = -d), zeta =
max(0, -z - t_d) / t_d the depth below the layer interface in dermal thicknesses, m the mesh
size factor, s = (0.5 / m)^(1/3) and p the element degree::

    h = p * s * min(h_w + 0.5 D,  (0.7 t_d + 0.1 D) (1 + 0.75 zeta),  L / 4,  h_w / 2 + D_f),
    h_w = min(t_d / 3, w / 6)

The floor line is where the open wound's stress concentrates (a wedge's apex is a re-entrant
edge, a cylinder's floor the notch root), so it gets half the wound's spacing; the excision
has no such term. The exponent 1/3 keeps the paper's coarsest factor (0.3) at 1.19 times the
reference spacing. Both were chosen by p99's mesh convergence on the benchmark geometries of
`benchmarks/convergence.py` at P2 (docs/validation.md, "Mesh convergence").

The law sets the spacing of the displacement's nodes: a P2 element's edge holds a node at
its midpoint, so P2 edges are twice as long as P1's for the same spacing, and a mesh size
factor means the same resolution, and about the same number of nodes away from the
geometry's fixed edges, for either element. (P2 on the P1 edge lengths has about 6.5 times
the dofs and costs 10 to 30 times as much, for stresses within a few per cent of these;
docs/model.md, "Element".)

All lengths scale with the geometry, so the cell count depends (up to OCC's absolute
tolerances) only on the dimensionless factors; every term scales with s, so a larger factor
gives a uniformly finer field. Fine at the wound (h_w resolves both the dermis and the wound
width), graded away from it, finer in the dermis than in the subcutis, coarser with depth,
and never coarser than s L / 4 (eight cells along the wound length at m = 0.5). On 60 of
the 432 paper geometries drawn at random (`random.seed(20261204)`; P1, default closure zone):
min / median / max cells 4.3k / 6.7k / 11.9k at m = 0.3, 5.3k / 8.8k / 16.2k at m = 0.5,
6.7k / 10.9k / 20.3k at m = 0.7; the count rises strictly with m for each of them, and the
minimum SICN is 0.10. The worst shapes are where a cylinder's bottom is tangent to (or
within 2% of) the layer interface: the dermis between wound and subcutis thins to a cusp.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType

from ..config.geometry import GeometrySpec, wound_distance_mm
from ..core.errors import GeometryError
from ..core.versions import MESH_LAW_VERSION

__all__ = [
    "MESH_LAW_VERSION",
    "MAX_CELLS",
    "PAPER_CELL_CAP",
    "SIZE_LAW",
    "check_cell_cap",
    "estimate_cells",
    "mesh_size_mm",
    "size_scale",
    "wound_size",
]

# The paper omitted models above 40,000 (P1) cells; the size law keeps every paper geometry
# below, and a P2 mesh of the same geometry has fewer cells for about as many nodes.
PAPER_CELL_CAP = 40_000
# No mesh is built whose size law predicts more cells than this (`estimate_cells`): gmsh would
# run for hours and out of memory. Every paper geometry stays below 25k cells, and the finest
# convergence level (factor 2) of any of them below 1M.
MAX_CELLS = 2_000_000
# Midpoint grid over the (x, z) cross-section for the size-law integral: 8 x 8 ranks the paper
# geometries by real gmsh cell count with Spearman ~0.94 (finer grids do no better).
_GRID = 8

# Constants of the size law in the module docstring.
SIZE_LAW: Mapping[str, float] = MappingProxyType(
    {
        "reference_factor": 0.5,  # m at which s = 1
        "factor_exponent": 1.0 / 3.0,  # s = (0.5 / m) ** exponent
        "wound_per_dermis": 1.0 / 3.0,  # h_w <= t_d / 3
        "wound_per_width": 1.0 / 6.0,  # h_w <= w / 6
        "wound_growth": 0.5,  # dh/dD near the wound
        "layer_per_dermis": 0.7,  # dermis size away from the wound, in t_d
        "layer_growth": 0.1,  # slow lateral coarsening far from the wound
        "depth_growth": 0.75,  # relative growth per t_d below the interface
        "patch_fraction": 0.25,  # h <= L / 4
        "floor_per_wound": 0.5,  # at the floor line (x = w / 2, z = -d), in h_w
        "floor_growth": 1.0,  # dh/dD_f away from it
    }
)


def size_scale(mesh_size_factor: float, element_degree: int) -> float:
    """``p * s`` of the size law: the factor that scales every length of the size field."""
    factor = (SIZE_LAW["reference_factor"] / mesh_size_factor) ** SIZE_LAW["factor_exponent"]
    return element_degree * factor


def wound_size(spec: GeometrySpec) -> float:
    """``h_w`` of the size law (mm): the edge length at the wound before `size_scale`."""
    return min(
        SIZE_LAW["wound_per_dermis"] * spec.dermal_thickness_mm,
        SIZE_LAW["wound_per_width"] * spec.wound_width_mm,
    )


def mesh_size_mm(spec: GeometrySpec, x: float, y: float, z: float) -> float:
    """Target edge length (mm) at a point: the size law of the module docstring."""
    t_d = spec.dermal_thickness_mm
    if spec.shape == "fusiform":
        dist = spec.lens().distance(x, y, z)
    else:  # the trenches and the layers are uniform along y
        dist = wound_distance_mm(spec, x, z)
    zeta = max(0.0, -z - t_d) / t_d
    near = wound_size(spec) + SIZE_LAW["wound_growth"] * dist
    layer = (SIZE_LAW["layer_per_dermis"] * t_d + SIZE_LAW["layer_growth"] * dist) * (
        1.0 + SIZE_LAW["depth_growth"] * zeta
    )
    cap = SIZE_LAW["patch_fraction"] * spec.patch_half_length_mm
    h = min(near, layer, cap)
    if spec.shape != "fusiform":
        floor = math.hypot(x - spec.wound_width_mm / 2, z + spec.wound_depth_mm)
        h = min(
            h, SIZE_LAW["floor_per_wound"] * wound_size(spec) + SIZE_LAW["floor_growth"] * floor
        )
    return size_scale(spec.mesh_size_factor, spec.element_degree) * h


def estimate_cells(spec: GeometrySpec) -> float:
    """The size law's cell count: 1 / V_tet(h) integrated over the patch (``_GRID`` squared
    samples of the cross-section, times the patch length); it ranks jobs and bounds meshes."""
    L, w, T = spec.patch_half_length_mm, spec.wound_width_mm, spec.total_thickness_mm
    dx, dz = (2 * L + w) / _GRID, T / _GRID
    total = 0.0
    for i in range(_GRID):
        x = -L + (i + 0.5) * dx
        for k in range(_GRID):
            h = mesh_size_mm(spec, x, 0.0, -T + (k + 0.5) * dz)
            total += 6.0 * math.sqrt(2.0) / h**3  # cells per mm^3: regular tetrahedra of edge h
    return total * dx * dz * 2 * spec.patch_half_length_y_mm  # the excision's patch: 2L + l


def check_cell_cap(spec: GeometrySpec) -> None:
    """GeometryError when the size law predicts more than `MAX_CELLS` cells for ``spec``."""
    cells = estimate_cells(spec)
    if not cells <= MAX_CELLS:
        raise GeometryError(
            f"{spec.describe()}: the size law predicts {cells:.3g} cells, above the cap of "
            f"{MAX_CELLS:,} (a smaller patch_size_factor or mesh_size_factor keeps it below)"
        )

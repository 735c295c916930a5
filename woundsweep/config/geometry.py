"""Geometric parameters of a two-layer skin patch with a wound along y (pure Python).

Coordinates in mm, z up, skin surface at z = 0 (docs/design.md): the patch is
x in [-L, L + w], y in [-L, L], z in [-T, 0]; the dermis (epidermis + dermis) is
z in [-t_d, 0] and the subcutis lies below it. The wound runs the whole y-length, centred on
x = w/2:

- cylindrical: a cylinder along y with its axis at (x = w/2, z = a w) and radius
  R = sqrt((w/2)^2 + (a w)^2), so the opening at the surface is w and the depth is R - a w;
- wedge: an isosceles triangular prism, width w at the surface, apex at z = -d;
- fusiform: the elliptical excision (`woundsweep.config.fusiform`): a lens of length l along y
  and width w, depth d, centred on (w/2, 0) in a patch that extends L beyond it on every side
  (x in [-L, L + w], y in [-(L + l/2), L + l/2]).

The closure zone (where primary intention acts, the sweep's ``stages.closure_zone``) is part
of the geometry: the wound surface within |y| <= zone_y_fraction * (the wound's half-length:
L for the trenches, l/2 for the excision) and
z >= -zone_depth_fraction * d is meshed as its own faces (`woundsweep.mesh.build`).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from ..core.errors import GeometryError
from ..core.versions import MESH_LAW_VERSION
from .fusiform import FLOOR_RISE, Lens, lens
from .paper import ClosureZone
from .solver import DEGREES, SolverSettings

__all__ = [
    "FINEST_FACTOR",
    "LENGTH_RANGE_MM",
    "MAX_SCALE_RATIO",
    "SHAPES",
    "GeometrySpec",
    "wound_distance_mm",
]

SHAPES = ("cylindrical", "wedge", "fusiform")
# The finest mesh size factor a mesh can have. A sweep's grid takes factors in (0, 1];
# `woundsweep converge` refines past it to extrapolate, and a case's mesh check needs up to
# about 4 to halve the realised element size at a clinical wound (`MAX_CELLS` bounds the
# meshes either way).
FINEST_FACTOR = 8.0
# Every length of a geometry (mm), and how far apart its largest and smallest may be: the
# shipped sweeps span 0.08-36 mm and ratios up to about 25, a clinical case about 500.
LENGTH_RANGE_MM = (0.01, 1000.0)
MAX_SCALE_RATIO = 2000.0


@dataclass(frozen=True)
class GeometrySpec:
    """Geometric parameters of one mesh (mm); validated on construction.

    ``wound_aspect_factor`` is the cylinder's a (None for a wedge); for a cylinder
    ``wound_depth_mm`` must equal R - a w. ``mesh_size_factor`` in (0, FINEST_FACTOR]: larger
    is finer (a sweep's grid stays in (0, 1]).
    ``zone_y_fraction`` and ``zone_depth_fraction`` in (0, 1] bound the closure zone
    (|y| <= zone_y_fraction * L, z >= -zone_depth_fraction * d). ``element_degree`` is the
    displacement element's (`woundsweep.config.solver.DEGREES`): the size law sets the node
    spacing, and an element's edges span ``element_degree`` spacings (`mesh.sizing`).
    ``wound_length_mm`` is the excision's length l (fusiform only, None for the trenches).
    """

    shape: str
    dermal_thickness_mm: float
    subcutis_thickness_mm: float
    patch_half_length_mm: float
    wound_width_mm: float
    wound_depth_mm: float
    wound_aspect_factor: float | None
    mesh_size_factor: float
    zone_y_fraction: float = ClosureZone.y_fraction
    zone_depth_fraction: float = ClosureZone.depth_fraction
    element_degree: int = SolverSettings.element_degree
    wound_length_mm: float | None = None

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
        **settings: Any,
    ) -> GeometrySpec:
        """A cylindrical wound; the depth follows from the width and the aspect factor;
        ``settings``: the zone fractions and the element degree."""
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
            **settings,
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
        **settings: Any,
    ) -> GeometrySpec:
        """A wedge wound of the given width at the surface and apex depth; ``settings``: the
        zone fractions and the element degree."""
        return cls(
            "wedge",
            dermal_thickness_mm,
            subcutis_thickness_mm,
            patch_half_length_mm,
            wound_width_mm,
            wound_depth_mm,
            None,
            mesh_size_factor,
            **settings,
        )

    @classmethod
    def fusiform(
        cls,
        dermal_thickness_mm: float,
        subcutis_thickness_mm: float,
        patch_half_length_mm: float,
        wound_width_mm: float,
        wound_length_mm: float,
        wound_depth_mm: float,
        mesh_size_factor: float,
        **settings: Any,
    ) -> GeometrySpec:
        """A fusiform excision of the given width, length and depth; ``settings``: the zone
        fractions and the element degree."""
        return cls(
            "fusiform",
            dermal_thickness_mm,
            subcutis_thickness_mm,
            patch_half_length_mm,
            wound_width_mm,
            wound_depth_mm,
            None,
            mesh_size_factor,
            wound_length_mm=wound_length_mm,
            **settings,
        )

    @classmethod
    def from_row(
        cls,
        row: Mapping[str, Any] | Any,
        zone: ClosureZone | None = None,
        element_degree: int = SolverSettings.element_degree,
    ) -> GeometrySpec:
        """Build from a manifest row (pandas Series or dict with the manifest columns).

        ``zone`` (the sweep's `ClosureZone`) sets the closure zone (its depth resolved for
        this wound); None keeps the defaults. ``element_degree`` is
        the sweep's ``solver.element_degree``. Errors name the job (``job_index``) when the
        row has one.
        """
        get = row.get
        shape = get("wound_shape", get("shape"))
        aspect, length = get("wound_aspect_factor"), get("wound_length_mm")
        try:
            aspect = None if aspect is None or math.isnan(float(aspect)) else float(aspect)
            length = None if length is None or math.isnan(float(length)) else float(length)
            if shape != "cylindrical":
                aspect = None  # the manifest leaves the other shapes' factors NaN
            if shape != "fusiform":
                length = None
            return cls(
                str(shape),
                _num(get("dermal_thickness_mm")),
                _num(get("subcutis_thickness_mm")),
                _num(get("patch_half_length_mm")),
                _num(get("wound_width_mm")),
                _num(get("wound_depth_mm")),
                aspect,
                _num(get("mesh_size_factor")),
                float(ClosureZone.y_fraction if zone is None else zone.y_fraction),
                float(
                    ClosureZone.depth_fraction
                    if zone is None
                    else zone.depth_fraction_for(
                        _num(get("wound_width_mm")), _num(get("wound_depth_mm"))
                    )
                ),
                element_degree,
                length,
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

    @property
    def wound_half_length_mm(self) -> float:
        """Half the wound's length along y: l/2 for the excision, L for the trenches (which
        run the whole patch); the closure zone's ``zone_y_fraction`` is a fraction of it."""
        if self.wound_length_mm is None:
            return self.patch_half_length_mm
        return self.wound_length_mm / 2

    @property
    def patch_half_length_y_mm(self) -> float:
        """The patch's half-length along y: L beyond the wound's ends (L for the trenches)."""
        if self.wound_length_mm is None:
            return self.patch_half_length_mm
        return self.patch_half_length_mm + self.wound_length_mm / 2

    def lens(self) -> Lens:
        """The excision's outline and floor (fusiform only)."""
        if self.wound_length_mm is None:
            raise GeometryError(f"a {self.shape} wound has no lens outline")
        w = self.wound_width_mm
        return lens(self.wound_length_mm, w, self.wound_depth_mm, w / 2)

    def to_dict(self) -> dict[str, Any]:
        """The parameters; ``wound_length_mm`` only for the excision (so the trenches' cache
        keys are those of the shapes without it)."""
        d = asdict(self)
        if d["wound_length_mm"] is None:
            del d["wound_length_mm"]
        return d

    @property
    def mesh_id(self) -> str:
        """16 hex digits of the sha256 of everything that determines the mesh: these
        parameters (mesh size factor, closure zone and element degree included) and
        `MESH_LAW_VERSION`. It names the cached mesh files (`woundsweep.mesh.cache`)."""
        params = {
            k: float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v
            for k, v in self.to_dict().items()
        }
        blob = json.dumps(
            {"spec": params, "mesh_law": MESH_LAW_VERSION}, sort_keys=True, separators=(",", ":")
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def describe(self) -> str:
        """One-line summary for messages."""
        a = self.wound_aspect_factor
        aspect = f" a={a:g}" if a is not None else ""
        if self.wound_length_mm is not None:
            aspect = f" l={self.wound_length_mm:g}"
        zone = (self.zone_y_fraction, self.zone_depth_fraction)
        default = (ClosureZone.y_fraction, ClosureZone.depth_fraction)
        zone_text = "" if zone == default else f" zone={zone[0]:.4g},{zone[1]:.4g}"
        return (
            f"{self.shape} t_d={self.dermal_thickness_mm:g} t_s={self.subcutis_thickness_mm:g} "
            f"L={self.patch_half_length_mm:g} w={self.wound_width_mm:g} "
            f"d={self.wound_depth_mm:.4g}{aspect} m={self.mesh_size_factor:g}{zone_text}"
            f"{'' if self.element_degree == 1 else f' P{self.element_degree}'}"
        )


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
    _check_scale(spec)
    m = spec.mesh_size_factor
    if not isinstance(m, (int, float)) or not math.isfinite(m) or not 0 < m <= FINEST_FACTOR:
        raise GeometryError(
            f"mesh_size_factor={m!r} must be in (0, {FINEST_FACTOR:g}] (larger is finer)"
        )
    if spec.element_degree not in DEGREES or isinstance(spec.element_degree, bool):
        raise GeometryError(f"element_degree={spec.element_degree!r} must be one of {DEGREES}")
    for name in ("zone_y_fraction", "zone_depth_fraction"):
        v = getattr(spec, name)
        if not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 < v <= 1:
            raise GeometryError(f"{name}={v!r} must be a fraction in (0, 1]")
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
        raise GeometryError(f"wound_aspect_factor must be None for a {spec.shape} wound")
    if spec.shape == "fusiform":
        _validate_fusiform(spec)
    elif spec.wound_length_mm is not None:
        raise GeometryError(f"wound_length_mm must be None for a {spec.shape} wound")
    if spec.wound_depth_mm >= T:
        raise GeometryError(
            f"wound_depth_mm={spec.wound_depth_mm:g} reaches the bottom of the patch "
            f"(total thickness {T:g} mm)"
        )


_LENGTHS = (
    "dermal_thickness_mm", "subcutis_thickness_mm", "patch_half_length_mm", "wound_width_mm",
    "wound_depth_mm", "wound_length_mm",
)  # fmt: skip


def _check_scale(spec: GeometrySpec) -> None:
    """Every length within `LENGTH_RANGE_MM`, and the largest at most `MAX_SCALE_RATIO` times
    the smallest: gmsh does not finish a patch of kilometres or a wound a millionth of its
    patch (the size law's cell count alone does not see either)."""
    lo, hi = LENGTH_RANGE_MM
    lengths = {
        name: float(getattr(spec, name)) for name in _LENGTHS if getattr(spec, name) is not None
    }
    for name, v in lengths.items():
        if not lo <= v <= hi:
            raise GeometryError(f"{name}={v:g} must be within {lo:g}-{hi:g} mm")
    small = min(lengths, key=lengths.__getitem__)
    large = max(lengths, key=lengths.__getitem__)
    if lengths[large] > MAX_SCALE_RATIO * lengths[small]:
        raise GeometryError(
            f"{large}={lengths[large]:g} is more than {MAX_SCALE_RATIO:g} times "
            f"{small}={lengths[small]:g}: too far apart in scale to mesh"
        )


def _validate_fusiform(spec: GeometrySpec) -> None:
    length, w = spec.wound_length_mm, spec.wound_width_mm
    if not isinstance(length, (int, float)) or not math.isfinite(length) or length <= w:
        raise GeometryError(
            f"wound_length_mm={length!r} must be longer than the width ({w:g} mm) for a fusiform wound"
        )
    top = 1 - FLOOR_RISE
    if spec.zone_depth_fraction >= top:
        raise GeometryError(
            f"zone_depth_fraction={spec.zone_depth_fraction:g} must be below {top:g} for a "
            "fusiform wound (the closure zone ends on the walls, above the floor)"
        )


def wound_distance_mm(spec: GeometrySpec, x: float, z: float) -> float:
    """Distance from (x, z) to a trench's surface (uniform in y); 0 inside it. The
    excision's distance is `Lens.distance`."""
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

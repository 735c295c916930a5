"""One clinical case for `woundsweep case` (pure Python): the excision, the skin, the sutures,
the load after closure and the numerical settings, each default written once here.

- The excision: length and width (mm) of the ellipse, its long axis at ``angle_deg`` to the
  Langer line (0 along, 90 across; the model's ``orientation_deg`` is 90 - angle,
  docs/model.md "Angle to the Langer line"); depth through the dermis into the subcutis, by
  default the dermis plus a quarter of the subcutis (`DEPTH_INTO_SUBCUTIS`).
- The patch: a margin of `MARGIN_PER_LENGTH` wound lengths on every side (the stage-2 closing
  force changes by about 3 % from 2.7 l to 5.3 l, docs/validation.md "The fusiform excision").
- The closure zone (the walls the sutures hold): the whole length, down to the bite depth.
- The solver's element (`SolverSettings.element_degree`, P2: docs/model.md "Element", P1's
  closing force keeps falling with refinement) at mesh size factor `MESH_SIZE_FACTOR`; the
  mesh check re-solves on a mesh of at least `MESH_CHECK_FACTOR` times the factor (element
  sizes scale with (0.5 / m)^(1/3), `woundsweep.mesh.sizing`: 8 times the factor halves the
  size field), raised until the realised element size at the wound is halved (gmsh keeps
  the case's coarse meshes finer than their field; `woundsweep.studies.case`).
- The site: its layer thicknesses and the band of skin parameters the forces are given
  within (`SITES`); the skin type chosen is the band's central value.
- The load after closure: by default across the wound (`ITCH_TO_WOUND_deg`), whatever the
  wound's angle to the Langer line; `SCAN_TO_WOUND_deg` the directions of the scan.
- "Open": a surface gap above `OPEN_GAP_mm`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..core.errors import GeometryError
from .fusiform import FLOOR_RISE
from .geometry import FINEST_FACTOR, LENGTH_RANGE_MM, GeometrySpec
from .solver import DEGREES, SolverSettings
from .sutures import BODY_SITES, CaseError, ItchLoad, SuturePlan

__all__ = [
    "DEPTH_INTO_SUBCUTIS",
    "ITCH_TO_WOUND_deg",
    "MARGIN_PER_LENGTH",
    "MESH_CHECK_FACTOR",
    "MESH_SIZE_FACTOR",
    "OPEN_GAP_mm",
    "SCAN_TO_WOUND_deg",
    "SITES",
    "ClinicalCase",
    "Site",
    "line_angle",
]

DEPTH_INTO_SUBCUTIS = 0.25
MARGIN_PER_LENGTH = 2.7
# The element size 1.41 of the reference away from a trench's floor ((0.5 / 0.18)^(1/3)).
MESH_SIZE_FACTOR = 0.18
MESH_CHECK_FACTOR = 8.0
ELEMENT_DEGREE = SolverSettings.element_degree
SKIN_TYPES = ("normal", "stiff", "soft")
# The wound is open where the surface gap is wider than the epidermis is thick (cellular
# epidermis and stratum corneum 0.08 mm at the shoulder, 0.1 mm at the buttock:
# Sandby-Moller et al., Acta Derm. Venereol. 2003;83:410): the edges no longer meet.
OPEN_GAP_mm = 0.1
ITCH_TO_WOUND_deg = 90.0
SCAN_TO_WOUND_deg = (0.0, 45.0, 90.0, 135.0)


@dataclass(frozen=True)
class Site:
    """A body site's preset: layer thicknesses (`BODY_SITES`) with their source, and the band
    of skin parameters (Table 2's skin types, ``low`` to ``high``) with the reason for it."""

    thickness_source: str
    band: tuple[str, str]
    band_source: str


_TABLE2_BAND = (
    "Table 2's soft, normal and stiff skin (Flynn et al.'s facial skin); no Fung parameters "
    "of this site's dermis are known to the model, so its forces are given between the soft "
    "and the stiff skin"
)
SITES: dict[str, Site] = {
    "upper-back": Site(
        "representative values: truncal dermis is among the thickest (Olsen et al., Skin Res. "
        "Technol. 1995;1:74, 20 MHz ultrasound of 22 sites); subcutis of the interscapular "
        "region of lean adults of order 5 mm",
        ("soft", "stiff"),
        _TABLE2_BAND,
    ),
    "forearm": Site(
        "representative values: extremity skin thinner than truncal skin (Olsen et al. 1995)",
        ("soft", "stiff"),
        _TABLE2_BAND,
    ),
}


def line_angle(deg: float) -> float:
    """An angle between two lines reduced to (-90, 90] (a line at d is the line at d + 180)."""
    r = float(deg) % 180.0
    return r - 180.0 if r > 90.0 else r


# The closure zone may reach at most this fraction of the wound's depth (the walls are at
# least 1 - FLOOR_RISE of it high).
_ZONE_MAX = 0.95 * (1 - FLOOR_RISE)


@dataclass(frozen=True)
class ClinicalCase:
    """A fusiform excision closed by sutures (module docstring); lengths in mm, angles in
    degrees. ``dermal_thickness_mm`` / ``subcutis_thickness_mm`` None: the body site's."""

    length_mm: float = 20.0
    width_mm: float | None = None  # None: a third of the length
    angle_deg: float = 0.0
    site: str = "upper-back"
    dermal_thickness_mm: float | None = None
    subcutis_thickness_mm: float | None = None
    depth_mm: float | None = None
    skin_type: str = "normal"
    sutures: SuturePlan = field(default_factory=SuturePlan)
    itch: ItchLoad = field(default_factory=ItchLoad)
    mesh_size_factor: float = MESH_SIZE_FACTOR
    element_degree: int = ELEMENT_DEGREE
    # The load's direction as an angle to the wound's long axis (90: across the wound); None:
    # ``itch.angle_to_langer_deg`` instead.
    itch_to_wound_deg: float | None = ITCH_TO_WOUND_deg

    def __post_init__(self) -> None:
        for name in (
            "length_mm",
            "width_mm",
            "dermal_thickness_mm",
            "subcutis_thickness_mm",
            "depth_mm",
        ):
            v = getattr(self, name)
            if v is None and name != "length_mm":
                continue
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float))
                or not math.isfinite(v)
                or v <= 0
            ):
                raise CaseError(f"{name}={v!r} must be a positive length in mm")
            if not LENGTH_RANGE_MM[0] <= v <= LENGTH_RANGE_MM[1]:
                raise CaseError(
                    f"{name}={v:g} must be within {LENGTH_RANGE_MM[0]:g}-{LENGTH_RANGE_MM[1]:g} mm"
                )
        if self.width >= self.length_mm:
            raise CaseError(
                f"width_mm={self.width:g} must be below the length ({self.length_mm:g} mm)"
            )
        a = self.angle_deg
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 <= a <= 90:
            raise CaseError(f"angle_deg={a!r} must be in [0, 90] degrees to the Langer line")
        t = self.itch_to_wound_deg
        if t is not None and (
            isinstance(t, bool) or not isinstance(t, (int, float)) or not -180 <= t <= 180
        ):
            raise CaseError(f"itch_to_wound_deg={t!r} must be in [-180, 180] degrees")
        if self.site not in BODY_SITES:
            raise CaseError(f"site={self.site!r} must be one of {', '.join(BODY_SITES)}")
        if self.skin_type not in SKIN_TYPES:
            raise CaseError(f"skin_type={self.skin_type!r} must be one of {', '.join(SKIN_TYPES)}")
        m = self.mesh_size_factor
        if isinstance(m, bool) or not isinstance(m, (int, float)) or not 0 < m <= FINEST_FACTOR:
            raise CaseError(f"mesh_size_factor={m!r} must be in (0, {FINEST_FACTOR:g}]")
        if self.element_degree not in DEGREES or isinstance(self.element_degree, bool):
            raise CaseError(f"element_degree={self.element_degree!r} must be one of {DEGREES}")
        if self.depth <= self.dermis:
            raise CaseError(
                f"depth_mm={self.depth:g} must reach below the dermis ({self.dermis:g} mm)"
            )
        if self.depth >= self.dermis + self.subcutis:
            raise CaseError(
                f"depth_mm={self.depth:g} must stay above the patch's bottom "
                f"({self.dermis + self.subcutis:g} mm)"
            )
        bite = self.sutures.depth(self.dermis)
        if bite / self.depth > _ZONE_MAX:
            raise CaseError(
                f"bite_depth_mm={bite:g} must stay on the walls, above "
                f"{_ZONE_MAX * self.depth:.3g} mm for a {self.depth:g} mm deep excision"
            )
        self.sutures.positions(self.length_mm)  # raises if none fits (or too many would)
        self.geometry()  # the excision's bounds (scale, sizes), before anything is meshed

    @property
    def width(self) -> float:
        return self.width_mm if self.width_mm is not None else self.length_mm / 3

    @property
    def dermis(self) -> float:
        t = self.dermal_thickness_mm
        return t if t is not None else BODY_SITES[self.site].dermal_thickness_mm

    @property
    def subcutis(self) -> float:
        t = self.subcutis_thickness_mm
        return t if t is not None else BODY_SITES[self.site].subcutis_thickness_mm

    @property
    def depth(self) -> float:
        d = self.depth_mm
        return d if d is not None else self.dermis + DEPTH_INTO_SUBCUTIS * self.subcutis

    @property
    def load(self) -> ItchLoad:
        """The load after closure, its direction as an angle to the Langer line."""
        return self.load_at(self.itch_to_wound_deg)

    def load_at(self, to_wound_deg: float | None) -> ItchLoad:
        """The case's load along ``to_wound_deg`` to the wound's long axis (None: the given
        angle to the Langer line). The wound lies at +angle_deg to the Langer line, so a
        direction at t to it lies at angle_deg + t to the line (modulo 180: a stretch or a
        shear along n is the one along -n)."""
        it = self.itch
        if to_wound_deg is None:
            return it
        return ItchLoad(it.strain, line_angle(self.angle_deg + to_wound_deg), it.kind)

    def to_wound_deg(self, load: ItchLoad) -> float:
        """The angle in [0, 180) from the wound's long axis to ``load``'s direction, turning
        the way the wound turns from the Langer line (45 and 135 are the two diagonals)."""
        return (float(load.angle_to_langer_deg) - float(self.angle_deg)) % 180.0

    @property
    def band(self) -> tuple[str, str]:
        """The site's band of skin types (its ends; the case's skin type is its centre)."""
        return SITES[self.site].band

    @property
    def orientation_deg(self) -> float:
        """The model's angle of the stiff axis to x (90 - the angle to the Langer line)."""
        return 90.0 - float(self.angle_deg)

    @property
    def zone_depth_fraction(self) -> float:
        return self.sutures.depth(self.dermis) / self.depth

    def geometry(self, mesh_size_factor: float | None = None) -> GeometrySpec:
        """The excision's `GeometrySpec` (CaseError if it cannot be meshed)."""
        m = self.mesh_size_factor if mesh_size_factor is None else mesh_size_factor
        try:
            return GeometrySpec.fusiform(
                self.dermis,
                self.subcutis,
                MARGIN_PER_LENGTH * self.length_mm,
                self.width,
                self.length_mm,
                self.depth,
                m,
                zone_y_fraction=1.0,
                zone_depth_fraction=self.zone_depth_fraction,
                element_degree=self.element_degree,
            )
        except GeometryError as err:
            raise CaseError(str(err)) from None

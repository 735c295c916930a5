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
  closing force keeps falling with refinement) at mesh size factor `MESH_SIZE_FACTOR`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..core.errors import GeometryError
from .fusiform import FLOOR_RISE
from .geometry import FINEST_FACTOR, LENGTH_RANGE_MM, GeometrySpec
from .solver import DEGREES, SolverSettings
from .sutures import BODY_SITES, CaseError, ItchLoad, SuturePlan

__all__ = ["DEPTH_INTO_SUBCUTIS", "MARGIN_PER_LENGTH", "MESH_SIZE_FACTOR", "ClinicalCase"]

DEPTH_INTO_SUBCUTIS = 0.25
MARGIN_PER_LENGTH = 2.7
# The element size 1.41 of the reference away from a trench's floor ((0.5 / 0.18)^(1/3)).
MESH_SIZE_FACTOR = 0.18
ELEMENT_DEGREE = SolverSettings.element_degree
SKIN_TYPES = ("normal", "stiff", "soft")
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

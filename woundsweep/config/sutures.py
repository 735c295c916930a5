"""A clinical case's settings: the suture plan, the load after closure and body-site presets
(pure Python; docs/model.md, "Sutures" and "The load after closure").

Defaults from surgical practice, with their sources:

- Simple interrupted sutures through the full thickness of the dermis (Medscape, "Wound
  Closure Technique", simple interrupted suture: "traversing the epidermis and the full
  thickness of the dermis"): the bite depth defaults to the dermal thickness.
- Bites a few millimetres from the edge, sutures spaced about as far apart as the bite width
  (`shared/notes/clinical.md`, standard texts; 3-5 mm from the edge, about 4-5 mm apart in
  the skin-closure guides, e.g. vetsurgeryonline.com "Simple interrupted pattern"): bite width
  3 mm, spacing equal to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.errors import WoundsweepError
from .geometry import LENGTH_RANGE_MM

__all__ = ["BODY_SITES", "MAX_SUTURES", "BodySite", "CaseError", "ItchLoad", "SuturePlan"]

BITE_WIDTH_mm = 3.0
# At most this many sutures (one every 0.5 mm on a 10 cm wound); each is a footprint to tie.
MAX_SUTURES = 200


class CaseError(WoundsweepError):
    """A clinical case's input that cannot be solved (exit 2)."""


def _positive(name: str, value: float | None, allow_none: bool = False) -> None:
    """A positive length in mm, within `LENGTH_RANGE_MM` (CaseError otherwise)."""
    if value is None and allow_none:
        return
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or value <= 0
    ):
        raise CaseError(f"{name}={value!r} must be a positive number")
    lo, hi = LENGTH_RANGE_MM
    if not lo <= value <= hi:
        raise CaseError(f"{name}={value:g} must be within {lo:g}-{hi:g} mm")


@dataclass(frozen=True)
class SuturePlan:
    """Interrupted sutures across a wound of length l along y, centred on y = 0.

    ``count`` sutures evenly spaced, or ``spacing_mm`` apart (centred; the default spacing is
    the bite width), or at explicit ``positions_mm`` (y of each suture). ``bite_width_mm``:
    distance of each bite from the wound's edge at the surface; ``bite_depth_mm``: how deep
    the bite reaches (None: the dermal thickness).
    """

    count: int | None = None
    spacing_mm: float | None = None
    bite_width_mm: float = BITE_WIDTH_mm
    bite_depth_mm: float | None = None
    positions_mm: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        given = [x is not None for x in (self.count, self.spacing_mm, self.positions_mm)]
        if sum(given) > 1:
            raise CaseError("give the sutures' count, their spacing or their positions, not two")
        if self.count is not None and (
            isinstance(self.count, bool) or not isinstance(self.count, int) or self.count < 1
        ):
            raise CaseError(f"suture count={self.count!r} must be a whole number >= 1")
        if self.count is not None and self.count > MAX_SUTURES:
            raise CaseError(f"suture count={self.count} must be at most {MAX_SUTURES}")
        _positive("suture spacing_mm", self.spacing_mm, allow_none=True)
        _positive("bite_width_mm", self.bite_width_mm)
        _positive("bite_depth_mm", self.bite_depth_mm, allow_none=True)

    def positions(self, length_mm: float) -> tuple[float, ...]:
        """y (mm) of each suture on a wound of length ``length_mm`` (CaseError if one falls
        outside the wound or none fits)."""
        a = length_mm / 2
        if self.positions_mm is not None:
            ys = tuple(float(y) for y in self.positions_mm)
        else:
            if self.count is not None:
                n = self.count
                step = length_mm / (n + 1)
            else:
                step = self.spacing_mm if self.spacing_mm is not None else self.bite_width_mm
                if not length_mm / step <= MAX_SUTURES + 1:  # counted before any is placed
                    raise CaseError(
                        f"suture spacing {step:g} mm puts more than {MAX_SUTURES} sutures on "
                        f"a {length_mm:g} mm wound"
                    )
                n = int(math.ceil(length_mm / step - 1e-9)) - 1
                if n < 1:
                    raise CaseError(
                        f"suture spacing {step:g} mm leaves no suture on a {length_mm:g} mm wound"
                    )
            ys = tuple((i - (n - 1) / 2) * step for i in range(n))
        if not ys or any(not math.isfinite(y) or abs(y) >= a for y in ys):
            raise CaseError(f"every suture must lie within the wound (|y| < {a:g} mm)")
        return ys

    def depth(self, dermal_thickness_mm: float) -> float:
        """The bite depth (mm)."""
        return self.bite_depth_mm if self.bite_depth_mm is not None else dermal_thickness_mm


ITCH_KINDS = ("stretch", "shear")


@dataclass(frozen=True)
class ItchLoad:
    """The load after closure ("when my patient itches"): an extra in-plane stretch (strain
    ``strain`` along the direction at ``angle_to_langer_deg`` to the Langer line) or shear
    (engineering shear ``strain`` between that direction and its normal) of the patch's
    boundary, from the closed state."""

    strain: float = 0.10
    angle_to_langer_deg: float = 90.0  # across the Langer line
    kind: str = "stretch"

    def __post_init__(self) -> None:
        s = self.strain
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not 0 <= s <= 0.5:
            raise CaseError(f"itch strain={s!r} must be in [0, 0.5]")
        a = self.angle_to_langer_deg
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not -180 <= a <= 180:
            raise CaseError(f"itch angle={a!r} must be in [-180, 180] degrees")
        if self.kind not in ITCH_KINDS:
            raise CaseError(f"itch kind={self.kind!r} must be one of {', '.join(ITCH_KINDS)}")

    def gradient(self, orientation_deg: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """The in-plane displacement gradient E (2 x 2, model axes) of the load for a job at
        ``orientation_deg`` (the Langer line at that angle to x)."""
        phi = math.radians(orientation_deg + self.angle_to_langer_deg)
        n = (math.cos(phi), math.sin(phi))
        m = (-n[1], n[0])
        e = self.strain
        if self.kind == "stretch":
            return ((e * n[0] * n[0], e * n[0] * n[1]), (e * n[1] * n[0], e * n[1] * n[1]))
        h = e / 2
        return (
            (h * 2 * n[0] * m[0], h * (n[0] * m[1] + m[0] * n[1])),
            (h * (n[1] * m[0] + m[1] * n[0]), h * 2 * n[1] * m[1]),
        )


@dataclass(frozen=True)
class BodySite:
    """A body site's layer thicknesses (mm) and where they come from."""

    dermal_thickness_mm: float
    subcutis_thickness_mm: float
    source: str


BODY_SITES: dict[str, BodySite] = {
    "upper-back": BodySite(
        2.5,
        5.0,
        "representative values: truncal dermis is among the thickest (Olsen et al., Skin Res. "
        "Technol. 1995;1:74, 20 MHz ultrasound of 22 sites; shared/notes/clinical.md: a few "
        "mm on the back); subcutis of the interscapular region of lean adults of order 5 mm",
    ),
    "forearm": BodySite(
        1.2,
        4.0,
        "representative values: extremity skin thinner than truncal skin (Olsen et al. 1995)",
    ),
}

"""The model's settings as typed records, with the paper's values as their defaults: the
materials of Table 2 (from Flynn et al., Tables 2-3) and the stage settings of its Methods.

A sweep's ``materials`` and ``stages`` sections map onto `Materials` and `StageSettings`
(units in the field names; ``tsf`` is a stretch, dimensionless). `to_dict` gives the
sections' plain form, as a sweep file writes them; a result's fingerprint hashes it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

__all__ = [
    "CLOSURE_LOADS",
    "ClosureZone",
    "FungParameters",
    "Materials",
    "MooneyRivlinParameters",
    "StageSettings",
]


@dataclasses.dataclass(frozen=True)
class MooneyRivlinParameters:
    """The subcutis (Table 2): W = C10 (I1~ - 3) + C20 (I1~ - 3)^2 + K/2 (ln J)^2."""

    C10_kPa: float
    C20_kPa: float
    K_kPa: float

    @classmethod
    def table2(cls) -> MooneyRivlinParameters:
        """Table 2: C10 = 0.4, C20 = 1.4, K = 50 kPa."""
        return cls(0.4, 1.4, 50.0)


@dataclasses.dataclass(frozen=True)
class FungParameters:
    """One skin type's orthotropic Fung dermis (Table 2): c, mu_1..3, lambda_11, every other
    lambda_ab, the bulk modulus K, and the tension scaling factor (pre-stretch) tsf."""

    c_kPa: float
    mu_kPa: tuple[float, float, float]
    lambda11_kPa: float
    lambda_other_kPa: float
    K_kPa: float
    tsf: float

    @classmethod
    def normal(cls) -> FungParameters:
        """Table 2, normal skin."""
        return cls(21.3, (17.8, 5.9, 5.9), 1.0, 1.0, 250.0, 1.10)

    @classmethod
    def stiff(cls) -> FungParameters:
        """Table 2, stiff skin."""
        return cls(42.6, (35.6, 11.8, 11.8), 11.8, 2.0, 250.0, 1.05)

    @classmethod
    def soft(cls) -> FungParameters:
        """Table 2, soft skin."""
        return cls(10.7, (8.9, 3.0, 3.0), 0.5, 0.5, 250.0, 1.15)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["mu_kPa"] = list(self.mu_kPa)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FungParameters:
        return cls(
            float(d["c_kPa"]),
            tuple(float(m) for m in d["mu_kPa"]),  # type: ignore[arg-type]
            float(d["lambda11_kPa"]),
            float(d["lambda_other_kPa"]),
            float(d["K_kPa"]),
            float(d["tsf"]),
        )


@dataclasses.dataclass(frozen=True)
class Materials:
    """The sweep's ``materials``: the subcutis and the skin types by name."""

    subcutis: MooneyRivlinParameters
    skin_types: Mapping[str, FungParameters]

    @classmethod
    def table2(cls) -> Materials:
        """The paper's Table 2: one subcutis, the normal, stiff and soft skin types."""
        skins = {name: getattr(FungParameters, name)() for name in ("normal", "stiff", "soft")}
        return cls(MooneyRivlinParameters.table2(), MappingProxyType(skins))

    def to_dict(self) -> dict[str, Any]:
        return {
            "subcutis": dataclasses.asdict(self.subcutis),
            "skin_types": {name: p.to_dict() for name, p in self.skin_types.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Materials:
        sub = {k: float(v) for k, v in d["subcutis"].items()}
        skins = {str(n): FungParameters.from_dict(p) for n, p in d["skin_types"].items()}
        return cls(MooneyRivlinParameters(**sub), MappingProxyType(skins))


@dataclasses.dataclass(frozen=True)
class ClosureZone:
    """Where primary intention acts: the middle ``y_fraction`` of the wound length (|y - y_c| <=
    y_fraction * L_y, L_y the patch half-length) and the upper ``depth_fraction`` of its depth.
    ``depth_per_w``, when set, gives the depth as a multiple of the wound width w instead (the
    published code's zone reaches 0.7 w / 2 below the surface), capped at the wound's depth.
    """

    y_fraction: float = 1.0 / 3.0
    depth_fraction: float = 0.5
    depth_per_w: float | None = None

    def depth_fraction_for(self, width_mm: float, depth_mm: float) -> float:
        """The zone's depth as a fraction of a wound's depth."""
        if self.depth_per_w is None:
            return self.depth_fraction
        return min(1.0, self.depth_per_w * width_mm / depth_mm)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"y_fraction": self.y_fraction, "depth_fraction": self.depth_fraction}
        if self.depth_per_w is not None:
            d["depth_per_w"] = self.depth_per_w
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ClosureZone:
        per_w = d.get("depth_per_w")
        return cls(
            float(d["y_fraction"]),
            float(d["depth_fraction"]),
            None if per_w is None else float(per_w),
        )


# The closing load of stages 3-6 (docs/model.md, "Closure load"):
# - ``reactions``: the Dirichlet closure's nodal reactions of stage 2, held; the zone tied in
#   the contact stages, which restart from stage 2;
# - ``paper-code``: the published code's closure, a uniform x-traction of 1.82 max|P_xx| on
#   the wound's upper part, no tie, stage 4 restarting from stage 1 (the reproduction preset);
# - ``solved``: a uniform closing traction on the zone's dermal part whose amplitude is solved
#   in stage 3 so that the zone's median surface gap is zero, held in stages 4-6 (no tie).
CLOSURE_LOADS = ("reactions", "paper-code", "solved")


@dataclasses.dataclass(frozen=True)
class StageSettings:
    """The sweep's ``stages``: the closure zone, the contact penalty k_V of stages 4, 5 and 6,
    and the closing load of stages 3-6 (one of `CLOSURE_LOADS`)."""

    closure_zone: ClosureZone = ClosureZone()
    contact_penalty_GPa: tuple[float, float, float] = (1.0, 5.0, 100.0)
    closure_load: str = "reactions"

    def __post_init__(self) -> None:
        if self.closure_load not in CLOSURE_LOADS:
            raise ValueError(
                f"closure_load {self.closure_load!r}: expected one of {', '.join(CLOSURE_LOADS)}"
            )

    @classmethod
    def paper_code(cls) -> StageSettings:
        """The published code's stages (reference-findings: its zone |y| < L/2 down to
        0.7 w / 2, and its closure): the reproduction preset."""
        return cls(ClosureZone(0.5, 0.5, 0.35), closure_load="paper-code")

    def to_dict(self) -> dict[str, Any]:
        return {
            "closure_zone": self.closure_zone.to_dict(),
            "contact_penalty_GPa": list(self.contact_penalty_GPa),
            "closure_load": self.closure_load,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StageSettings:
        return cls(
            ClosureZone.from_dict(d["closure_zone"]),
            tuple(float(k) for k in d["contact_penalty_GPa"]),  # type: ignore[arg-type]
            str(d.get("closure_load", "reactions")),
        )

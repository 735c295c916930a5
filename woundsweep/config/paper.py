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
    y_fraction * L_y, L_y the patch half-length) and the upper ``depth_fraction`` of its depth."""

    y_fraction: float = 1.0 / 3.0
    depth_fraction: float = 0.5


@dataclasses.dataclass(frozen=True)
class StageSettings:
    """The sweep's ``stages``: the closure zone and the contact penalty k_V of stages 4, 5 and 6."""

    closure_zone: ClosureZone = ClosureZone()
    contact_penalty_GPa: tuple[float, float, float] = (1.0, 5.0, 100.0)

    def to_dict(self) -> dict[str, Any]:
        return {
            "closure_zone": dataclasses.asdict(self.closure_zone),
            "contact_penalty_GPa": list(self.contact_penalty_GPa),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StageSettings:
        zone = d["closure_zone"]
        return cls(
            ClosureZone(float(zone["y_fraction"]), float(zone["depth_fraction"])),
            tuple(float(k) for k in d["contact_penalty_GPa"]),  # type: ignore[arg-type]
        )

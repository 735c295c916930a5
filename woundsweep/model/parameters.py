"""Published parameter sets: the paper's Table 2 (from Flynn et al., Tables 2-3) and the stage
settings of its Methods.

Pure data: the materials in the keys of a sweep's ``materials`` section (units in the key
names; TSF is a stretch, dimensionless), the stage settings in those of its ``stages``
section. `woundsweep.model` builds the model from them and `woundsweep.sweep.grid` uses them
as the sweep defaults.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

__all__ = [
    "CONTACT_PENALTY_GPA",
    "SKIN_TYPES",
    "STAGE_SETTINGS",
    "SUBCUTIS",
    "TABLE2",
    "ClosureZone",
]

SUBCUTIS: dict[str, float] = {"C10_kPa": 0.4, "C20_kPa": 1.4, "K_kPa": 50.0}

SKIN_TYPES: dict[str, dict[str, Any]] = {
    "normal": {"c_kPa": 21.3, "mu_kPa": [17.8, 5.9, 5.9], "lambda11_kPa": 1.0,
               "lambda_other_kPa": 1.0, "K_kPa": 250.0, "tsf": 1.10},
    "stiff": {"c_kPa": 42.6, "mu_kPa": [35.6, 11.8, 11.8], "lambda11_kPa": 11.8,
              "lambda_other_kPa": 2.0, "K_kPa": 250.0, "tsf": 1.05},
    "soft": {"c_kPa": 10.7, "mu_kPa": [8.9, 3.0, 3.0], "lambda11_kPa": 0.5,
             "lambda_other_kPa": 0.5, "K_kPa": 250.0, "tsf": 1.15},
}  # fmt: skip

TABLE2: dict[str, Any] = {"subcutis": SUBCUTIS, "skin_types": SKIN_TYPES}


@dataclasses.dataclass(frozen=True)
class ClosureZone:
    """Where primary intention acts: the middle ``y_fraction`` of the wound length (|y - y_c| <=
    y_fraction * L_y, L_y the patch half-length) and the upper ``depth_fraction`` of its depth."""

    y_fraction: float = 1.0 / 3.0
    depth_fraction: float = 0.5

    @classmethod
    def from_sweep(cls, stages: Mapping[str, Any] | None) -> ClosureZone:
        zone = (stages or {}).get("closure_zone", {})
        return cls(
            float(zone.get("y_fraction", cls.y_fraction)),
            float(zone.get("depth_fraction", cls.depth_fraction)),
        )


CONTACT_PENALTY_GPA = (1.0, 5.0, 100.0)  # k_V of stages 4, 5 and 6

STAGE_SETTINGS: dict[str, Any] = {
    "closure_zone": dataclasses.asdict(ClosureZone()),
    "contact_penalty_GPa": list(CONTACT_PENALTY_GPA),
    # The contact formulation of stages 4-6: "smooth" (`woundsweep.contact`) is the only one.
    "contact_model": "smooth",
}

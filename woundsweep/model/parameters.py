"""Published parameter sets: the paper's Table 2 (from Flynn et al., Tables 2-3).

Pure data, in the keys of a sweep's ``materials`` section (units in the key names; TSF is a
stretch, dimensionless). `woundsweep.model.materials` builds the material objects from it
and `woundsweep.sweep.grid` uses it as the sweep default.
"""

from __future__ import annotations

from typing import Any

__all__ = ["SKIN_TYPES", "SUBCUTIS", "TABLE2"]

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

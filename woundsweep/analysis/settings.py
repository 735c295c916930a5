"""What the stress-quantile model is built from, and its tunable settings.

The features are the adjustable parameters of Table 1 plus the stage; the target is the
quantile class of ``STRESS`` (the volume-weighted 99th percentile of von Mises, kPa).
`ModelSettings` holds the ``Sweep.analysis`` keys: quantiles, split fractions and the
XGBoost hyperparameters.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

from ..errors import AnalysisError
from ..schema import FailureClass

__all__ = [
    "FEATURES",
    "IMPORTANCE_GROUPS",
    "LOCATION_COLUMNS",
    "CONVERGENCE_FAILURES",
    "COVERAGE_LEVELS",
    "FAILURE_FORMAT",
    "JOB_FEATURES",
    "MIN_FAILED_JOBS",
    "MIN_ROWS_PER_QUANTILE",
    "MODEL_FORMAT",
    "REQUIRED_COLUMNS",
    "SCHEMES",
    "SHAPE_CODES",
    "STAGE_GROUPS",
    "STRESS",
    "SURROGATE_FORMAT",
    "ModelSettings",
    "resolve_settings",
]

STRESS = "p99_von_mises_kPa"
# Model features, in model column order. Shape and skin type are encoded as numbers (below);
# the two shape-specific factors stay separate columns, NaN where they do not apply
# (XGBoost routes missing values down a learned default branch).
FEATURES: tuple[str, ...] = (
    "wound_shape",
    "dermal_thickness_mm",
    "subcutis_thickness_factor",
    "patch_size_factor",
    "wound_width_factor",
    "wound_depth_factor",
    "wound_aspect_factor",
    "mesh_size_factor",
    "orientation_deg",
    "skin_type",
    "stage",
)
SHAPE_CODES: dict[str, float] = {"cylindrical": 0.0, "wedge": 1.0}
# The paper's most important "feature" was one column holding the wedge depth factor or the
# cylinder height offset. Importances of our two columns are summed into one "wound_depth"
# entry for the ranking (split counts and total gains add; average gain = total / count).
IMPORTANCE_GROUPS: dict[str, tuple[str, ...]] = {
    "wound_depth": ("wound_depth_factor", "wound_aspect_factor"),
    **{f: (f,) for f in FEATURES if f not in ("wound_depth_factor", "wound_aspect_factor")},
}
LOCATION_COLUMNS = ("max_location_x_mm", "max_location_y_mm", "max_location_z_mm")
REQUIRED_COLUMNS: tuple[str, ...] = (
    "job_id",
    "geometry_id",
    *FEATURES,
    "status",
    STRESS,
    *LOCATION_COLUMNS,
    "total_thickness_mm",
    "patch_half_length_mm",
    "wound_width_mm",
)
SCHEMES = ("random", "geometry")
# Fewer rows than this per quantile class cannot fill train, validation and test sensibly.
MIN_ROWS_PER_QUANTILE = 10
# Stage groups of the location statistics and figures (Figure 2).
STAGE_GROUPS = (("stage 1", (1,)), ("stage 2", (2,)), ("stages 3-6", (3, 4, 5, 6)))
MODEL_FORMAT = "woundsweep-quantile-model/1"
SURROGATE_FORMAT = "woundsweep-stress-surrogate/1"
FAILURE_FORMAT = "woundsweep-failure-model/1"
# Nominal levels whose empirical coverage on the test geometries metrics.json reports.
COVERAGE_LEVELS = (0.8, 0.95)
# The failure model's features: a job's parameters (no stage: the job fails as a whole).
JOB_FEATURES: tuple[str, ...] = tuple(f for f in FEATURES if f != "stage")
# Job outcomes that count as "did not converge" (iteration or time budget spent); crashes,
# out-of-memory, mesh failures and invalid input say nothing about convergence and are left out.
CONVERGENCE_FAILURES = (FailureClass.NOT_CONVERGED.value, FailureClass.TIMEOUT.value)
# Fewer failed (or converged) jobs than this train no failure model; the report says so.
MIN_FAILED_JOBS = 10


@dataclasses.dataclass(frozen=True)
class ModelSettings:
    """Quantiles, split fractions and XGBoost hyperparameters (``Sweep.analysis`` keys)."""

    quantiles: int = 8
    seed: int = 0
    train_fraction: float = 0.63
    validation_fraction: float = 0.27  # the test set gets the rest (10 %)
    n_estimators: int = 150  # maximum boosting rounds; early stopping usually ends sooner
    early_stopping_rounds: int = 20
    max_depth: int = 6
    learning_rate: float = 0.1
    min_child_weight: float = 1.0
    subsample: float = 1.0
    colsample_bytree: float = 1.0
    reg_lambda: float = 1.0
    nthread: int = 2  # fixed, so that identical seeds give identical models
    sobol_samples: int = 1024  # Saltelli base samples N (a power of 2): N (d + 2) surrogate calls

    def check(self) -> ModelSettings:
        """Raise `AnalysisError` on values XGBoost or the splits cannot use."""
        if self.quantiles < 2:
            raise AnalysisError(f"analysis.quantiles: expected at least 2, got {self.quantiles}")
        for name in ("n_estimators", "max_depth", "nthread"):
            if getattr(self, name) < 1:
                raise AnalysisError(
                    f"analysis.{name}: expected at least 1, got {getattr(self, name)}"
                )
        n = self.sobol_samples
        if n < 16 or n & (n - 1):
            raise AnalysisError(f"analysis.sobol_samples: expected a power of 2 >= 16, got {n}")
        if self.early_stopping_rounds < 1:
            raise AnalysisError("analysis.early_stopping_rounds: expected at least 1")
        if not (0 < self.train_fraction < 1 and 0 < self.validation_fraction < 1):
            raise AnalysisError(
                "analysis: train_fraction and validation_fraction must lie in (0, 1)"
            )
        if self.train_fraction + self.validation_fraction >= 1:
            raise AnalysisError(
                "analysis: train_fraction + validation_fraction must leave rows for the test set"
            )
        for name in ("subsample", "colsample_bytree"):
            if not 0 < getattr(self, name) <= 1:
                raise AnalysisError(f"analysis.{name}: expected a value in (0, 1]")
        if self.learning_rate <= 0 or self.min_child_weight < 0 or self.reg_lambda < 0:
            raise AnalysisError(
                "analysis: learning_rate must be > 0, min_child_weight and reg_lambda >= 0"
            )
        return self

    def xgb_params(self) -> dict[str, Any]:
        """Parameters for `xgboost.train` (``multi:softprob``, histogram trees)."""
        return {
            "objective": "multi:softprob",
            "num_class": self.quantiles,
            # The last metric drives early stopping: the validation log loss.
            "eval_metric": ["merror", "mlogloss"],
            "tree_method": "hist",
            "max_depth": self.max_depth,
            "eta": self.learning_rate,
            "min_child_weight": self.min_child_weight,
            "subsample": self.subsample,
            "colsample_bytree": self.colsample_bytree,
            "lambda": self.reg_lambda,
            "nthread": self.nthread,
            "seed": self.seed,
        }


def _coerce(name: str, value: Any, kind: type) -> Any:
    try:
        if kind is int:
            f = float(value)
            if not f.is_integer():
                raise ValueError
            return int(f)
        f = float(value)
        if not math.isfinite(f):
            raise ValueError
        return f
    except (TypeError, ValueError):
        raise AnalysisError(f"analysis.{name}: expected {kind.__name__}, got {value!r}") from None


def resolve_settings(*layers: Mapping[str, Any] | None) -> ModelSettings:
    """Overlay mappings (e.g. ``Sweep.analysis``, then command-line values) on the defaults."""
    fields = {f.name: f.type for f in dataclasses.fields(ModelSettings)}
    values: dict[str, Any] = {}
    for layer in layers:
        for key, value in (layer or {}).items():
            if key not in fields:
                raise AnalysisError(
                    f"analysis.{key}: unknown setting (expected one of {sorted(fields)})"
                )
            if value is not None:
                values[key] = _coerce(key, value, int if fields[key] in ("int", int) else float)
    return ModelSettings(**values).check()

"""The stress model's settings: the sweep's ``analysis`` section (quantiles, split fractions,
XGBoost hyperparameters, the stress surrogate's kind), with each default written once here."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

from ..core.errors import AnalysisError

__all__ = ["CHOICES", "INT_RANGES", "ModelSettings", "resolve_settings"]

# The integer settings' ranges, both ends allowed (XGBoost takes a 32-bit unsigned seed).
INT_RANGES = {
    "quantiles": (2, 100),
    "seed": (0, 2**32 - 1),
    "n_estimators": (1, 100_000),
    "early_stopping_rounds": (1, 100_000),
    "max_depth": (1, 32),
    "nthread": (1, 1024),
    "sobol_samples": (16, 2**16),
}
# The named settings' values (the first is the default).
CHOICES = {
    # The stress surrogate: XGBoost trees, or Gaussian processes that interpolate between
    # the grid's values (`woundsweep.analysis.interpolant`).
    "surrogate": ("trees", "gp"),
}


@dataclasses.dataclass(frozen=True)
class ModelSettings:
    """Quantiles, split fractions, XGBoost hyperparameters and the stress surrogate's kind
    (``Sweep.analysis`` keys)."""

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
    surrogate: str = "trees"  # one of CHOICES["surrogate"]

    def check(self) -> ModelSettings:
        """Raise `AnalysisError` on values XGBoost or the splits cannot use (`INT_RANGES`,
        `CHOICES`)."""
        for name, allowed in CHOICES.items():
            if getattr(self, name) not in allowed:
                raise AnalysisError(
                    f"analysis.{name}: expected one of {', '.join(allowed)}, "
                    f"got {getattr(self, name)!r}"
                )
        for name, (lo, hi) in INT_RANGES.items():
            if not lo <= getattr(self, name) <= hi:
                raise AnalysisError(
                    f"analysis.{name}: expected an integer from {lo} to {hi}, "
                    f"got {getattr(self, name)}"
                )
        n = self.sobol_samples
        if n & (n - 1):
            raise AnalysisError(f"analysis.sobol_samples: expected a power of 2, got {n}")
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
        if not 0 < self.learning_rate <= 1:
            raise AnalysisError("analysis.learning_rate: expected a value in (0, 1]")
        for name in ("min_child_weight", "reg_lambda"):
            if not 0 <= getattr(self, name) <= 1e6:
                raise AnalysisError(f"analysis.{name}: expected a value from 0 to 1e6")
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
    if kind is str:
        if not isinstance(value, str):
            raise AnalysisError(f"analysis.{name}: expected a name, got {value!r}")
        return value.strip()
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
    except (TypeError, ValueError, OverflowError):
        raise AnalysisError(f"analysis.{name}: expected {kind.__name__}, got {value!r}") from None


# A field's annotation -> its type.
_KINDS: dict[str, type] = {"int": int, "float": float, "str": str}


def resolve_settings(*layers: Mapping[str, Any] | None) -> ModelSettings:
    """Overlay mappings (e.g. ``Sweep.analysis``, then command-line values) on the defaults."""
    # Annotations are text here (`from __future__ import annotations`).
    fields = {f.name: str(f.type) for f in dataclasses.fields(ModelSettings)}
    values: dict[str, Any] = {}
    for layer in layers:
        for key, value in (layer or {}).items():
            if key not in fields:
                raise AnalysisError(
                    f"analysis.{key}: unknown setting (expected one of {sorted(fields)})"
                )
            if value is not None:
                values[key] = _coerce(key, value, _KINDS.get(fields[key], float))
    return ModelSettings(**values).check()

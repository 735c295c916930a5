"""The stress surrogate's common interface, whichever kind `ModelSettings.surrogate` chose.

A surrogate maps rows of its model columns (``features``) to log p99 (log kPa) and a scale
per row: ``predict_log(X) -> (mean, sd)``. Conformal scores are ``|log y - mean| / sd`` and
a half-width is the calibrated score quantile times ``sd``. The trees' scale is 1 (absolute
log residuals), the Gaussian process's its predictive standard deviation. ``continuous``:
the answer moves smoothly between trained values, so `predict` evaluates it at the asked
orientation instead of weighting the two trained neighbours.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    import xgboost as xgb

__all__ = ["Surrogate", "TreeSurrogate", "as_surrogate"]


class Surrogate(Protocol):
    """What every stress surrogate offers."""

    kind: str
    continuous: bool

    @property
    def features(self) -> list[str]: ...

    def predict_log(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Log p99 (log kPa) and its scale for the rows of ``X`` (the model columns)."""
        ...

    def to_bytes(self) -> bytes:
        """The model file's contents (``surrogate.json``)."""
        ...


class TreeSurrogate:
    """The XGBoost booster of `regression` behind the common interface (scale 1)."""

    kind = "trees"
    continuous = False

    def __init__(self, booster: xgb.Booster, nthread: int = 2) -> None:
        self.booster = booster
        self.nthread = nthread

    @property
    def features(self) -> list[str]:
        from .training import booster_features

        return booster_features(self.booster)

    def predict_log(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from .regression import predict_log

        return predict_log(self.booster, X, self.nthread), np.ones(len(X))

    def to_bytes(self) -> bytes:
        return bytes(self.booster.save_raw("json"))


def as_surrogate(model: Any, nthread: int = 2) -> Surrogate:
    """``model`` itself, or a bare XGBoost booster behind the common interface."""
    return model if hasattr(model, "predict_log") else TreeSurrogate(model, nthread)

"""XGBoost ``multi:softprob`` on the quantile classes, with early stopping on validation."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..config.analysis import ModelSettings
from .settings import FEATURES
from .splits import Split

if TYPE_CHECKING:
    import xgboost as xgb

__all__ = ["Trained", "booster_features", "dmatrix", "predict_proba", "train_model"]


class Trained(NamedTuple):
    """A booster cut to its best round, with the per-round evaluation log."""

    booster: xgb.Booster
    best_iteration: int  # 0-based; the booster holds rounds 0..best_iteration
    rounds_run: int
    eval_log: dict[str, dict[str, list[float]]]


def dmatrix(
    X: np.ndarray,
    y: np.ndarray | None = None,
    nthread: int = 2,
    features: Sequence[str] = FEATURES,
) -> Any:
    """An ``xgboost.DMatrix`` of ``X`` (columns named ``features``, NaN missing), labels ``y``."""
    import xgboost as xgb

    return xgb.DMatrix(X, label=y, feature_names=list(features), missing=np.nan, nthread=nthread)


def train_model(
    X: np.ndarray,
    y: np.ndarray,
    split: Split,
    settings: ModelSettings,
    features: Sequence[str] = FEATURES,
) -> Trained:
    """Boost on the training rows (columns ``features``), stop early on the validation log loss."""
    import xgboost as xgb

    dtrain = dmatrix(X[split.train], y[split.train], settings.nthread, features)
    dval = dmatrix(X[split.validation], y[split.validation], settings.nthread, features)
    log: dict[str, dict[str, list[float]]] = {}
    booster = xgb.train(
        settings.xgb_params(),
        dtrain,
        num_boost_round=settings.n_estimators,
        evals=[(dtrain, "train"), (dval, "validation")],
        early_stopping_rounds=settings.early_stopping_rounds,
        evals_result=log,
        verbose_eval=False,
    )
    rounds = booster.num_boosted_rounds()
    best = int(getattr(booster, "best_iteration", rounds - 1))
    log = {s: {m: [float(v) for v in vals] for m, vals in ms.items()} for s, ms in log.items()}
    return Trained(booster[: best + 1], best, rounds, log)


def booster_features(booster: xgb.Booster) -> list[str]:
    """The columns a booster was trained on (`FEATURES` for one saved without names)."""
    return list(booster.feature_names or FEATURES)


def predict_proba(booster: xgb.Booster, X: np.ndarray, nthread: int = 2) -> np.ndarray:
    """Class probabilities (rows x q), renormalised in float64 (XGBoost sums in float32);
    ``X`` has the booster's columns."""
    d = dmatrix(X, nthread=nthread, features=booster_features(booster))
    prob = np.asarray(booster.predict(d), dtype=np.float64)
    return prob / prob.sum(axis=1, keepdims=True)

"""The stress surrogate: XGBoost regression of log p99 (kPa) with conformal intervals.

One booster over the classifier's columns (`model_features`; the stage is a feature, so it answers per
stage). Rows are split by physical geometry, as the classifier's ``geometry`` scheme: its
training geometries train the booster; its validation geometries are halved at random
into early-stopping rows and calibration rows (`conformal`); its test geometries are used
once, for RMSE and the empirical coverage at `COVERAGE_LEVELS`. No geometry of the
calibration or test rows was seen in training, so the intervals are meant for a new wound.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pandas as pd

from .. import __version__
from ..config.analysis import ModelSettings
from ..core.errors import AnalysisError
from ..core.versions import SURROGATE_FORMAT
from .conformal import calibrate, coverage
from .evaluation import feature_importance, shap_importance
from .settings import COVERAGE_LEVELS, STRESS, model_features
from .splits import geometry_groups, geometry_split
from .training import booster_features, dmatrix

if TYPE_CHECKING:
    import xgboost as xgb

__all__ = ["SurrogateFit", "SurrogateSplit", "fit_surrogate", "predict_log", "surrogate_split"]


class SurrogateSplit(NamedTuple):
    """Sorted row indices: training, early stopping, calibration, test."""

    train: np.ndarray
    stop: np.ndarray
    calibration: np.ndarray
    test: np.ndarray


class SurrogateFit(NamedTuple):
    """The booster, its split, the test predictions (log kPa), metrics and metadata."""

    booster: xgb.Booster
    split: SurrogateSplit
    pred_test: np.ndarray
    metrics: dict[str, Any]
    meta: dict[str, Any]


def surrogate_split(groups: np.ndarray, settings: ModelSettings) -> SurrogateSplit:
    """The geometry split, with its validation geometries halved into stop / calibration."""
    base = geometry_split(
        groups, settings.train_fraction, settings.validation_fraction, settings.seed
    )
    val_groups = np.unique(groups[base.validation])
    # A second stream of the same seed: the halving is reproducible and independent of the split.
    order = np.random.default_rng([settings.seed, 1]).permutation(val_groups)
    stop_groups = order[: len(order) // 2]
    in_stop = np.isin(groups[base.validation], stop_groups)
    return SurrogateSplit(
        base.train, base.validation[in_stop], base.validation[~in_stop], base.test
    )


def predict_log(booster: xgb.Booster, X: np.ndarray, nthread: int = 2) -> np.ndarray:
    """The surrogate's log p99 (log kPa) for the rows of ``X`` (the booster's columns), float64."""
    d = dmatrix(X, nthread=nthread, features=booster_features(booster))
    return np.asarray(booster.predict(d), dtype=np.float64)


def _params(settings: ModelSettings) -> dict[str, Any]:
    p = settings.xgb_params()
    del p["num_class"]
    return {**p, "objective": "reg:squarederror", "eval_metric": "rmse"}


def fit_surrogate(rows: pd.DataFrame, X: np.ndarray, settings: ModelSettings) -> SurrogateFit:
    """Train on the training geometries, stop early, calibrate, and score on the test ones."""
    import xgboost as xgb

    from .fitting import feature_levels, feature_ranges

    y = np.log(rows[STRESS].to_numpy(dtype=np.float64))
    stage = rows["stage"].to_numpy(dtype=np.int64)
    split = surrogate_split(geometry_groups(rows), settings)
    for name, idx in split._asdict().items():
        if len(idx) == 0:
            raise AnalysisError(
                f"stress surrogate: empty {name} set from {len(rows)} rows; too few geometries"
            )
    nt = settings.nthread
    features = model_features(rows["wound_shape"].astype(str))
    dtrain = dmatrix(X[split.train], y[split.train], nt, features)
    dstop = dmatrix(X[split.stop], y[split.stop], nt, features)
    log: dict[str, dict[str, list[float]]] = {}
    booster = xgb.train(
        _params(settings), dtrain, num_boost_round=settings.n_estimators,
        evals=[(dtrain, "train"), (dstop, "stop")],
        early_stopping_rounds=settings.early_stopping_rounds, evals_result=log, verbose_eval=False,
    )  # fmt: skip
    rounds = booster.num_boosted_rounds()
    best = int(getattr(booster, "best_iteration", rounds - 1))
    booster = booster[: best + 1]
    cal, test = split.calibration, split.test
    scores = calibrate(stage[cal], y[cal] - predict_log(booster, X[cal], nt))
    pred = predict_log(booster, X[test], nt)
    resid = y[test] - pred
    ss_tot = float(np.sum((y[test] - y[test].mean()) ** 2))
    metrics = {
        "target": f"log({STRESS})",
        "calibration": "split-conformal, absolute log residuals, per stage",
        "split_rows": {k: int(len(v)) for k, v in split._asdict().items()},
        "split_geometries": {
            k: int(rows["geometry_id"].iloc[v].nunique()) for k, v in split._asdict().items()
        },
        "best_iteration": best,
        "rounds_run": rounds,
        "test": {
            "rows": int(len(test)),
            "rmse_log": float(np.sqrt(np.mean(resid**2))),
            "r2_log": 1.0 - float(np.sum(resid**2)) / ss_tot if ss_tot > 0 else None,
            "coverage": {
                str(lv): coverage(y[test], pred, stage[test], scores, lv) for lv in COVERAGE_LEVELS
            },
        },
        "importance": {
            **feature_importance(booster),
            "shap": shap_importance(booster, dmatrix(X, nthread=nt, features=features)),
        },
    }
    meta = {
        "format": SURROGATE_FORMAT,
        "features": list(features),
        "target": metrics["target"],
        "stages": sorted(int(s) for s in np.unique(stage[split.train])),
        "ranges": feature_ranges(X[split.train], features),
        "levels": feature_levels(X[split.train], features),
        "skin_levels_c_kPa": np.unique(X[split.train, features.index("skin_type")]).tolist(),
        "calibration_scores_log": scores,
        "best_iteration": best,
        "settings": dataclasses.asdict(settings),
        "training_rows": int(len(split.train)),
        "calibration_geometries": int(rows["geometry_id"].iloc[cal].nunique()),
        "woundsweep_version": __version__,
    }
    return SurrogateFit(booster, split, pred, metrics, meta)

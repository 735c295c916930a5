"""The stress surrogate: log p99 (kPa) with split-conformal intervals.

Two kinds (`ModelSettings.surrogate`), both answering through `surrogate.Surrogate`:
``trees``, one XGBoost booster over the classifier's columns (`model_features`; the stage is
a feature), and ``gp``, Gaussian processes per (shape, skin, stage) that interpolate between
the grid's values (`interpolant`).

Rows are split by physical geometry, as the classifier's ``geometry`` scheme (for the GP,
geometries that differ only in t_d are one group: it cannot tell them apart). Its training
geometries train the surrogate; its validation geometries are halved at random into
early-stopping rows (the trees'; the GP trains on them) and calibration rows (`conformal`);
its test geometries are used once, for RMSE and the empirical coverage at
`COVERAGE_LEVELS`, with its bootstrap interval over the test geometries (`conformal`).
Scores are ``|log y - mean| / sd`` per stage (sd = 1 for the trees). Calibrated off the grid
(``calibration``: another run's rows, or several runs' pooled, `analyze --calibrate-on`),
the scores come from those rows and the grid's calibration geometries join the training
rows.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
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
from .surrogate import Surrogate, TreeSurrogate
from .training import booster_features, dmatrix

if TYPE_CHECKING:
    import xgboost as xgb

    from .offgrid import OtherRows

__all__ = ["SurrogateFit", "SurrogateSplit", "fit_surrogate", "predict_log", "surrogate_split"]

# What the conformal scores are, per kind.
SCORES = {
    "trees": "absolute log residuals",
    "gp": "normalised scores |log y - mean| / sd (the GP's predictive SD)",
}


class SurrogateSplit(NamedTuple):
    """Sorted row indices: training, early stopping, calibration, test."""

    train: np.ndarray
    stop: np.ndarray
    calibration: np.ndarray
    test: np.ndarray


class SurrogateFit(NamedTuple):
    """The surrogate, its split, the test predictions (log kPa) and their scale, metrics and
    metadata."""

    model: Surrogate
    split: SurrogateSplit
    pred_test: np.ndarray
    sd_test: np.ndarray
    metrics: dict[str, Any]
    meta: dict[str, Any]

    @property
    def booster(self) -> xgb.Booster | None:
        """The trees' booster (None for the GP)."""
        return getattr(self.model, "booster", None)


class _Fitted(NamedTuple):
    """What one kind's fitter returns: the model, its training rows, extra metrics and meta."""

    model: Surrogate
    train: np.ndarray
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


def _fit_trees(
    rows: pd.DataFrame, X: np.ndarray, y: np.ndarray, split: SurrogateSplit,
    settings: ModelSettings, features: tuple[str, ...], off_grid: bool,
) -> _Fitted:  # fmt: skip
    """The booster, early-stopped on the stop rows."""
    import xgboost as xgb

    train = np.union1d(split.train, split.calibration) if off_grid else split.train
    nt = settings.nthread
    dtrain = dmatrix(X[train], y[train], nt, features)
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
    importance = {
        **feature_importance(booster),
        "shap": shap_importance(booster, dmatrix(X, nthread=nt, features=features)),
    }
    metrics = {"best_iteration": best, "rounds_run": rounds, "importance": importance}
    return _Fitted(TreeSurrogate(booster, nt), train, metrics, {"best_iteration": best})


def _fit_gp(
    rows: pd.DataFrame, X: np.ndarray, y: np.ndarray, split: SurrogateSplit,
    settings: ModelSettings, features: tuple[str, ...], off_grid: bool,
) -> _Fitted:  # fmt: skip
    """Per-group Gaussian processes on the training and stop rows (no early stopping)."""
    from .interpolant import fit_gp

    parts = [split.train, split.stop] + ([split.calibration] if off_grid else [])
    train = np.sort(np.concatenate(parts))
    c = X[:, features.index("skin_type")]
    skins = {float(k): str(v) for k, v in zip(c, rows["skin_type"].astype(str))}
    model = fit_gp(X[train], y[train], features, skins, settings.seed)
    return _Fitted(model, train, {"gp": model.summary()}, {})


_FITTERS: dict[str, Callable[..., _Fitted]] = {"trees": _fit_trees, "gp": _fit_gp}


def fit_surrogate(
    rows: pd.DataFrame, X: np.ndarray, settings: ModelSettings,
    calibration: OtherRows | None = None,
) -> SurrogateFit:  # fmt: skip
    """Train, calibrate (on held-out grid geometries, or on ``calibration``'s rows), and score
    on the test geometries."""
    from .fitting import feature_levels, feature_ranges

    kind = settings.surrogate
    y = np.log(rows[STRESS].to_numpy(dtype=np.float64))
    stage = rows["stage"].to_numpy(dtype=np.int64)
    split = surrogate_split(geometry_groups(rows, scale_free=kind == "gp"), settings)
    # The coverage's bootstrap clusters: rows that differ only in t_d are one wound.
    clusters = geometry_groups(rows, scale_free=True)
    for name, idx in split._asdict().items():
        if len(idx) == 0:
            raise AnalysisError(
                f"stress surrogate: empty {name} set from {len(rows)} rows; too few geometries"
            )
    features = model_features(rows["wound_shape"].astype(str))
    fitted = _FITTERS[kind](rows, X, y, split, settings, features, calibration is not None)
    model, train = fitted.model, fitted.train
    if calibration is None:
        cal = split.calibration
        cal_rows, cal_X, source = rows.iloc[cal], X[cal], "held-out grid geometries"
    else:
        cal_rows, cal_X = calibration.rows, calibration.X
        source = f"the rows of {calibration.source} (off the grid)"
    cal_y = np.log(cal_rows[STRESS].to_numpy(dtype=np.float64))
    mean, sd = model.predict_log(cal_X)
    scores = calibrate(cal_rows["stage"].to_numpy(dtype=np.int64), (cal_y - mean) / sd)
    test = split.test
    pred, sd_test = model.predict_log(X[test])
    resid = y[test] - pred
    ss_tot = float(np.sum((y[test] - y[test].mean()) ** 2))
    cal_geoms = int(cal_rows["geometry_id"].nunique())
    statement = f"split-conformal, {SCORES[kind]}, per stage, on {source}"
    rows_of = {k: int(len(v)) for k, v in split._asdict().items()}
    metrics = {
        "surrogate": kind,
        "target": f"log({STRESS})",
        "calibration": statement,
        "calibration_rows": int(len(cal_rows)),
        "calibration_geometries": cal_geoms,
        "split_rows": rows_of,
        "split_geometries": {
            k: int(rows["geometry_id"].iloc[v].nunique()) for k, v in split._asdict().items()
        },
        "training_rows": int(len(train)),
        **{k: v for k, v in fitted.metrics.items() if k != "importance"},
        "test": {
            "rows": int(len(test)),
            "rmse_log": float(np.sqrt(np.mean(resid**2))),
            "r2_log": 1.0 - float(np.sum(resid**2)) / ss_tot if ss_tot > 0 else None,
            "coverage": {
                str(lv): coverage(y[test], pred, stage[test], scores, lv, sd_test, clusters[test])
                for lv in COVERAGE_LEVELS
            },
        },
    }
    if "importance" in fitted.metrics:
        metrics["importance"] = fitted.metrics["importance"]
    meta = {
        "format": SURROGATE_FORMAT,
        "surrogate": kind,
        "features": list(features),
        "target": metrics["target"],
        "stages": sorted(int(s) for s in np.unique(stage[train])),
        "ranges": feature_ranges(X[train], features),
        "levels": feature_levels(X[train], features),
        "skin_levels_c_kPa": np.unique(X[train, features.index("skin_type")]).tolist(),
        "calibration_scores_log": scores,
        "calibration": statement,
        **fitted.meta,
        "settings": dataclasses.asdict(settings),
        "training_rows": int(len(train)),
        "calibration_geometries": cal_geoms,
        "woundsweep_version": __version__,
    }
    return SurrogateFit(model, split, pred, sd_test, metrics, meta)

"""One split scheme end to end: split, bin on the training rows, train, evaluate.

`SchemeFit` is what a scheme produced; the figures and the pipeline both read it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from .. import __version__
from ..config.analysis import ModelSettings
from ..core.errors import AnalysisError
from ..core.versions import MODEL_FORMAT
from .evaluation import auc_interval, evaluate, feature_importance
from .settings import FEATURES, SCHEMES, SHAPE_CODES, STRESS, model_features
from .splits import (
    Split,
    assign_quantiles,
    geometry_groups,
    geometry_split,
    quantile_edges,
    random_split,
)
from .training import Trained, predict_proba, train_model

__all__ = ["MAX_LEVELS", "SchemeFit", "feature_levels", "feature_ranges", "fit_scheme"]

# A numeric feature with more distinct training values than this is treated as continuous.
MAX_LEVELS = 64


class SchemeFit(NamedTuple):
    """Everything one split scheme produced (metrics and what the figures need)."""

    scheme: str
    split: Split
    edges_kPa: np.ndarray
    y: np.ndarray
    trained: Trained
    prob_test: np.ndarray
    metrics: dict[str, Any]
    meta: dict[str, Any]


def _per_shape(
    X: np.ndarray,
    summarise: Callable[[np.ndarray], list[float] | None],
    features: Sequence[str] = FEATURES,
) -> dict[str, dict[str, list[float]]]:
    """Per wound shape, ``summarise`` of each numeric feature's finite values over the rows of
    ``X`` (columns ``features``; a feature left out where it gives None)."""
    out: dict[str, dict[str, list[float]]] = {}
    shape_col = list(features).index("wound_shape")
    for shape, code in SHAPE_CODES.items():
        sub = X[X[:, shape_col] == code]
        if len(sub) == 0:
            continue
        out[shape] = {}
        for j, name in enumerate(features):
            if name in ("wound_shape", "skin_type", "stage"):
                continue
            got = summarise(sub[:, j][np.isfinite(sub[:, j])])
            if got is not None:
                out[shape][name] = got
    return out


def feature_ranges(
    X: np.ndarray, features: Sequence[str] = FEATURES
) -> dict[str, dict[str, list[float]]]:
    """Per wound shape, [min, max] of every numeric feature over the rows of ``X``."""
    return _per_shape(X, lambda v: [float(v.min()), float(v.max())] if len(v) else None, features)


def feature_levels(
    X: np.ndarray, features: Sequence[str] = FEATURES
) -> dict[str, dict[str, list[float]]]:
    """Per wound shape, the distinct training values of every numeric feature (the grid's
    values), or none for a feature with more than `MAX_LEVELS` of them."""

    def levels(v: np.ndarray) -> list[float] | None:
        u = np.unique(v)
        return u.tolist() if 0 < len(u) <= MAX_LEVELS else None

    return _per_shape(X, levels, features)


def fit_scheme(
    scheme: str,
    rows: pd.DataFrame,
    X: np.ndarray,
    skins: Mapping[str, float],
    settings: ModelSettings,
) -> SchemeFit:
    """Split, bin on the training rows, train, and evaluate one scheme."""
    q = settings.quantiles
    stress = rows[STRESS].to_numpy(dtype=np.float64)
    f_t, f_v = settings.train_fraction, settings.validation_fraction
    if scheme == "random":
        split = random_split(len(rows), f_t, f_v, settings.seed)
    elif scheme == "geometry":
        groups = geometry_groups(rows)
        split = geometry_split(groups, f_t, f_v, settings.seed)
    else:
        raise AnalysisError(f"unknown split scheme {scheme!r} (expected one of {SCHEMES})")
    for name, idx in split._asdict().items():
        if len(idx) == 0:
            extra = f" ({len(np.unique(groups))} geometries)" if scheme == "geometry" else ""
            raise AnalysisError(
                f"{scheme} split: empty {name} set from {len(rows)} rows{extra}; too few rows for the splits"
            )
    edges = quantile_edges(stress[split.train], q)
    y = assign_quantiles(stress, edges)
    test_classes = len(np.unique(y[split.test]))
    if test_classes < 2:
        raise AnalysisError(
            f"{scheme} split: the test set ({len(split.test)} rows) holds {test_classes} quantile class; too few rows for the splits"
        )
    features = model_features(rows["wound_shape"].astype(str))
    trained = train_model(X, y, split, settings, features)
    probs = {
        name: predict_proba(trained.booster, X[idx], settings.nthread)
        for name, idx in split._asdict().items()
    }
    metrics = {
        "split_rows": {name: int(len(idx)) for name, idx in split._asdict().items()},
        "split_geometries": {
            name: int(rows["geometry_id"].iloc[idx].nunique())
            for name, idx in split._asdict().items()
        },
        "quantile_edges_kPa": edges.tolist(),
        "quantile_edges_from": "training rows",
        "best_iteration": trained.best_iteration,
        "rounds_run": trained.rounds_run,
        "eval_log": trained.eval_log,
        **{name: evaluate(y[idx], probs[name]) for name, idx in split._asdict().items()},
        "importance": feature_importance(trained.booster),
    }
    test_geoms = rows["geometry_id"].to_numpy()[split.test]
    metrics["test"]["auc_macro_interval"] = auc_interval(
        y[split.test], probs["test"], test_geoms, settings.seed
    )
    train_rows = rows.iloc[split.train]
    meta = {
        "format": MODEL_FORMAT,
        "scheme": scheme,
        "features": list(features),
        "shape_codes": dict(SHAPE_CODES),
        "skin_codes_c_kPa": {
            k: float(v) for k, v in skins.items() if k in set(train_rows["skin_type"].astype(str))
        },
        "stages": sorted(int(s) for s in train_rows["stage"].unique()),
        "ranges": feature_ranges(X[split.train], features),
        "levels": feature_levels(X[split.train], features),
        "quantiles": q,
        "quantile_edges_kPa": edges.tolist(),
        "stress": STRESS,
        "best_iteration": trained.best_iteration,
        "settings": dataclasses.asdict(settings),
        "training_rows": int(len(split.train)),
        "woundsweep_version": __version__,
    }
    return SchemeFit(scheme, split, edges, y, trained, probs["test"], metrics, meta)

"""Scores of a trained model on one set of rows, and its feature importances."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .settings import FEATURES, IMPORTANCE_GROUPS

__all__ = ["auc_interval", "evaluate", "feature_importance", "shap_importance"]


def evaluate(y: np.ndarray, prob: np.ndarray) -> dict[str, Any]:
    """Accuracy, log loss, one-vs-rest AUC per quantile, micro and macro AUC, confusion matrix.

    A quantile without both positives and negatives in ``y`` has no AUC (``None``); the macro
    AUC is the mean over the quantiles that have one (sklearn's ``average="macro"``).
    """
    from sklearn.metrics import confusion_matrix, log_loss, roc_auc_score

    q = prob.shape[1]
    y = np.asarray(y, dtype=np.int64)
    pred = prob.argmax(axis=1)
    onehot = np.eye(q, dtype=np.int64)[y]
    per_class: list[float | None] = []
    for k in range(q):
        npos = int(onehot[:, k].sum())
        per_class.append(
            float(roc_auc_score(onehot[:, k], prob[:, k])) if 0 < npos < len(y) else None
        )
    defined = [a for a in per_class if a is not None]
    return {
        "rows": int(len(y)),
        "accuracy": float(np.mean(pred == y)),
        "within_one_quantile": float(np.mean(np.abs(pred - y) <= 1)),
        "log_loss": float(log_loss(y, prob, labels=list(range(q)))),
        "auc_per_quantile": per_class,
        "auc_macro": float(np.mean(defined)) if defined else None,
        "auc_micro": float(roc_auc_score(onehot.ravel(), prob.ravel()))
        if len(set(y)) > 1
        else None,
        "class_counts": np.bincount(y, minlength=q).tolist(),
        "confusion_matrix": confusion_matrix(y, pred, labels=list(range(q))).tolist(),
    }


def auc_interval(
    y: np.ndarray, prob: np.ndarray, groups: np.ndarray, seed: int, reps: int = 200
) -> dict[str, Any]:
    """A 95% bootstrap interval of the macro AUC over the test rows' geometries (``groups``):
    whole geometries resampled with replacement, since the rows of one geometry move
    together. ``None`` bounds with fewer than two geometries."""
    geoms, inverse = np.unique(np.asarray(groups).astype(str), return_inverse=True)
    out: dict[str, Any] = {"geometries": int(len(geoms)), "reps": reps, "ci95": None}
    if len(geoms) < 2:
        return out
    from scipy.stats import rankdata

    rng = np.random.default_rng(seed)
    members = [np.flatnonzero(inverse == g) for g in range(len(geoms))]
    y = np.asarray(y, dtype=np.int64)
    values = []
    for _ in range(reps):
        idx = np.concatenate([members[g] for g in rng.integers(0, len(geoms), len(geoms))])
        yy, pp = y[idx], prob[idx]
        aucs = []
        for k in range(prob.shape[1]):  # Mann-Whitney: sklearn's one-vs-rest AUC, ties halved
            pos = yy == k
            n_pos = int(pos.sum())
            if 0 < n_pos < len(yy):
                ranks = rankdata(pp[:, k])
                aucs.append(
                    (ranks[pos].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * (len(yy) - n_pos))
                )
        if aucs:
            values.append(float(np.mean(aucs)))
    if values:
        out["ci95"] = [float(np.percentile(values, 2.5)), float(np.percentile(values, 97.5))]
    return out


def feature_importance(booster: Any) -> dict[str, Any]:
    """Split counts ("weight", Figure 3C) and gains per feature and per `IMPORTANCE_GROUPS` entry."""
    weight = booster.get_score(importance_type="weight")
    total = booster.get_score(importance_type="total_gain")

    def entry(names: Sequence[str]) -> dict[str, float]:
        w = float(sum(weight.get(n, 0.0) for n in names))
        t = float(sum(total.get(n, 0.0) for n in names))
        return {"weight": w, "gain": t / w if w else 0.0, "total_gain": t}

    names = list(booster.feature_names or FEATURES)
    features = {f: entry([f]) for f in names}
    grouped = {g: entry(m) for g, m in IMPORTANCE_GROUPS.items() if set(m) & set(names)}

    def rank(key: str) -> list[str]:
        return sorted(grouped, key=lambda g: (-grouped[g][key], g))

    return {
        "features": features,
        "grouped": grouped,
        "ranking_weight": rank("weight"),
        "ranking_total_gain": rank("total_gain"),
    }


def shap_importance(booster: Any, dmatrix: Any) -> dict[str, Any]:
    """Mean absolute SHAP value per feature and per `IMPORTANCE_GROUPS` entry (model units).

    Exact TreeSHAP (path-dependent) from XGBoost's ``pred_contribs``; a group's value per row
    is the sum of its members' values (the two depth columns are never both set), then the
    mean of its absolute value over the rows of ``dmatrix``.
    """
    names = list(booster.feature_names)
    contrib = np.asarray(booster.predict(dmatrix, pred_contribs=True), dtype=np.float64)
    col = {n: i for i, n in enumerate(names)}

    def mean_abs(members: Sequence[str]) -> float:
        return float(np.mean(np.abs(contrib[:, [col[m] for m in members if m in col]].sum(axis=1))))

    grouped = {g: mean_abs(m) for g, m in IMPORTANCE_GROUPS.items() if any(x in col for x in m)}
    return {
        "method": "TreeSHAP (xgboost pred_contribs), mean |SHAP| over all rows",
        "features": {n: mean_abs([n]) for n in names},
        "grouped": grouped,
        "ranking": sorted(grouped, key=lambda g: (-grouped[g], g)),
    }

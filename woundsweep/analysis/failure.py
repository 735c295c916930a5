"""The probability that a job does not converge, from the store's failure classes.

One row per job of the store; the features are its parameters (`job_features`); the
target is whether its ``failure_class`` is one of `CONVERGENCE_FAILURES`. Jobs of the other
failure classes (crashed, out-of-memory, mesh-failed, invalid) are left out. Jobs are split
by physical geometry as the classifier's ``geometry`` scheme (train / validation for early
stopping / test for the AUC). With fewer than `MIN_FAILED_JOBS` failed or converged jobs, or
a split without both outcomes in training, no model is trained and the metrics say why.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pandas as pd

from .. import __version__
from ..config.analysis import ModelSettings
from ..core.schema import FailureClass
from ..core.versions import FAILURE_FORMAT
from .data import encode_features
from .evaluation import feature_importance
from .settings import (
    CONVERGENCE_FAILURES,
    FEATURES,
    JOB_FEATURES,
    MIN_FAILED_JOBS,
    job_features,
    model_features,
)
from .splits import geometry_groups, geometry_split
from .training import dmatrix

if TYPE_CHECKING:
    import xgboost as xgb

__all__ = ["FailureFit", "failure_matrix", "fit_failure", "job_table", "predict_failure"]


class FailureFit(NamedTuple):
    """The booster (``None`` when none could be trained), metrics and metadata."""

    booster: xgb.Booster | None
    metrics: dict[str, Any]
    meta: dict[str, Any]


def job_table(results: pd.DataFrame) -> pd.DataFrame:
    """One row per job (its first stage row: the parameters and the job's failure class)."""
    return results.sort_values(["job_id", "stage"]).drop_duplicates("job_id").reset_index(drop=True)


def failure_matrix(X: np.ndarray, features: Sequence[str] = FEATURES) -> np.ndarray:
    """The `job_features` columns of a matrix with the columns ``features``."""
    return X[:, [list(features).index(f) for f in job_features(features)]]


def predict_failure(booster: xgb.Booster, X: np.ndarray, nthread: int = 2) -> np.ndarray:
    """Failure probabilities of the jobs in ``X`` (the booster's columns: `job_features`)."""
    names = list(booster.feature_names or JOB_FEATURES)
    return np.asarray(
        booster.predict(dmatrix(X, nthread=nthread, features=names)), dtype=np.float64
    )


def fit_failure(
    results: pd.DataFrame, skins: Mapping[str, float], settings: ModelSettings
) -> FailureFit:
    """Train and test the failure model, or say why there are too few failures for one."""
    import xgboost as xgb
    from sklearn.metrics import roc_auc_score

    jobs = job_table(results)
    fclass = jobs["failure_class"].astype(str)
    by_class = {c.value: int((fclass == c.value).sum()) for c in FailureClass}
    keep = fclass.isin([FailureClass.CONVERGED.value, *CONVERGENCE_FAILURES]).to_numpy()
    jobs = jobs[keep].reset_index(drop=True)
    failed = jobs["failure_class"].astype(str).isin(CONVERGENCE_FAILURES).to_numpy().astype(float)
    n_fail, n_ok = int(failed.sum()), int(len(failed) - failed.sum())
    metrics: dict[str, Any] = {
        "target": f"failure_class in {list(CONVERGENCE_FAILURES)}",
        "jobs_by_failure_class": by_class,
        "jobs": int(len(jobs)),
        "failed_jobs": n_fail,
        "failure_rate": n_fail / len(jobs) if len(jobs) else None,
        "trained": False,
        "test": None,
    }
    features = model_features(jobs["wound_shape"].astype(str))
    columns = job_features(features)
    meta = {"format": FAILURE_FORMAT, "features": list(columns), "failure_rate": metrics["failure_rate"],
            "jobs": int(len(jobs)), "failed_jobs": n_fail, "woundsweep_version": __version__}  # fmt: skip

    def untrained(why: str) -> FailureFit:
        metrics["statement"] = f"no failure model: {why}"
        meta["statement"] = metrics["statement"]
        return FailureFit(None, metrics, meta)

    if min(n_fail, n_ok) < MIN_FAILED_JOBS:
        return untrained(
            f"{n_fail} of {len(jobs)} jobs failed to converge and {n_ok} converged; at least "
            f"{MIN_FAILED_JOBS} of each are needed to train one"
        )
    X = failure_matrix(encode_features(jobs, skins, features), features)
    split = geometry_split(
        geometry_groups(jobs), settings.train_fraction, settings.validation_fraction, settings.seed
    )
    if any(len(np.unique(failed[idx])) < 2 for idx in (split.train, split.validation)):
        return untrained("the training or validation geometries hold only one outcome")
    nt = settings.nthread
    params = {**settings.xgb_params(), "objective": "binary:logistic", "eval_metric": "logloss"}
    del params["num_class"]
    dtrain = dmatrix(X[split.train], failed[split.train], nt, columns)
    dval = dmatrix(X[split.validation], failed[split.validation], nt, columns)
    booster = xgb.train(
        params, dtrain, num_boost_round=settings.n_estimators,
        evals=[(dtrain, "train"), (dval, "validation")],
        early_stopping_rounds=settings.early_stopping_rounds, verbose_eval=False,
    )  # fmt: skip
    best = int(getattr(booster, "best_iteration", booster.num_boosted_rounds() - 1))
    booster = booster[: best + 1]
    y_test = failed[split.test]
    p_test = predict_failure(booster, X[split.test], nt)
    both = len(np.unique(y_test)) == 2
    metrics["trained"] = True
    metrics["split_jobs"] = {k: int(len(v)) for k, v in split._asdict().items()}
    metrics["best_iteration"] = best
    metrics["test"] = {
        "jobs": int(len(y_test)),
        "failed_jobs": int(y_test.sum()),
        "auc": float(roc_auc_score(y_test, p_test)) if both else None,
        "mean_predicted": float(p_test.mean()) if len(p_test) else None,
    }
    metrics["importance"] = feature_importance(booster)
    metrics["statement"] = (
        f"trained on {len(split.train)} jobs ({int(failed[split.train].sum())} failed); test AUC "
        + (
            f"{metrics['test']['auc']:.3f}"
            if both
            else "n/a (the test geometries hold one outcome)"
        )
    )
    meta["statement"] = metrics["statement"]
    meta["best_iteration"] = best
    return FailureFit(booster, metrics, meta)

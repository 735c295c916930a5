"""The stress-quantile model of a result store (the paper's Figure 3) and its evaluation.

Rows are the converged (job, stage) results with a positive maximal stress (the
volume-weighted 99th percentile of von Mises, ``p99_von_mises_kPa``). The features are the
adjustable parameters of Table 1 plus the stage; the target is the quantile class of the
stress (q = 8 by default). Two split schemes are evaluated side by side:

* ``random``: rows drawn at random into train / validation / test (63 / 27 / 10 %), as the
  paper did. Stages, skin types and orientations of one geometry land in several sets.
* ``geometry``: whole physical geometries (all `grid.GEOMETRY_KEYS` except the mesh size
  factor, so the same wound meshed at several resolutions counts once) go to one set only.

Quantile edges are computed on the training rows of each scheme only (the paper used all
rows, so its test rows helped place the edges). XGBoost's ``multi:softprob`` is trained
with early stopping on the validation log loss and evaluated once on the test rows.
Stresses are in kPa, lengths in mm.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from . import __version__
from .errors import AnalysisError
from .fsutil import atomic_write_bytes

__all__ = [
    "FEATURES",
    "IMPORTANCE_GROUPS",
    "MIN_ROWS_PER_QUANTILE",
    "REQUIRED_COLUMNS",
    "SCHEMES",
    "SHAPE_CODES",
    "STRESS",
    "AnalysisOutput",
    "LoadedModel",
    "ModelSettings",
    "Prediction",
    "SchemeFit",
    "Split",
    "Trained",
    "assign_quantiles",
    "encode_features",
    "evaluate",
    "feature_importance",
    "fit_scheme",
    "geometry_groups",
    "geometry_split",
    "load_model",
    "load_results",
    "normalised_locations",
    "predict",
    "predict_proba",
    "quantile_edges",
    "random_split",
    "resolve_model_path",
    "resolve_settings",
    "run_analysis",
    "select_rows",
    "skin_codes",
    "stiff_vs_soft",
    "train_model",
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
STAGE_GROUPS = (("stage 1", (1,)), ("stage 2", (2,)), ("stages 3-6", (3, 4, 5, 6)))
MODEL_FORMAT = "woundsweep-quantile-model/1"


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

    def check(self) -> ModelSettings:
        """Raise `AnalysisError` on values XGBoost or the splits cannot use."""
        if self.quantiles < 2:
            raise AnalysisError(f"analysis.quantiles: expected at least 2, got {self.quantiles}")
        for name in ("n_estimators", "max_depth", "nthread"):
            if getattr(self, name) < 1:
                raise AnalysisError(
                    f"analysis.{name}: expected at least 1, got {getattr(self, name)}"
                )
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


# -- loading -------------------------------------------------------------------------------


def _sweep_settings(run_dir: Path) -> tuple[dict[str, Any], dict[str, float]]:
    """``Sweep.analysis`` and skin type -> Fung c (kPa) of the run, or the paper's defaults."""
    from .grid import DEFAULTS, load_run

    if (run_dir / "sweep.yaml").is_file() and (run_dir / "manifest.parquet").is_file():
        sweep = load_run(run_dir).sweep
        analysis, materials = dict(sweep.analysis), sweep.materials
    else:
        analysis, materials = {}, DEFAULTS["materials"]
    return analysis, {name: float(p["c_kPa"]) for name, p in materials["skin_types"].items()}


def skin_codes(run_dir: str | Path) -> dict[str, float]:
    """Skin type name -> its Fung ``c`` in kPa: an ordered, physical code for the model."""
    return _sweep_settings(Path(run_dir))[1]


def load_results(run_dir: str | Path) -> pd.DataFrame:
    """All rows of ``RUN_DIR/results`` (one per job and stage); check the needed columns."""
    res = Path(run_dir) / "results"
    if not res.exists():
        raise AnalysisError(f"{res}: no result store (run `woundsweep run {run_dir}` first)")
    if res.is_dir() and not any(p.suffix == ".parquet" for p in res.rglob("*.parquet")):
        raise AnalysisError(f"{res}: the result store holds no Parquet files")
    try:
        df = pd.read_parquet(res)
    except Exception as err:  # pyarrow raises several types for damaged or mixed files
        first = str(err).splitlines()[0] if str(err) else ""
        raise AnalysisError(
            f"{res}: unreadable result store ({type(err).__name__}: {first})"
        ) from None
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise AnalysisError(f"{res}: missing columns {missing}")
    return df


def select_rows(df: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Converged rows with a finite, positive maximal stress; and the row counts."""
    converged = df["status"].astype(str) == "converged"
    stress = pd.to_numeric(df[STRESS], errors="coerce")
    positive = converged & np.isfinite(stress) & (stress > 0)
    rows = df[positive].reset_index(drop=True)
    counts = {
        "store_rows": int(len(df)),
        "jobs": int(df["job_id"].nunique()),
        "converged_rows": int(converged.sum()),
        "used_rows": int(len(rows)),
        "status": {
            str(k): int(v) for k, v in df["status"].astype(str).value_counts().sort_index().items()
        },
        "used_rows_by_stage": {
            str(int(k)): int(v) for k, v in rows["stage"].value_counts().sort_index().items()
        },
    }
    if not converged.any():
        raise AnalysisError(
            f"no converged rows in the result store ({len(df)} rows: {counts['status']})"
        )
    if rows.empty:
        raise AnalysisError("no converged row has a positive, finite maximal stress")
    dup = rows.duplicated(["job_id", "stage"])
    if dup.any():
        raise AnalysisError(f"the result store has {int(dup.sum())} duplicate (job_id, stage) rows")
    return rows, counts


def encode_features(rows: pd.DataFrame, skins: Mapping[str, float]) -> np.ndarray:
    """The model matrix (rows x `FEATURES`), float64, NaN for factors that do not apply."""
    X = np.empty((len(rows), len(FEATURES)), dtype=np.float64)
    for j, name in enumerate(FEATURES):
        col = rows[name]
        if name in ("wound_shape", "skin_type"):
            codes = SHAPE_CODES if name == "wound_shape" else skins
            unknown = sorted(set(col.astype(str)) - set(codes))
            if unknown:
                raise AnalysisError(f"{name}: unknown values {unknown} (known: {sorted(codes)})")
            X[:, j] = col.astype(str).map(codes).to_numpy(dtype=np.float64)
        else:
            X[:, j] = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64)
    return X


# -- quantiles and splits ------------------------------------------------------------------


def quantile_edges(stress: np.ndarray, q: int) -> np.ndarray:
    """``q + 1`` edges in kPa: the minimum, the ``k/q`` quantiles, the maximum."""
    s = np.asarray(stress, dtype=np.float64)
    if len(s) < q:
        raise AnalysisError(f"{len(s)} training rows cannot fill {q} quantiles")
    edges = np.quantile(s, np.linspace(0.0, 1.0, q + 1))
    if np.any(np.diff(edges[1:-1]) <= 0) or edges[1] <= edges[0]:
        raise AnalysisError(
            f"too few distinct stress values for {q} quantiles (tied quantile edges)"
        )
    return edges


def assign_quantiles(stress: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Class 0..q-1 of each stress; values outside the training range go to the end classes."""
    return np.searchsorted(edges[1:-1], np.asarray(stress, dtype=np.float64), side="right")


class Split(NamedTuple):
    """Sorted row indices of the three sets."""

    train: np.ndarray
    validation: np.ndarray
    test: np.ndarray


def random_split(n: int, train_fraction: float, validation_fraction: float, seed: int) -> Split:
    """The paper's split: rows drawn at random."""
    perm = np.random.default_rng(seed).permutation(n)
    n_train = int(round(train_fraction * n))
    n_val = int(round(validation_fraction * n))
    parts = (perm[:n_train], perm[n_train : n_train + n_val], perm[n_train + n_val :])
    return Split(*(np.sort(p) for p in parts))


def geometry_groups(rows: pd.DataFrame) -> np.ndarray:
    """Integer id of each row's physical geometry (geometry keys without the mesh size)."""
    from .grid import GEOMETRY_KEYS

    keys = [k for k in GEOMETRY_KEYS if k != "mesh_size_factor"]
    # NaN is not equal to itself: turn the not-applicable factors into a sentinel first.
    frame = rows[keys].astype(object).where(rows[keys].notna(), "n/a").astype(str)
    return pd.MultiIndex.from_frame(frame).factorize()[0]


def geometry_split(
    groups: np.ndarray, train_fraction: float, validation_fraction: float, seed: int
) -> Split:
    """Whole groups to one set: groups in random order fill train, then validation, then test."""
    groups = np.asarray(groups)
    ids, inverse, sizes = np.unique(groups, return_inverse=True, return_counts=True)
    order = np.random.default_rng(seed).permutation(len(ids))
    before = np.cumsum(sizes[order]) - sizes[order]  # rows already placed when a group comes
    n = len(groups)
    dest = np.where(
        before < train_fraction * n,
        0,
        np.where(before < (train_fraction + validation_fraction) * n, 1, 2),
    )
    set_of_group = np.empty(len(ids), dtype=np.int64)
    set_of_group[order] = dest
    row_set = set_of_group[inverse]
    return Split(*(np.flatnonzero(row_set == k) for k in range(3)))


# -- model ---------------------------------------------------------------------------------


class Trained(NamedTuple):
    """A booster cut to its best round, with the per-round evaluation log."""

    booster: Any  # xgboost.Booster
    best_iteration: int  # 0-based; the booster holds rounds 0..best_iteration
    rounds_run: int
    eval_log: dict[str, dict[str, list[float]]]


def _dmatrix(X: np.ndarray, y: np.ndarray | None = None, nthread: int = 2) -> Any:
    import xgboost as xgb

    return xgb.DMatrix(X, label=y, feature_names=list(FEATURES), missing=np.nan, nthread=nthread)


def train_model(X: np.ndarray, y: np.ndarray, split: Split, settings: ModelSettings) -> Trained:
    """Boost on the training rows, stop early on the validation log loss."""
    import xgboost as xgb

    dtrain = _dmatrix(X[split.train], y[split.train], settings.nthread)
    dval = _dmatrix(X[split.validation], y[split.validation], settings.nthread)
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


def predict_proba(booster: Any, X: np.ndarray, nthread: int = 2) -> np.ndarray:
    """Class probabilities (rows x q), renormalised in float64 (XGBoost sums in float32)."""
    prob = np.asarray(booster.predict(_dmatrix(X, nthread=nthread)), dtype=np.float64)
    return prob / prob.sum(axis=1, keepdims=True)


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


def feature_importance(booster: Any) -> dict[str, Any]:
    """Split counts ("weight", Figure 3C) and gains per feature and per `IMPORTANCE_GROUPS` entry."""
    weight = booster.get_score(importance_type="weight")
    total = booster.get_score(importance_type="total_gain")

    def entry(names: Sequence[str]) -> dict[str, float]:
        w = float(sum(weight.get(n, 0.0) for n in names))
        t = float(sum(total.get(n, 0.0) for n in names))
        return {"weight": w, "gain": t / w if w else 0.0, "total_gain": t}

    features = {f: entry([f]) for f in FEATURES}
    grouped = {g: entry(m) for g, m in IMPORTANCE_GROUPS.items()}

    def rank(key: str) -> list[str]:
        return sorted(grouped, key=lambda g: (-grouped[g][key], g))

    return {
        "features": features,
        "grouped": grouped,
        "ranking_weight": rank("weight"),
        "ranking_total_gain": rank("total_gain"),
    }


# -- descriptive statistics ----------------------------------------------------------------


def stiff_vs_soft(rows: pd.DataFrame) -> tuple[dict[str, Any], pd.DataFrame]:
    """Pair stiff and soft results of the same geometry, orientation and stage.

    Returns per wound shape the number of pairs, how often stiff > soft, < soft or tied, the
    fraction stiff > soft, and a two-sided sign test (binomial, p = 1/2, ties dropped); and
    the pairs themselves (for the figure).
    """
    from scipy.stats import binomtest

    key = ["geometry_id", "orientation_deg", "stage"]
    cols = [*key, "wound_shape", STRESS]
    skin = rows["skin_type"].astype(str)
    stiff, soft = rows.loc[skin == "stiff", cols], rows.loc[skin == "soft", cols]
    pairs = stiff.merge(soft.drop(columns="wound_shape"), on=key, suffixes=("_stiff", "_soft"))
    pairs = pairs.rename(columns={f"{STRESS}_stiff": "stiff_kPa", f"{STRESS}_soft": "soft_kPa"})
    out: dict[str, Any] = {}
    for shape in sorted(pairs["wound_shape"].astype(str).unique()):
        p = pairs[pairs["wound_shape"].astype(str) == shape]
        greater = int((p["stiff_kPa"] > p["soft_kPa"]).sum())
        less = int((p["stiff_kPa"] < p["soft_kPa"]).sum())
        n = len(p)
        out[shape] = {
            "pairs": n,
            "stiff_greater": greater,
            "soft_greater": less,
            "ties": n - greater - less,
            "fraction_stiff_greater": greater / n,
            "sign_test_p": float(binomtest(greater, greater + less, 0.5).pvalue)
            if greater + less
            else None,
        }
    return out, pairs.reset_index(drop=True)


def normalised_locations(rows: pd.DataFrame) -> pd.DataFrame:
    """Where the maximum sits, scaled by the patch (rows with a location only).

    ``y_along`` = (y + L) / 2L: 0 and 1 at the patch ends, the closure zone's ends at 1/3 and
    2/3. ``x_across`` = (x - w/2) / (L + w/2): 0 on the wound's mid-plane, -1 and +1 at the
    lateral faces. ``z_depth`` = -z / T: 0 at the skin surface, 1 at the bottom face.
    """
    loc = rows.dropna(subset=list(LOCATION_COLUMNS))
    L, w, T = (
        loc[c].to_numpy(dtype=float)
        for c in ("patch_half_length_mm", "wound_width_mm", "total_thickness_mm")
    )
    stage = loc["stage"].to_numpy()
    group = np.full(len(loc), "", dtype=object)
    for name, stages in STAGE_GROUPS:
        group[np.isin(stage, stages)] = name
    return pd.DataFrame(
        {
            "stage_group": group,
            "y_along": (loc["max_location_y_mm"].to_numpy(dtype=float) + L) / (2 * L),
            "x_across": (loc["max_location_x_mm"].to_numpy(dtype=float) - w / 2) / (L + w / 2),
            "z_depth": -loc["max_location_z_mm"].to_numpy(dtype=float) / T,
        }
    )


# -- one scheme end to end -----------------------------------------------------------------


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


def _ranges(rows: pd.DataFrame, X: np.ndarray) -> dict[str, dict[str, list[float]]]:
    """Per wound shape, [min, max] of every numeric feature over the given rows."""
    out: dict[str, dict[str, list[float]]] = {}
    shape_col = FEATURES.index("wound_shape")
    for shape, code in SHAPE_CODES.items():
        sub = X[X[:, shape_col] == code]
        if len(sub) == 0:
            continue
        out[shape] = {}
        for j, name in enumerate(FEATURES):
            vals = sub[:, j][np.isfinite(sub[:, j])]
            if name in ("wound_shape", "skin_type", "stage") or len(vals) == 0:
                continue
            out[shape][name] = [float(vals.min()), float(vals.max())]
    return out


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
    trained = train_model(X, y, split, settings)
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
    train_rows = rows.iloc[split.train]
    meta = {
        "format": MODEL_FORMAT,
        "scheme": scheme,
        "features": list(FEATURES),
        "shape_codes": dict(SHAPE_CODES),
        "skin_codes_c_kPa": {
            k: float(v) for k, v in skins.items() if k in set(train_rows["skin_type"].astype(str))
        },
        "stages": sorted(int(s) for s in train_rows["stage"].unique()),
        "ranges": _ranges(train_rows, X[split.train]),
        "quantiles": q,
        "quantile_edges_kPa": edges.tolist(),
        "stress": STRESS,
        "best_iteration": trained.best_iteration,
        "settings": dataclasses.asdict(settings),
        "training_rows": int(len(split.train)),
        "woundsweep_version": __version__,
    }
    return SchemeFit(scheme, split, edges, y, trained, probs["test"], metrics, meta)


# -- the whole analysis --------------------------------------------------------------------


class AnalysisOutput(NamedTuple):
    """What `run_analysis` wrote."""

    out_dir: Path
    metrics: dict[str, Any]
    files: list[Path]


def _json_bytes(obj: Any) -> bytes:
    return (json.dumps(obj, indent=1, allow_nan=False) + "\n").encode()


def run_analysis(
    run_dir: str | Path,
    overrides: Mapping[str, Any] | None = None,
    schemes: Sequence[str] = SCHEMES,
    out_dir: str | Path | None = None,
    echo: Callable[[str], None] | None = None,
) -> AnalysisOutput:
    """Fit and evaluate each scheme; write metrics, models, figures and report.md.

    Settings: `ModelSettings` defaults, then the run's ``Sweep.analysis``, then ``overrides``.
    ``echo`` receives a line before each long step (training takes minutes on 70k rows).
    """
    say = echo or (lambda _line: None)
    import xgboost as xgb

    from . import figures
    from .report import write_report

    rd = Path(run_dir)
    if not rd.is_dir():
        raise AnalysisError(f"{rd}: no such run directory")
    for s in schemes:
        if s not in SCHEMES:
            raise AnalysisError(f"unknown split scheme {s!r} (expected one of {SCHEMES})")
    sweep_analysis, skins = _sweep_settings(rd)
    settings = resolve_settings(sweep_analysis, overrides)
    q = settings.quantiles
    results = load_results(rd)
    orphans = 0
    if (rd / "manifest.parquet").is_file():
        # Rows of jobs that a regenerated manifest no longer holds belong to another sweep.
        in_manifest = results["job_id"].isin(
            set(pd.read_parquet(rd / "manifest.parquet", columns=["job_id"])["job_id"])
        )
        orphans = int((~in_manifest).sum())
        results = results[in_manifest]
    rows, counts = select_rows(results)
    counts["rows_not_in_manifest"] = orphans
    if len(rows) < MIN_ROWS_PER_QUANTILE * q:
        raise AnalysisError(
            f"{len(rows)} usable rows: at least {MIN_ROWS_PER_QUANTILE * q} are needed for {q} quantiles "
            "and the train/validation/test splits"
        )
    X = encode_features(rows, skins)
    fits = []
    for s in schemes:
        say(f"training the {s} split model on {len(rows)} rows ({q} quantiles)...")
        fits.append(fit_scheme(s, rows, X, skins, settings))
    svs, pairs = stiff_vs_soft(rows)
    locs = normalised_locations(rows)
    stress = rows[STRESS].to_numpy(dtype=np.float64)
    metrics: dict[str, Any] = {
        "woundsweep_version": __version__,
        "xgboost_version": xgb.__version__,
        "stress": STRESS,
        "stress_units": "kPa",
        "features": list(FEATURES),
        "importance_groups": {k: list(v) for k, v in IMPORTANCE_GROUPS.items()},
        "settings": dataclasses.asdict(settings),
        "rows": counts,
        "stress_summary_kPa": {
            "min": float(stress.min()),
            "median": float(np.median(stress)),
            "max": float(stress.max()),
            "all_rows_quantile_edges": np.quantile(stress, np.linspace(0, 1, q + 1)).tolist(),
        },
        "schemes": {f.scheme: f.metrics for f in fits},
        "stiff_vs_soft": svs,
        "max_location": {
            "normalisation": {
                "y_along": "(y + L) / 2L; closure zone ends at 1/3 and 2/3",
                "x_across": "(x - w/2) / (L + w/2); 0 = wound mid-plane, +-1 = lateral faces",
                "z_depth": "-z / T; 0 = skin surface, 1 = bottom face",
            },
            "rows": {name: int((locs["stage_group"] == name).sum()) for name, _ in STAGE_GROUPS},
            "outside_unit_range": {
                c: int(((locs[c] < (-1 if c == "x_across" else 0)) | (locs[c] > 1)).sum())
                for c in ("y_along", "x_across", "z_depth")
            },
        },
    }
    out = Path(out_dir) if out_dir is not None else rd / "analysis"
    out.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    for f in fits:
        model_path = out / f"model_{f.scheme}.json"
        atomic_write_bytes(model_path, bytes(f.trained.booster.save_raw("json")))
        meta_path = out / f"model_{f.scheme}_meta.json"
        atomic_write_bytes(meta_path, _json_bytes(f.meta))
        files += [model_path, meta_path]
    say("writing figures...")
    figs = figures.write_all(out, fits, stress, rows["stage"].to_numpy(), pairs, svs, locs)
    files += figs
    metrics_path = out / "metrics.json"
    atomic_write_bytes(metrics_path, _json_bytes(metrics))
    files.append(metrics_path)
    report_path = out / "report.md"
    write_report(report_path, metrics, [p.name for p in figs])
    files.append(report_path)
    return AnalysisOutput(out, metrics, files)


# -- prediction ----------------------------------------------------------------------------


class LoadedModel(NamedTuple):
    """A saved booster and its metadata (feature ranges, codes, quantile edges)."""

    path: Path
    booster: Any
    meta: dict[str, Any]


class Prediction(NamedTuple):
    """One stage's answer: quantile 1..q, class probabilities, that quantile's stress range."""

    stage: int
    quantile: int
    probabilities: list[float]
    stress_range_kPa: tuple[float, float]
    extrapolated: list[str]


def resolve_model_path(path: str | Path, scheme: str | None = None) -> Path:
    """A model file, or the model of ``scheme`` (default: geometry, else random) in a run or analysis dir."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.is_dir():
        raise AnalysisError(f"{p}: no such model file or run directory")
    for d in (p / "analysis", p):
        for s in [scheme] if scheme else ["geometry", "random"]:
            if (d / f"model_{s}.json").is_file():
                return d / f"model_{s}.json"
    raise AnalysisError(f"{p}: no trained model found (run `woundsweep analyze` first)")


def load_model(path: str | Path, scheme: str | None = None) -> LoadedModel:
    """Load ``model_<scheme>.json`` and the ``model_<scheme>_meta.json`` beside it."""
    import xgboost as xgb

    model_path = resolve_model_path(path, scheme)
    meta_path = model_path.with_name(model_path.stem + "_meta.json")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError):
        raise AnalysisError(f"{meta_path}: missing or unreadable model metadata") from None
    if meta.get("format") != MODEL_FORMAT:
        raise AnalysisError(f"{meta_path}: not a woundsweep model description")
    booster = xgb.Booster()
    try:
        booster.load_model(str(model_path))
    except xgb.core.XGBoostError:
        raise AnalysisError(f"{model_path}: unreadable XGBoost model") from None
    return LoadedModel(model_path, booster, meta)


def _check_params(
    meta: dict[str, Any], params: Mapping[str, Any]
) -> tuple[dict[str, float], list[str]]:
    """Encode one parameter set; list what lies outside the training data."""
    shape = params["wound_shape"]
    if shape not in SHAPE_CODES:
        raise AnalysisError(f"wound shape {shape!r}: expected one of {sorted(SHAPE_CODES)}")
    own = "wound_depth_factor" if shape == "wedge" else "wound_aspect_factor"
    other = "wound_aspect_factor" if shape == "wedge" else "wound_depth_factor"
    if params.get(own) is None:
        raise AnalysisError(f"a {shape} wound needs {own}")
    if params.get(other) is not None:
        raise AnalysisError(f"{other} does not apply to a {shape} wound")
    skins = meta["skin_codes_c_kPa"]
    if params["skin_type"] not in skins:
        raise AnalysisError(
            f"skin type {params['skin_type']!r} was not in the training data {sorted(skins)}"
        )
    flagged: list[str] = []
    ranges = meta["ranges"].get(shape)
    if ranges is None:
        flagged.append(f"wound_shape={shape} (no {shape} wounds in the training data)")
        ranges = {}
    values: dict[str, float] = {
        "wound_shape": SHAPE_CODES[shape],
        "skin_type": float(skins[params["skin_type"]]),
    }
    for name in FEATURES:
        if name in ("wound_shape", "skin_type", "stage"):
            continue
        v = params.get(name)
        values[name] = float("nan") if v is None else float(v)
        if v is None or name not in ranges:
            continue
        lo, hi = ranges[name]
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        if not lo - tol <= float(v) <= hi + tol:
            flagged.append(f"{name}={float(v):g} (trained on {lo:g}..{hi:g})")
    return values, flagged


def predict(
    model: LoadedModel,
    params: Mapping[str, Any],
    stages: Sequence[int] | None = None,
    allow_extrapolation: bool = False,
) -> list[Prediction]:
    """Predict the stress quantile of one wound for the given stages (default: all trained).

    ``params`` holds the Table 1 parameters by manifest column name (``wound_shape`` and
    ``skin_type`` as names, the factor that does not apply to the shape as ``None``).
    Values outside the training data are refused unless ``allow_extrapolation``, and then
    flagged in each `Prediction`.
    """
    meta = model.meta
    values, flagged = _check_params(meta, params)
    stages = list(meta["stages"]) if stages is None else [int(s) for s in stages]
    out_of_range_stages = [s for s in stages if s not in meta["stages"]]
    stage_flags = [f"stage={s} (trained on stages {meta['stages']})" for s in out_of_range_stages]
    if (flagged or stage_flags) and not allow_extrapolation:
        raise AnalysisError(
            "outside the training data: "
            + "; ".join(flagged + stage_flags)
            + " (use --allow-extrapolation)"
        )
    X = np.array(
        [[values[f] if f != "stage" else float(s) for f in FEATURES] for s in stages],
        dtype=np.float64,
    )
    prob = predict_proba(model.booster, X, nthread=1)
    edges = meta["quantile_edges_kPa"]
    out = []
    for s, p in zip(stages, prob):
        k = int(np.argmax(p))
        flags = flagged + [f for f, st in zip(stage_flags, out_of_range_stages) if st == s]
        out.append(
            Prediction(int(s), k + 1, [float(v) for v in p], (edges[k], edges[k + 1]), flags)
        )
    return out

"""The stress-quantile model of a result store (the paper's Figure 3) and its evaluation.

Rows are the converged (job, stage) results with a positive maximal stress; the features
are the adjustable parameters of Table 1 plus the stage; the target is the stress quantile
class. Two split schemes, ``random`` (the paper's) and ``geometry`` (no physical geometry in
two sets), are fitted with XGBoost and evaluated side by side. Stresses are in kPa, lengths
in mm.

Modules: `settings` (features and constants), `data` (rows from the store's
validated reader, the model matrix), `splits` (quantile classes, the two schemes),
`training` (XGBoost), `evaluation` (scores, importances, TreeSHAP), `paper` (stiff against
soft, locations of the maximum), `fitting` (one scheme end to end, `SchemeFit`),
`regression` (the stress surrogate of log p99) and `conformal` (its split-conformal
intervals), `failure` (the failure-probability model), `sensitivity` (Sobol indices,
SALib), `profile_locations` (Figure 2 from the profile lines), `mesh_sensitivity`
(matched geometries across mesh size factors), `pipeline` (`run_analysis`), `model_io`
(model files), `prediction`, `figures` (with `figures_profiles`, `figures_mesh`) and
`report`. Names are
re-exported lazily, so importing the package loads neither XGBoost nor matplotlib.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

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
    "Prediction",
    "SchemeFit",
    "Split",
    "Trained",
    "WoundPrediction",
    "assign_quantiles",
    "encode_features",
    "evaluate",
    "fit_failure",
    "fit_surrogate",
    "feature_importance",
    "fit_scheme",
    "geometry_groups",
    "geometry_split",
    "load_model",
    "load_results",
    "normalised_locations",
    "predict",
    "predict_proba",
    "predict_wound",
    "quantile_edges",
    "random_split",
    "resolve_model_path",
    "run_analysis",
    "select_rows",
    "shap_importance",
    "sobol_indices",
    "skin_codes",
    "stiff_vs_soft",
    "train_model",
]

_HOME = {
    "FEATURES": "settings",
    "IMPORTANCE_GROUPS": "settings",
    "MIN_ROWS_PER_QUANTILE": "settings",
    "REQUIRED_COLUMNS": "settings",
    "SCHEMES": "settings",
    "SHAPE_CODES": "settings",
    "STRESS": "settings",
    "encode_features": "data",
    "load_results": "data",
    "select_rows": "data",
    "skin_codes": "data",
    "Split": "splits",
    "assign_quantiles": "splits",
    "geometry_groups": "splits",
    "geometry_split": "splits",
    "quantile_edges": "splits",
    "random_split": "splits",
    "Trained": "training",
    "predict_proba": "training",
    "train_model": "training",
    "evaluate": "evaluation",
    "feature_importance": "evaluation",
    "normalised_locations": "paper",
    "stiff_vs_soft": "paper",
    "SchemeFit": "fitting",
    "fit_scheme": "fitting",
    "AnalysisOutput": "pipeline",
    "run_analysis": "pipeline",
    "LoadedModel": "model_io",
    "load_model": "model_io",
    "resolve_model_path": "model_io",
    "Prediction": "prediction",
    "WoundPrediction": "prediction",
    "predict": "prediction",
    "predict_wound": "prediction",
    "fit_surrogate": "regression",
    "fit_failure": "failure",
    "shap_importance": "evaluation",
    "sobol_indices": "sensitivity",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

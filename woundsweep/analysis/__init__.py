"""The stress-quantile model of a result store (the paper's Figure 3) and its evaluation.

Rows are the converged (job, stage) results with a positive maximal stress; the features
are the adjustable parameters of Table 1 (and the fusiform excision's length factor when
excisions are among the rows) plus the stage; the target is the stress quantile
class. Two split schemes, ``random`` (the paper's) and ``geometry`` (no physical geometry in
two sets), are fitted with XGBoost and evaluated side by side. Stresses are in kPa, lengths
in mm.

Modules: `settings` (features and constants), `data` (rows from the store's
validated reader, the model matrix), `splits` (quantile classes, the two schemes),
`training` (XGBoost), `evaluation` (scores, importances, TreeSHAP), `paper` (stiff against
soft, locations of the maximum), `fitting` (one scheme end to end, `SchemeFit`),
`regression` (the stress surrogate of log p99; `surrogate` its common interface,
`interpolant` the Gaussian-process kind) and `conformal` (its split-conformal intervals),
`offgrid` (runs between the grid's values: calibration and test), `failure` (the
failure-probability model), `sensitivity` (Sobol indices,
SALib), `profile_locations` (Figure 2 from the profile lines), `mesh_sensitivity`
(matched geometries across mesh size factors), `pipeline` (`run_analysis`), `model_io`
(model files), `prediction`, `figures` (with `figures_profiles`, `figures_mesh`) and
`report`. Names are
re-exported lazily, so importing the package loads neither XGBoost nor matplotlib.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "settings": ("FEATURES", "FUSIFORM_FEATURES", "IMPORTANCE_GROUPS",
                     "MIN_ROWS_PER_QUANTILE", "REQUIRED_COLUMNS", "SCHEMES", "SHAPE_CODES",
                     "STRESS", "model_features"),
        "data": ("encode_features", "load_results", "select_rows", "skin_codes"),
        "splits": ("Split", "assign_quantiles", "geometry_groups", "geometry_split",
                   "quantile_edges", "random_split"),
        "training": ("Trained", "predict_proba", "train_model"),
        "evaluation": ("evaluate", "feature_importance", "shap_importance"),
        "paper": ("normalised_locations", "stiff_vs_soft"),
        "fitting": ("SchemeFit", "fit_scheme"),
        "pipeline": ("AnalysisOutput", "run_analysis"),
        "model_io": ("LoadedModel", "load_model", "resolve_model_path"),
        "prediction": ("Prediction", "WoundPrediction", "predict", "predict_wound"),
        "regression": ("fit_surrogate",),
        "failure": ("fit_failure",),
        "sensitivity": ("sobol_indices",),
    },
)  # fmt: skip

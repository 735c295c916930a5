"""What the stress-quantile model is built from, and its tunable settings.

The features are the adjustable parameters of Table 1 plus the stage; the target is the
quantile class of ``STRESS`` (the volume-weighted 99th percentile of von Mises, kPa).
Its tunable settings are `woundsweep.config.analysis.ModelSettings`.

A model of trenches alone (the paper's grid) has the columns `FEATURES`; one whose rows hold
fusiform excisions has `FUSIFORM_FEATURES` (the excision's length factor added), so a trench
store trains exactly the model it trained before the excision existed (`model_features`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ..core.schema import FailureClass

__all__ = [
    "FEATURES",
    "FUSIFORM_FEATURES",
    "IMPORTANCE_GROUPS",
    "LOCATION_COLUMNS",
    "CONVERGENCE_FAILURES",
    "COVERAGE_LEVELS",
    "DUPLICATE_COLUMNS",
    "DUPLICATE_RTOL",
    "JOB_FEATURES",
    "MIN_FAILED_JOBS",
    "SHAPE_FACTORS",
    "MIN_ROWS_PER_QUANTILE",
    "REQUIRED_COLUMNS",
    "SCHEMES",
    "SHAPE_CODES",
    "STAGE_GROUPS",
    "STRESS",
    "job_features",
    "model_features",
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
# The excision's own factor: its length as a multiple of the width (its depth factor is the
# wedge's column, the depth as a fraction of T for both).
FUSIFORM_FEATURES: tuple[str, ...] = (
    *FEATURES[: FEATURES.index("wound_aspect_factor") + 1],
    "wound_length_factor",
    *FEATURES[FEATURES.index("wound_aspect_factor") + 1 :],
)
SHAPE_CODES: dict[str, float] = {"cylindrical": 0.0, "wedge": 1.0, "fusiform": 2.0}
# Each shape's own factors (the others are NaN in its rows): the sweep file's shape axes.
SHAPE_FACTORS: dict[str, tuple[str, ...]] = {
    "cylindrical": ("wound_aspect_factor",),
    "wedge": ("wound_depth_factor",),
    "fusiform": ("wound_length_factor", "wound_depth_factor"),
}
# The paper's most important "feature" was one column holding the wedge depth factor or the
# cylinder height offset. Importances of our two columns are summed into one "wound_depth"
# entry for the ranking (split counts and total gains add; average gain = total / count).
# A group enters a model's importances only when one of its members is a model column.
IMPORTANCE_GROUPS: dict[str, tuple[str, ...]] = {
    "wound_depth": ("wound_depth_factor", "wound_aspect_factor"),
    **{
        f: (f,) for f in FUSIFORM_FEATURES if f not in ("wound_depth_factor", "wound_aspect_factor")
    },
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
# Stage groups of the location statistics and figures (Figure 2).
STAGE_GROUPS = (("stage 1", (1,)), ("stage 2", (2,)), ("stages 3-6", (3, 4, 5, 6)))
# Nominal levels whose empirical coverage on the test geometries metrics.json reports.
COVERAGE_LEVELS = (0.8, 0.95)
# The failure model's features: a job's parameters (no stage: the job fails as a whole).
JOB_FEATURES: tuple[str, ...] = tuple(f for f in FEATURES if f != "stage")
# Job outcomes that count as "did not converge" (iteration or time budget spent); crashes,
# out-of-memory, mesh failures and invalid input say nothing about convergence and are left out.
CONVERGENCE_FAILURES = (FailureClass.NOT_CONVERGED.value, FailureClass.TIMEOUT.value)
# Fewer failed (or converged) jobs than this train no failure model; the report says so.
MIN_FAILED_JOBS = 10
# A row repeats an earlier stage's state of its job when each of these columns (those the
# store has, finite in both) agrees within DUPLICATE_RTOL relative (stages 4-6 re-solve stage
# 3's loads, and where the contact does not engage they end in the same state). Such rows
# are one state counted several times: left out of the models unless kept.
DUPLICATE_COLUMNS = ("max_von_mises_kPa", "min_J", "closure_gap_max_mm", "contact_force_mN")
DUPLICATE_RTOL = 1e-6


def model_features(shapes: Iterable[object]) -> tuple[str, ...]:
    """The model columns for rows of these wound shapes: `FEATURES` for trenches alone,
    `FUSIFORM_FEATURES` once a fusiform excision is among them."""
    return FUSIFORM_FEATURES if "fusiform" in set(shapes) else FEATURES


def job_features(features: Sequence[str]) -> tuple[str, ...]:
    """The failure model's columns of a model with ``features``: all but the stage."""
    return tuple(f for f in features if f != "stage")

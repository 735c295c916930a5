"""One wound's answer from the saved models: the paper's stress quantile (classifier), the
stress estimate with its conformal interval (surrogate) and the failure probability.

Values outside the training ranges are refused, or answered and flagged.

The orientation t is answered continuously: at an orientation between two trained ones (25
degrees on a 0/45/90 grid) every model is evaluated at both neighbours and the answers are
weighted linearly in cos 2t (`angle_weights`: every result is a function of cos 2t; class
probabilities, log stress, failure probability; the interval is the calibrated half-width
around the weighted log stress). The tree models
alone are piecewise constant in the angle, with their steps at the trained values, so
their own answer between two trained angles is one neighbour's, whichever side of a split it
falls. A Gaussian-process surrogate (``continuous``) interpolates by itself: it is evaluated
at the asked angle. Other parameters between the grid's values are answered by the models
as they are and flagged as interpolated.

Without a mesh size factor the answer is that of the finest mesh trained on for the shape
(the largest factor), and says so.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from ..core.errors import AnalysisError
from .interpolant import cos_2t
from .model_io import LoadedModel
from .settings import FEATURES, SHAPE_CODES, SHAPE_FACTORS
from .training import booster_features, predict_proba

__all__ = [
    "ANGLE",
    "MAX_PARAMETER",
    "Prediction",
    "WoundPrediction",
    "angle_weights",
    "check_level",
    "predict",
    "predict_wound",
]

# The models compute in float32: 1e308 becomes infinity there. No wound parameter (mm, factors,
# degrees) comes near this bound.
MAX_PARAMETER = 1e6
# The parameter answered continuously between its trained values.
ANGLE = "orientation_deg"


class Prediction(NamedTuple):
    """One stage's answer: quantile 1..q, class probabilities, that quantile's stress range;
    the surrogate's estimate and interval at ``level`` (kPa; ``None`` bounds: no interval,
    ``interval_note`` says why: too few calibration rows for the level, or an extrapolated
    answer, which the calibration does not cover), ``None`` without a surrogate; the
    quantile class the surrogate's estimate falls in (``estimate_quantile``)."""

    stage: int
    quantile: int
    probabilities: list[float]
    stress_range_kPa: tuple[float, float]
    extrapolated: list[str]
    stress_kPa: float | None = None
    interval_kPa: tuple[float | None, float | None] | None = None
    level: float | None = None
    interval_note: str = ""
    estimate_quantile: int | None = None


class WoundPrediction(NamedTuple):
    """Every stage's `Prediction`, the job's failure probability (``None`` without a failure
    model, ``failure_note`` says why), the interpolation flags, the mesh size factor answered
    for (``mesh_size_default``: the finest trained, none was given) and the trained
    orientations the answer weighs (``[orientation_deg, weight]`` pairs)."""

    stages: list[Prediction]
    failure_probability: float | None
    failure_note: str
    interpolated: list[str]
    mesh_size_factor: float | None = None
    mesh_size_default: bool = False
    orientation_weights: list[tuple[float, float]] = []
    # What the answer rests on (`answer_basis`): training rows and ranges, calibration rows
    # and geometries.
    basis: dict[str, Any] = {}


def _check_factors(params: Mapping[str, Any]) -> str:
    """The wound's shape, once its own factors are given and the others' are not."""
    shape = params["wound_shape"]
    if shape not in SHAPE_CODES:
        raise AnalysisError(f"wound shape {shape!r}: expected one of {sorted(SHAPE_CODES)}")
    own = SHAPE_FACTORS[shape]
    for name in sorted({f for fs in SHAPE_FACTORS.values() for f in fs}):
        if name in own and params.get(name) is None:
            raise AnalysisError(f"a {shape} wound needs {name}")
        if name not in own and params.get(name) is not None:
            raise AnalysisError(f"{name} does not apply to a {shape} wound")
    return shape


def _check_columns(meta: dict[str, Any], shape: str) -> str:
    """``shape``, once the model has a column for each of its factors (refused even with
    --allow-extrapolation otherwise: a model of trenches has none for the excision's length)."""
    features = list(meta.get("features", FEATURES))
    missing = [f for f in SHAPE_FACTORS[shape] if f not in features]
    if missing:
        raise AnalysisError(
            f"the model has no column for {', '.join(missing)}: it was trained without "
            f"{shape} wounds"
        )
    return shape


def finest_mesh(meta: dict[str, Any], shape: str) -> float:
    """The largest (finest) mesh size factor of the shape's training rows."""
    span = meta["ranges"].get(shape, {}).get("mesh_size_factor")
    if span is None:
        raise AnalysisError(
            f"no {shape} wounds in the training data to take a mesh size factor from; "
            "give --mesh-size-factor"
        )
    return float(span[1])


# What `generate` accepts (docs/sweeps.md): no model answers a wound that cannot exist.
_POSITIVE = (
    "dermal_thickness_mm",
    "subcutis_thickness_factor",
    "patch_size_factor",
    "wound_width_factor",
    "mesh_size_factor",
)


def check_physical(params: Mapping[str, Any]) -> None:
    """Refuse (`AnalysisError`, with or without --allow-extrapolation) a wound the sweep file
    could not describe: a length or factor that must be positive and is not, a width factor
    above 2, a depth factor of 1 or more (the depth is a fraction of the thickness), an
    excision's length factor of 1 or less (its length is a multiple of its width), a negative
    cylinder offset, a mesh size factor above the finest (2)."""

    def get(name: str) -> float | None:
        v = params.get(name)
        return None if v is None else float(v)

    problems = [
        f"{n}={get(n):g} (must be positive)"
        for n in _POSITIVE
        if get(n) is not None and get(n) <= 0  # type: ignore[operator]
    ]
    width, mesh = get("wound_width_factor"), get("mesh_size_factor")
    depth, length, aspect = (
        get("wound_depth_factor"), get("wound_length_factor"), get("wound_aspect_factor")
    )  # fmt: skip
    if width is not None and width > 2:
        problems.append(f"wound_width_factor={width:g} (at most 2: the wound must fit the patch)")
    if mesh is not None and mesh > 2:
        problems.append(f"mesh_size_factor={mesh:g} (at most 2, the finest the mesher takes)")
    if depth is not None and not 0 < depth < 1:
        problems.append(f"wound_depth_factor={depth:g} (a fraction of the thickness: 0 to 1)")
    if length is not None and length <= 1:
        problems.append(f"wound_length_factor={length:g} (a multiple of the width: above 1)")
    if aspect is not None and aspect < 0:
        problems.append(f"wound_aspect_factor={aspect:g} (must not be negative)")
    if problems:
        raise AnalysisError("not a possible wound: " + "; ".join(problems))


def _in_terms(name: str, v: float, lo: float, hi: float, angle_to_langer: bool) -> str:
    """A flag for ``name`` = ``v`` outside [lo, hi], in the terms the user gave it."""
    if name == ANGLE and angle_to_langer:
        return f"angle to the Langer line {90 - v:g} deg (trained on {90 - hi:g}..{90 - lo:g} deg)"
    return f"{name}={v:g} (trained on {lo:g}..{hi:g})"


def _check_params(
    meta: dict[str, Any], params: Mapping[str, Any], angle_to_langer: bool = False
) -> tuple[dict[str, float], list[str]]:
    """Encode one parameter set; list what lies outside the training data."""
    shape = _check_columns(meta, _check_factors(params))
    features = list(meta.get("features", FEATURES))
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
    for name in features:
        if name in ("wound_shape", "skin_type", "stage"):
            continue
        v = params.get(name)
        values[name] = float("nan") if v is None else float(v)
        if v is not None and not abs(values[name]) <= MAX_PARAMETER:
            raise AnalysisError(  # refused even with --allow-extrapolation: no model answers it
                f"{name}={values[name]:g}: expected a magnitude of at most {MAX_PARAMETER:g}"
            )
        if v is None or name not in ranges:
            continue
        lo, hi = ranges[name]
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        if not lo - tol <= float(v) <= hi + tol:
            flagged.append(_in_terms(name, float(v), lo, hi, angle_to_langer))
    return values, flagged


def angle_weights(meta: dict[str, Any], shape: str, value: float) -> list[tuple[float, float]]:
    """The trained orientations an answer at ``value`` weighs, with their weights: the value
    itself (weight 1) on a trained orientation or outside the trained ones (or when the
    orientations were too many to record), else its two neighbours, linearly in cos 2t (every
    result is a function of cos 2t: `interpolant`'s symmetry; linearly in t where the two
    neighbours lie on both sides of a multiple of 90 deg)."""
    grid = meta.get("levels", {}).get(shape, {}).get(ANGLE)
    if not grid or not grid[0] < value < grid[-1]:
        return [(float(value), 1.0)]
    g = np.asarray(grid, dtype=np.float64)
    if np.min(np.abs(g - value)) <= 1e-9 * max(1.0, float(np.abs(g).max())):
        return [(float(value), 1.0)]
    k = int(np.searchsorted(g, value))
    a, b = g[k - 1], g[k]
    if np.floor(a / 90.0) == np.ceil(b / 90.0) - 1:  # cos 2t is monotone on [a, b]
        c = cos_2t([a, value, b])
        t = (c[1] - c[0]) / (c[2] - c[0])
    else:
        t = (value - a) / (b - a)
    return [(float(a), float(1.0 - t)), (float(b), float(t))]


def interpolation_flags(meta: dict[str, Any], params: Mapping[str, Any]) -> list[str]:
    """The parameters inside the trained range but between the grid's values."""
    levels = meta.get("levels", {}).get(params["wound_shape"], {})
    out = []
    for name, grid in levels.items():
        v = params.get(name)
        if v is None or not grid or not grid[0] <= float(v) <= grid[-1]:
            continue
        g = np.asarray(grid, dtype=np.float64)
        if np.min(np.abs(g - float(v))) > 1e-9 * max(1.0, float(np.abs(g).max())):
            k = int(np.searchsorted(g, float(v)))
            flag = f"{name}={float(v):g} (interpolated between trained values {g[k - 1]:g} and {g[k]:g})"
            if name == ANGLE:
                (_, wa), (_, wb) = angle_weights(meta, params["wound_shape"], float(v))
                flag += f": their answers weighted {wa:.3g} and {wb:.3g}, linearly in cos 2t"
            out.append(flag)
    return out


def check_level(level: float) -> None:
    """Refuse (`AnalysisError`) an interval level outside (0, 1)."""
    if not 0.0 < float(level) < 1.0:
        raise AnalysisError(f"interval level {level}: expected a value between 0 and 1")


def predict(
    model: LoadedModel,
    params: Mapping[str, Any],
    stages: Sequence[int] | None = None,
    allow_extrapolation: bool = False,
    level: float = 0.9,
) -> list[Prediction]:
    """Every stage's `Prediction` of `predict_wound`."""
    return predict_wound(model, params, stages, allow_extrapolation, level).stages


def _rows(values: Mapping[str, float], columns: Sequence[str], stages: Sequence[int]) -> np.ndarray:
    """One row per stage in the order of a booster's ``columns``."""
    return np.array(
        [[values[f] if f != "stage" else float(s) for f in columns] for s in stages],
        dtype=np.float64,
    )


def predict_wound(
    model: LoadedModel,
    params: Mapping[str, Any],
    stages: Sequence[int] | None = None,
    allow_extrapolation: bool = False,
    level: float = 0.9,
    angle_to_langer: bool = False,
) -> WoundPrediction:
    """Predict one wound for the given stages (default: all trained).

    ``params`` holds the Table 1 parameters by manifest column name (``wound_shape`` and
    ``skin_type`` as names, the factors that do not apply to the shape as ``None``;
    ``mesh_size_factor`` ``None`` for the finest trained). Values outside the training data
    are refused unless ``allow_extrapolation``, and then flagged in each `Prediction`;
    ``level`` in (0, 1) is the interval's nominal coverage. An orientation between two
    trained ones weighs their answers linearly (`angle_weights`). A wound that cannot exist
    (`check_physical`) is refused either way; ``angle_to_langer``: the user gave the
    orientation as the angle to the Langer line, and the flags say it so. An extrapolated
    answer has no interval (the calibration holds inside the training data only).
    """
    check_level(level)
    meta = model.meta
    shape = _check_columns(meta, _check_factors(params))
    check_physical(params)
    params = dict(params)
    default_mesh = params.get("mesh_size_factor") is None
    if default_mesh:
        params["mesh_size_factor"] = finest_mesh(meta, shape)
    values, flagged = _check_params(meta, params, angle_to_langer)
    if model.surrogate is not None:  # its training rows may differ (the random split's do)
        sur_meta: dict[str, Any] = {**meta, **{k: model.surrogate[1][k] for k in ("ranges", "features")
                               if k in model.surrogate[1]}}  # fmt: skip
        own = _check_params(sur_meta, params, angle_to_langer)[1]
        flagged += [f"surrogate: {f}" for f in own if f not in flagged]
    stages = list(meta["stages"]) if stages is None else [int(s) for s in stages]
    out_of_range_stages = [s for s in stages if s not in meta["stages"]]
    stage_flags = [f"stage={s} (trained on stages {meta['stages']})" for s in out_of_range_stages]
    if (flagged or stage_flags) and not allow_extrapolation:
        raise AnalysisError(
            "outside the training data: "
            + "; ".join(flagged + stage_flags)
            + " (use --allow-extrapolation)"
        )
    weights = angle_weights(meta, shape, values[ANGLE])
    prob = np.zeros((len(stages), int(meta["quantiles"])))
    p_fail: float | None = 0.0
    note = ""
    for angle, w in weights:
        at = {**values, ANGLE: angle}
        prob += w * predict_proba(
            model.booster, _rows(at, booster_features(model.booster), stages), nthread=1
        )
        p, note = _failure(model, at)
        p_fail = None if p is None or p_fail is None else p_fail + w * p
    log_est = _surrogate_log(model, values, weights, stages)
    estimate, bounds = _surrogate(model, log_est, stages, level)
    edges = meta["quantile_edges_kPa"]
    out = []
    for i, (s, p) in enumerate(zip(stages, prob)):
        p = p / p.sum()
        k = int(np.argmax(p))
        flags = flagged + [f for f, st in zip(stage_flags, out_of_range_stages) if st == s]
        interval = None if bounds is None else bounds[i]
        why = ""
        if interval is not None and interval[0] is None:
            why = "unbounded: too few calibration rows for the level"
        if flags and interval is not None:
            interval, why = (None, None), "none: extrapolated, outside what the calibration covers"
        est_class = None
        if estimate is not None:
            j = int(np.searchsorted(edges, estimate[i], side="right"))
            est_class = int(np.clip(j, 1, len(edges) - 1))
        out.append(
            Prediction(
                int(s), k + 1, [float(v) for v in p], (edges[k], edges[k + 1]), flags,
                None if estimate is None else estimate[i],
                interval,
                None if estimate is None else float(level),
                why,
                est_class,
            )
        )  # fmt: skip
    return WoundPrediction(
        out, p_fail, note, interpolation_flags(meta, params),
        float(params["mesh_size_factor"]), default_mesh, weights,
        answer_basis(model, shape, stages),
    )  # fmt: skip


def answer_basis(model: LoadedModel, shape: str, stages: Sequence[int]) -> dict[str, Any]:
    """What an answer rests on: the classifier's training rows and the shape's training
    ranges; the surrogate's training rows, its calibration rows (in all and per asked stage)
    and geometries (``None`` where a model file does not record them)."""
    meta = model.meta
    out: dict[str, Any] = {
        "classifier_training_rows": meta.get("training_rows"),
        "training_ranges": meta["ranges"].get(shape, {}),
    }
    if model.surrogate is not None:
        sur = model.surrogate[1]
        scores = sur["calibration_scores_log"]
        out.update(
            surrogate=model.surrogate[0].kind,
            surrogate_training_rows=sur.get("training_rows"),
            calibration_rows=sum(len(v) for v in scores.values()),
            calibration_rows_by_stage={str(s): len(scores.get(str(s), [])) for s in stages},
            calibration_geometries=sur.get("calibration_geometries"),
            calibration=sur.get("calibration"),
        )
    return out


def _surrogate_log(
    model: LoadedModel, values: Mapping[str, float], weights: Sequence[tuple[float, float]],
    stages: Sequence[int],
) -> tuple[np.ndarray, np.ndarray] | None:  # fmt: skip
    """The surrogate's log p99 (log kPa) and its scale per stage: weighted over the trained
    orientations ``weights``, or at the asked one for a continuous surrogate; None without."""
    if model.surrogate is None:
        return None
    sur = model.surrogate[0]
    if sur.continuous:
        weights = [(values[ANGLE], 1.0)]
    log_est, scale = np.zeros(len(stages)), np.zeros(len(stages))
    for angle, w in weights:
        mean, sd = sur.predict_log(_rows({**values, ANGLE: angle}, sur.features, stages))
        log_est, scale = log_est + w * mean, scale + w * sd
    return log_est, scale


def _surrogate(
    model: LoadedModel, answer: tuple[np.ndarray, np.ndarray] | None, stages: Sequence[int],
    level: float,
) -> tuple[list[float] | None, list[tuple[float | None, float | None]] | None]:  # fmt: skip
    """The surrogate's estimates (kPa) and interval bounds per stage around its log p99 and
    scale ``answer``; ``None`` without a surrogate."""
    if model.surrogate is None or answer is None:
        return None, None
    from .conformal import half_widths

    log_est, scale = answer
    hw = half_widths(model.surrogate[1]["calibration_scores_log"], stages, level) * scale
    est = [float(np.exp(v)) for v in log_est]
    bounds: list[tuple[float | None, float | None]] = [
        (float(np.exp(v - h)), float(np.exp(v + h))) if np.isfinite(h) else (None, None)
        for v, h in zip(log_est, hw)
    ]
    return est, bounds


def _failure(model: LoadedModel, values: Mapping[str, float]) -> tuple[float | None, str]:
    """The job's failure probability, or ``None`` and the reason."""
    if model.failure is None:
        return None, "no failure model beside this model (re-run `woundsweep analyze`)"
    booster, meta = model.failure
    if booster is None:
        return None, meta["statement"]
    from .failure import predict_failure

    columns = list(booster.feature_names or meta["features"])
    X = np.array([[values.get(f, np.nan) for f in columns]], dtype=np.float64)
    return float(predict_failure(booster, X, nthread=1)[0]), meta["statement"]

"""One wound's answer from the saved models: the paper's stress quantile (classifier), the
stress estimate with its conformal interval (surrogate) and the failure probability.

Values outside the training ranges are refused, or answered and flagged. Values inside a
range but between the grid's values (an orientation of 25 degrees on a 0/45/90 grid) are
answered and flagged as interpolated: the tree models are piecewise constant between grid
values, so such an answer is that of a neighbouring grid value's side of a split.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from ..core.errors import AnalysisError
from .model_io import LoadedModel
from .settings import FEATURES, SHAPE_CODES
from .training import predict_proba

__all__ = ["MAX_PARAMETER", "Prediction", "WoundPrediction", "predict", "predict_wound"]

# The models compute in float32: 1e308 becomes infinity there. No wound parameter (mm, factors,
# degrees) comes near this bound.
MAX_PARAMETER = 1e6


class Prediction(NamedTuple):
    """One stage's answer: quantile 1..q, class probabilities, that quantile's stress range;
    the surrogate's estimate and interval at ``level`` (kPa; a ``None`` bound is unbounded:
    too few calibration rows for the level), ``None`` without a surrogate."""

    stage: int
    quantile: int
    probabilities: list[float]
    stress_range_kPa: tuple[float, float]
    extrapolated: list[str]
    stress_kPa: float | None = None
    interval_kPa: tuple[float | None, float | None] | None = None
    level: float | None = None


class WoundPrediction(NamedTuple):
    """Every stage's `Prediction`, the job's failure probability (``None`` without a failure
    model, ``failure_note`` says why) and the interpolation flags."""

    stages: list[Prediction]
    failure_probability: float | None
    failure_note: str
    interpolated: list[str]


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
        if v is not None and not abs(values[name]) <= MAX_PARAMETER:
            raise AnalysisError(  # refused even with --allow-extrapolation: no model answers it
                f"{name}={values[name]:g}: expected a magnitude of at most {MAX_PARAMETER:g}"
            )
        if v is None or name not in ranges:
            continue
        lo, hi = ranges[name]
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        if not lo - tol <= float(v) <= hi + tol:
            flagged.append(f"{name}={float(v):g} (trained on {lo:g}..{hi:g})")
    return values, flagged


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
            out.append(
                f"{name}={float(v):g} (interpolated between trained values {g[k - 1]:g} and {g[k]:g})"
            )
    return out


def predict(
    model: LoadedModel,
    params: Mapping[str, Any],
    stages: Sequence[int] | None = None,
    allow_extrapolation: bool = False,
    level: float = 0.9,
) -> list[Prediction]:
    """Every stage's `Prediction` of `predict_wound`."""
    return predict_wound(model, params, stages, allow_extrapolation, level).stages


def predict_wound(
    model: LoadedModel,
    params: Mapping[str, Any],
    stages: Sequence[int] | None = None,
    allow_extrapolation: bool = False,
    level: float = 0.9,
) -> WoundPrediction:
    """Predict one wound for the given stages (default: all trained).

    ``params`` holds the Table 1 parameters by manifest column name (``wound_shape`` and
    ``skin_type`` as names, the factor that does not apply to the shape as ``None``).
    Values outside the training data are refused unless ``allow_extrapolation``, and then
    flagged in each `Prediction`; ``level`` in (0, 1) is the interval's nominal coverage.
    """
    if not 0.0 < float(level) < 1.0:
        raise AnalysisError(f"interval level {level}: expected a value between 0 and 1")
    meta = model.meta
    values, flagged = _check_params(meta, params)
    if model.surrogate is not None:  # its training rows may differ (the random split's do)
        own = _check_params({**meta, "ranges": model.surrogate[1]["ranges"]}, params)[1]
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
    X = np.array(
        [[values[f] if f != "stage" else float(s) for f in FEATURES] for s in stages],
        dtype=np.float64,
    )
    prob = predict_proba(model.booster, X, nthread=1)
    estimate, bounds = _surrogate(model, X, stages, level)
    edges = meta["quantile_edges_kPa"]
    out = []
    for i, (s, p) in enumerate(zip(stages, prob)):
        k = int(np.argmax(p))
        flags = flagged + [f for f, st in zip(stage_flags, out_of_range_stages) if st == s]
        out.append(
            Prediction(
                int(s), k + 1, [float(v) for v in p], (edges[k], edges[k + 1]), flags,
                None if estimate is None else estimate[i],
                None if bounds is None else bounds[i],
                None if estimate is None else float(level),
            )
        )  # fmt: skip
    p_fail, note = _failure(model, X[:1])
    return WoundPrediction(out, p_fail, note, interpolation_flags(meta, params))


def _surrogate(
    model: LoadedModel, X: np.ndarray, stages: Sequence[int], level: float
) -> tuple[list[float] | None, list[tuple[float | None, float | None]] | None]:
    """The surrogate's estimates (kPa) and interval bounds per stage; ``None`` without one."""
    if model.surrogate is None:
        return None, None
    from .conformal import half_widths
    from .regression import predict_log

    booster, meta = model.surrogate
    log_est = predict_log(booster, X, nthread=1)
    hw = half_widths(meta["calibration_scores_log"], stages, level)
    est = [float(np.exp(v)) for v in log_est]
    bounds = [
        (float(np.exp(v - h)), float(np.exp(v + h))) if np.isfinite(h) else (None, None)
        for v, h in zip(log_est, hw)
    ]
    return est, bounds


def _failure(model: LoadedModel, X: np.ndarray) -> tuple[float | None, str]:
    """The job's failure probability, or ``None`` and the reason."""
    if model.failure is None:
        return None, "no failure model beside this model (re-run `woundsweep analyze`)"
    booster, meta = model.failure
    if booster is None:
        return None, meta["statement"]
    from .failure import failure_matrix, predict_failure

    return float(predict_failure(booster, failure_matrix(X), nthread=1)[0]), meta["statement"]

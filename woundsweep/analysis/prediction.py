"""The stress quantile of one wound from a saved model, refusing or flagging extrapolation."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from ..errors import AnalysisError
from .model_io import LoadedModel
from .settings import FEATURES, SHAPE_CODES
from .training import predict_proba

__all__ = ["Prediction", "predict"]


class Prediction(NamedTuple):
    """One stage's answer: quantile 1..q, class probabilities, that quantile's stress range."""

    stage: int
    quantile: int
    probabilities: list[float]
    stress_range_kPa: tuple[float, float]
    extrapolated: list[str]


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

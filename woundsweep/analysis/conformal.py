"""Split-conformal prediction intervals for the stress surrogate (log p99, per stage).

Scores are absolute residuals ``|log p99 - prediction|`` on calibration rows whose
geometries the surrogate never saw, divided by the surrogate's scale of each row (1 for the
trees, the predictive SD for the Gaussian process: normalised scores, the half-width then
the score quantile times the row's scale). For level ``1 - a`` the half-width is the
``ceil((n + 1)(1 - a))``-th smallest of the ``n`` scores, which covers a new, exchangeable
row with probability at least ``1 - a`` (Vovk et al. 2005; Lei et al. 2018, "Distribution-
free predictive inference for regression"). Calibration is per stage (Mondrian): a stage
with too few scores for the level uses the scores of all stages; with too few of those the
interval is unbounded (``inf``). Intervals are symmetric in log stress, so multiplicative
in kPa.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["calibrate", "coverage", "half_width", "half_widths"]


def half_width(scores: Sequence[float] | np.ndarray, level: float) -> float:
    """The conformal half-width of ``scores`` at ``level`` in (0, 1); ``inf`` if too few."""
    s = np.sort(np.asarray(scores, dtype=np.float64))
    # Rounded first, so that e.g. 20 * 0.9 = 18.000000000000004 asks for the 18th score.
    k = math.ceil(round((len(s) + 1) * level, 9))
    return float(s[k - 1]) if 1 <= k <= len(s) else math.inf


def calibrate(stage: np.ndarray, residual: np.ndarray) -> dict[str, list[float]]:
    """Sorted absolute residuals per stage (keys are the stage numbers as text, for JSON)."""
    stage = np.asarray(stage, dtype=np.int64)
    score = np.abs(np.asarray(residual, dtype=np.float64))
    return {str(int(s)): np.sort(score[stage == s]).tolist() for s in np.unique(stage)}


def half_widths(
    scores: Mapping[str, Sequence[float]], stages: Sequence[int] | np.ndarray, level: float
) -> np.ndarray:
    """The half-width for each entry of ``stages``: its own stage's, else the pooled one."""
    pooled = half_width(
        np.concatenate([np.asarray(v, dtype=float) for v in scores.values()]), level
    )
    own = {k: half_width(v, level) for k, v in scores.items()}
    out = [own.get(str(int(s)), math.inf) for s in stages]
    return np.array([w if math.isfinite(w) else pooled for w in out], dtype=np.float64)


def coverage(
    y: np.ndarray, pred: np.ndarray, stage: np.ndarray, scores: Mapping[str, Sequence[float]],
    level: float, scale: np.ndarray | None = None,
) -> dict[str, object]:  # fmt: skip
    """Empirical coverage of the level-``level`` intervals on rows (``y``, ``pred`` in log kPa;
    ``scale``: each row's score unit, the half-width is the score quantile times it; 1 if None).

    Returns the nominal level, rows, covered rows, the empirical fraction, the median interval
    width as a factor (upper / lower bound in kPa) and the same per stage.
    """
    y, pred, stage = (np.asarray(a, dtype=np.float64) for a in (y, pred, stage))
    hw = half_widths(scores, stage, level)
    if scale is not None:
        hw = hw * np.asarray(scale, dtype=np.float64)
    inside = np.abs(y - pred) <= hw

    def summary(sel: np.ndarray) -> dict[str, object]:
        n = int(sel.sum())
        width = np.exp(2 * hw[sel]) if n else np.array([])
        return {
            "rows": n,
            "covered": int(inside[sel].sum()),
            "empirical": float(inside[sel].mean()) if n else None,
            "median_width_factor": float(np.median(width))
            if n and np.isfinite(width).all()
            else None,
        }

    return {
        "nominal": level,
        **summary(np.ones(len(y), dtype=bool)),
        "by_stage": {str(int(s)): summary(stage == s) for s in np.unique(stage)},
    }

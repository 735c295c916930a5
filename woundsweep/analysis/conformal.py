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

An empirical coverage carries its own uncertainty: the rows of one geometry (its stages,
skins and orientations) move together, so the effective sample is nearer the number of
geometries than of rows. `coverage_interval` gives the `INTERVAL_LEVEL` percentile interval
of a bootstrap over geometries (whole clusters resampled with replacement, `BOOTSTRAP_REPS`
times, seed fixed; with several test sets, each set's geometries resampled apart, a
stratified bootstrap), the calibration held fixed: the uncertainty of these intervals'
coverage on geometries like the tested ones, not of a fresh calibration's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = [
    "BOOTSTRAP_REPS",
    "INTERVAL_LEVEL",
    "calibrate",
    "covered",
    "coverage",
    "coverage_interval",
    "half_width",
    "half_widths",
]

# The coverage's own interval: its level, and the bootstrap's resamples.
INTERVAL_LEVEL = 0.9
BOOTSTRAP_REPS = 2000


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


def covered(
    y: np.ndarray, pred: np.ndarray, stage: np.ndarray, scores: Mapping[str, Sequence[float]],
    level: float, scale: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Whether each row lies inside its level-``level`` interval, and the half-widths (log)."""
    y, pred, stage = (np.asarray(a, dtype=np.float64) for a in (y, pred, stage))
    hw = half_widths(scores, stage, level)
    if scale is not None:
        hw = hw * np.asarray(scale, dtype=np.float64)
    return np.abs(y - pred) <= hw, hw


def coverage_interval(
    inside: Sequence[np.ndarray], groups: Sequence[np.ndarray], level: float = INTERVAL_LEVEL,
    reps: int = BOOTSTRAP_REPS, seed: int = 0,
) -> list[float] | None:  # fmt: skip
    """The ``level`` percentile interval of the coverage ``sum(covered) / sum(rows)`` over
    ``reps`` bootstrap resamples of whole clusters: ``inside[k]`` the rows' covered flags of
    test set k, ``groups[k]`` their cluster (geometry) labels; each set's clusters resampled
    apart (stratified). ``None`` without rows."""
    rng = np.random.default_rng(seed)
    hits, rows = np.zeros(reps), np.zeros(reps)
    for flags, labels in zip(inside, groups, strict=True):
        flags = np.asarray(flags, dtype=bool)
        if len(flags) == 0:
            continue
        inverse = np.unique(np.asarray(labels), return_inverse=True)[1].ravel()
        n = int(inverse.max()) + 1
        per_rows = np.bincount(inverse, minlength=n).astype(np.float64)
        per_hits = np.bincount(inverse, weights=flags.astype(np.float64), minlength=n)
        counts = rng.multinomial(n, np.full(n, 1.0 / n), size=reps)  # times each is drawn
        hits += counts @ per_hits
        rows += counts @ per_rows
    if not rows.any():
        return None
    tail = (1.0 - level) / 2
    lo, hi = np.quantile(hits / rows, [tail, 1.0 - tail])
    return [float(lo), float(hi)]


def coverage(
    y: np.ndarray, pred: np.ndarray, stage: np.ndarray, scores: Mapping[str, Sequence[float]],
    level: float, scale: np.ndarray | None = None, groups: np.ndarray | None = None,
) -> dict[str, object]:  # fmt: skip
    """Empirical coverage of the level-``level`` intervals on rows (``y``, ``pred`` in log kPa;
    ``scale``: each row's score unit, the half-width is the score quantile times it; 1 if None).

    Returns the nominal level, rows, covered rows, the empirical fraction, the median interval
    width as a factor (upper / lower bound in kPa) and the same per stage; with ``groups``
    (each row's geometry), the number of geometries and the coverage's `INTERVAL_LEVEL`
    bootstrap interval over them (``interval``; `coverage_interval`).
    """
    inside, hw = covered(y, pred, stage, scores, level, scale)
    stage = np.asarray(stage, dtype=np.float64)

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

    out: dict[str, object] = {"nominal": level, **summary(np.ones(len(inside), dtype=bool))}
    if groups is not None:
        out["geometries"] = int(len(np.unique(np.asarray(groups))))
        out["interval"] = coverage_interval([inside], [np.asarray(groups)])
        out["interval_level"] = INTERVAL_LEVEL
    out["by_stage"] = {str(int(s)): summary(stage == s) for s in np.unique(stage)}
    return out

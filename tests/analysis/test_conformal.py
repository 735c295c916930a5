"""The conformal intervals' coverage and its uncertainty (`woundsweep.analysis.conformal`), and
the cross-calibration by run (`woundsweep.analysis.offgrid.cross_calibration`), on synthetic
rows whose truth is known: clustered coverage flags of a known mean, and a stand-in surrogate
whose residuals and scales are set by hand."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from woundsweep.analysis.conformal import (
    INTERVAL_LEVEL,
    calibrate,
    coverage,
    coverage_interval,
    half_width,
)
from woundsweep.analysis.offgrid import OtherRows, coverage_text, cross_calibration, pool
from woundsweep.config.sweep import GEOMETRY_KEYS
from woundsweep.core.errors import AnalysisError


def _clustered(rng: np.random.Generator, clusters: int, size: int, p: float, spread: float):
    """Covered flags in ``clusters`` clusters of ``size`` rows: each cluster's own rate drawn
    from a Beta of mean ``p`` (``spread`` its share of the Bernoulli variance, the
    intra-cluster correlation), rows Bernoulli at their cluster's rate."""
    a = p * (1 - spread) / spread
    b = (1 - p) * (1 - spread) / spread
    rate = rng.beta(a, b, clusters)
    flags = rng.random((clusters, size)) < rate[:, None]
    return flags.ravel(), np.repeat(np.arange(clusters), size)


def test_cluster_bootstrap_interval_covers_the_true_coverage() -> None:
    """Rows of one cluster move together (intra-cluster correlation 0.15, as the off-grid
    rows of one geometry do): the 90 % interval over clusters holds the true mean coverage
    in about 90 % of repeated samples; one that treats the rows as independent does not."""
    rng = np.random.default_rng(7)
    p, hits, naive_hits, trials = 0.8, 0, 0, 300
    for _ in range(trials):
        flags, groups = _clustered(rng, clusters=30, size=30, p=p, spread=0.15)
        lo, hi = coverage_interval([flags], [groups], reps=500, seed=int(rng.integers(1 << 30)))
        hits += lo <= p <= hi
        est, se = flags.mean(), math.sqrt(flags.mean() * (1 - flags.mean()) / len(flags))
        naive_hits += abs(est - p) <= 1.645 * se
    # Binomial spread of 300 trials at 0.9: SD 1.7 points. Percentile intervals over 30
    # clusters run a little short of their level.
    assert 0.83 <= hits / trials <= 0.96, hits / trials
    assert naive_hits / trials < 0.6, naive_hits / trials


def test_cluster_bootstrap_by_hand() -> None:
    # Every cluster covers the same share: any resample has it, the interval is a point.
    flags = np.array([1, 1, 1, 0] * 5, dtype=bool)
    groups = np.repeat(np.arange(5), 4)
    assert coverage_interval([flags], [groups]) == [0.75, 0.75]
    # Two sets resampled apart (stratified): each all covered or all not, the pooled share
    # is fixed by the sets' sizes, whatever the resample.
    lo, hi = coverage_interval(
        [np.ones(6, bool), np.zeros(2, bool)], [np.arange(6), np.array([0, 0])]
    )
    assert lo == hi == pytest.approx(6 / 8)
    # Clusters that disagree: the interval spans, within the range of the cluster means.
    flags = np.array([1, 1, 0, 0, 1, 1, 1, 1], dtype=bool)
    lo, hi = coverage_interval([flags], [np.repeat(np.arange(4), 2)], level=INTERVAL_LEVEL)
    assert 0.0 <= lo < flags.mean() < hi <= 1.0
    assert coverage_interval([np.zeros(0, bool)], [np.zeros(0, int)]) is None


def test_coverage_reports_its_interval_and_geometries() -> None:
    rng = np.random.default_rng(3)
    n = 400
    y = rng.normal(0, 1, n)
    stage = np.tile([1, 2], n // 2)
    scores = calibrate(np.tile([1, 2], 150), rng.normal(0, 1, 300))
    groups = np.repeat(np.arange(40), 10)
    c = coverage(y, np.zeros(n), stage, scores, 0.8, None, groups)
    assert c["geometries"] == 40 and c["interval_level"] == INTERVAL_LEVEL
    lo, hi = c["interval"]  # type: ignore[misc]
    assert lo <= c["empirical"] <= hi  # type: ignore[operator]
    assert coverage_text(c).startswith(f"{c['empirical']:.3f} (90% {lo:.3f}-{hi:.3f})")
    assert "interval" not in coverage(y, np.zeros(n), stage, scores, 0.8)


class _Fixed:
    """A stand-in surrogate: each row's mean and scale stored in two extra model columns."""

    kind = "fixed"
    continuous = True
    features = ["mean", "sd"]

    def predict_log(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return X[:, 0].copy(), X[:, 1].copy()

    def to_bytes(self) -> bytes:
        return b""


def _run(name: str, rng: np.random.Generator, geometries: int, width: float) -> OtherRows:
    """A run of ``geometries`` geometries x 2 stages x 3 rows, log residuals normal with SD
    ``width`` times each row's scale (so normalised scores of SD ``width``)."""
    n = geometries * 6
    geom = np.repeat(np.arange(geometries), 6)
    rows = pd.DataFrame({k: 1.0 for k in GEOMETRY_KEYS}, index=range(n))
    rows["wound_width_factor"] = geom  # a distinct geometry per value
    rows["dermal_thickness_mm"] = 1.0 + (np.arange(n) % 3)  # t_d replicates: one geometry
    rows["stage"] = np.tile([1, 1, 1, 2, 2, 2], geometries)
    mean = rng.normal(3.0, 0.5, n)
    sd = rng.uniform(0.5, 2.0, n)
    rows["p99_von_mises_kPa"] = np.exp(mean + width * sd * rng.normal(0, 1, n))
    rows["geometry_id"] = [f"{name}-{g}" for g in geom]
    return OtherRows(name, rows, np.column_stack([mean, sd]))


def test_cross_calibration_counts_by_hand() -> None:
    rng = np.random.default_rng(11)
    a, b = _run("A", rng, 20, 1.0), _run("B", rng, 12, 1.0)
    x = cross_calibration(_Fixed(), [a, b])
    assert x["runs"] == ["A", "B"] and "pooled" in x["method"]
    for fold, test, cal in zip(x["folds"], (a, b), (b, a)):
        assert fold["test_run"] == test.source and fold["calibrated_on"] == [cal.source]
        assert fold["calibration_rows"] == len(cal.rows) and fold["rows"] == len(test.rows)
        assert fold["geometries"] == test.rows["wound_width_factor"].nunique()
        # The half-width by hand: the fold's calibration run's normalised scores per stage.
        y = np.log(test.rows["p99_von_mises_kPa"].to_numpy())
        score_cal = np.abs(np.log(cal.rows["p99_von_mises_kPa"].to_numpy()) - cal.X[:, 0])
        score_cal /= cal.X[:, 1]
        stage_cal, stage = cal.rows["stage"].to_numpy(), test.rows["stage"].to_numpy()
        for level in ("0.8", "0.95"):
            q = {s: half_width(score_cal[stage_cal == s], float(level)) for s in (1, 2)}
            hw = np.array([q[s] for s in stage]) * test.X[:, 1]
            inside = np.abs(y - test.X[:, 0]) <= hw
            assert fold["coverage"][level]["covered"] == int(inside.sum())
            assert fold["coverage"][level]["rows"] == len(y)
    pooled = x["pooled"]
    assert pooled["rows"] == len(a.rows) + len(b.rows) and pooled["geometries"] == 32
    for level in ("0.8", "0.95"):
        c = pooled["coverage"][level]
        assert c["covered"] == sum(f["coverage"][level]["covered"] for f in x["folds"])
        assert c["empirical"] == pytest.approx(c["covered"] / c["rows"])
        lo, hi = c["interval"]
        assert lo <= c["empirical"] <= hi
    with pytest.raises(AnalysisError, match="two calibration runs"):
        cross_calibration(_Fixed(), [a])
    # The intervals saved with the model: one run as it is, several pooled.
    assert pool([a]) is a
    both = pool([a, b])
    assert both.source == "A and B pooled" and len(both.rows) == len(both.X) == 32 * 6


def test_cross_calibration_sees_runs_whose_scores_differ() -> None:
    """Exchangeable runs: each fold near nominal. Runs whose normalised scores differ (one
    twice as wide): the narrow run over-covers, the wide one under-covers, and the pooled
    estimate lies between them, the spread of the folds showing the difference."""
    rng = np.random.default_rng(5)
    same = cross_calibration(_Fixed(), [_run("A", rng, 150, 1.0), _run("B", rng, 150, 1.0)])
    for fold in same["folds"]:
        assert fold["coverage"]["0.8"]["empirical"] == pytest.approx(0.8, abs=0.05)
    assert same["pooled"]["coverage"]["0.8"]["empirical"] == pytest.approx(0.8, abs=0.035)
    shifted = cross_calibration(
        _Fixed(), [_run("narrow", rng, 150, 1.0), _run("wide", rng, 150, 2.0)]
    )
    narrow, wide = (f["coverage"]["0.8"]["empirical"] for f in shifted["folds"])
    assert narrow > 0.95 and wide < 0.5
    assert wide < shifted["pooled"]["coverage"]["0.8"]["empirical"] < narrow

"""The stress surrogate, its conformal intervals, the failure model and the sensitivities,
on synthetic rows whose truth is known (the real manifest of `SMALL_SWEEP`, stresses from a
known function plus known noise, or pure noise), against hand calculations."""

from __future__ import annotations

import functools
import math

import numpy as np
import pandas as pd
import pytest
from synthetic_store import SMALL_SWEEP, depth_level, depth_stress, random_stress

from woundsweep.analysis import (
    FEATURES,
    encode_features,
    fit_failure,
    fit_surrogate,
    sobol_indices,
)
from woundsweep.analysis.conformal import half_width, half_widths
from woundsweep.analysis.regression import predict_log
from woundsweep.analysis.sensitivity import SobolInput, surrogate_sobol
from woundsweep.config.analysis import resolve_settings
from woundsweep.config.manifest import expand
from woundsweep.config.sweep import DEFAULTS, parse_sweep

# Few, fast rounds; a larger test share (30 % of the geometries) so that the coverage
# estimates rest on ~3,500 rows of ~65 geometries.
FAST = {"n_estimators": 40, "learning_rate": 0.3, "early_stopping_rounds": 5, "nthread": 2}
WIDE_TEST = {"train_fraction": 0.4, "validation_fraction": 0.3}
SKINS = {k: float(v["c_kPa"]) for k, v in DEFAULTS["materials"]["skin_types"].items()}
NOISE = 0.05  # depth_stress's log-normal sigma


@functools.cache
def _manifest() -> pd.DataFrame:
    return expand(parse_sweep(dict(SMALL_SWEEP), "synthetic.yaml"))


def _rows(stress: str, seed: int) -> tuple[pd.DataFrame, np.ndarray]:
    """Every job and stage of the manifest (11,664 rows), with a known stress."""
    m = _manifest()
    rows = m.loc[m.index.repeat(6)].reset_index(drop=True)
    rows["stage"] = np.tile(np.arange(1, 7), len(m))
    fn = depth_stress if stress == "depth" else random_stress
    rows["p99_von_mises_kPa"] = fn(rows, np.random.default_rng(seed))
    return rows, encode_features(rows, SKINS)


@functools.cache
def _fit(stress: str, seed: int = 1):
    rows, X = _rows(stress, seed)
    return fit_surrogate(rows, X, resolve_settings(FAST, WIDE_TEST)), rows, X


# -- conformal quantiles by hand -------------------------------------------------------------


def test_conformal_half_width_is_the_finite_sample_order_statistic() -> None:
    scores = np.random.default_rng(0).permutation(np.arange(1.0, 20.0))  # 1..19
    assert half_width(scores, 0.9) == 18.0  # ceil(20 * 0.9) = 18th smallest
    assert half_width(scores, 0.95) == 19.0
    assert half_width(scores, 0.96) == math.inf  # ceil(20 * 0.96) = 20 > 19 scores
    # Per stage; a stage with too few scores for the level falls back to all of them.
    per_stage = {"1": [0.1, 0.2, 0.3], "2": list(np.arange(1.0, 20.0))}
    # Stage 3 has none: the 12th (ceil(23 * 0.5)) of the 22 pooled scores, 9.
    assert half_widths(per_stage, [2, 1, 3], 0.5).tolist() == [10.0, 0.2, 9.0]
    pooled = half_width([0.1, 0.2, 0.3, *range(1, 20)], 0.9)
    assert half_widths(per_stage, [1], 0.9).tolist() == [pooled]


# -- the surrogate on a known truth --------------------------------------------------------


def test_known_function_and_noise_give_nominal_coverage_on_held_out_geometries() -> None:
    fit, rows, X = _fit("depth")
    sets = [set(rows["geometry_id"].iloc[idx]) for idx in fit.split]
    assert all(not (a & b) for i, a in enumerate(sets) for b in sets[i + 1 :])
    test = fit.split.test
    assert len(test) > 3000 and fit.metrics["split_geometries"]["test"] > 50
    y = np.log(rows["p99_von_mises_kPa"].to_numpy()[test])
    pred = predict_log(fit.booster, X[test])
    stage = rows["stage"].to_numpy()[test]
    scores = fit.meta["calibration_scores_log"]
    for level, z in ((0.8, 1.2816), (0.95, 1.9600)):
        reported = fit.metrics["test"]["coverage"][str(level)]
        hw = half_widths(scores, stage, level)
        covered = np.abs(y - pred) <= hw
        assert reported["covered"] == int(covered.sum()) and reported["rows"] == len(test)
        assert abs(covered.mean() - level) <= 0.03, (level, covered.mean())
        # The noise is the only uncertainty left: the half-width is its normal quantile.
        assert np.median(hw) == pytest.approx(z * NOISE, rel=0.25)


def test_pure_noise_gives_intervals_as_wide_as_the_data() -> None:
    fit, rows, _ = _fit("random", seed=2)
    y = np.log(rows["p99_von_mises_kPa"].to_numpy()[fit.split.test])
    for level in (0.8, 0.95):
        c = fit.metrics["test"]["coverage"][str(level)]
        assert abs(c["empirical"] - level) <= 0.03
        lo, hi = np.quantile(y, [(1 - level) / 2, (1 + level) / 2])
        # Width factor = exp(2 h); the data's central interval spans hi - lo in log stress.
        assert math.log(c["median_width_factor"]) == pytest.approx(hi - lo, rel=0.15)
    assert fit.metrics["test"]["r2_log"] < 0.05


def test_shap_ranks_depth_first_and_adds_up_to_the_prediction() -> None:
    import xgboost as xgb

    fit, rows, X = _fit("depth")
    shap = fit.metrics["importance"]["shap"]
    assert shap["ranking"][:2] == ["wound_depth", "stage"]
    contrib = fit.booster.predict(
        xgb.DMatrix(X[:500], feature_names=list(FEATURES)), pred_contribs=True
    )
    assert contrib.sum(axis=1) == pytest.approx(predict_log(fit.booster, X[:500]), abs=1e-4)


def test_sobol_of_the_surrogate_matches_the_known_variance_shares() -> None:
    fit, rows, _ = _fit("depth")
    sob = surrogate_sobol(fit.booster, fit.meta, 1024, seed=0)
    assert sob["ranking_total"][:2] == ["wound_depth", "stage"]
    # log stress = 3 d + log(1 + 0.05 (stage - 1)) + noise, d and stage uniform on the grid.
    v_depth = np.var(3.0 * np.array([0.3, 0.5, 0.7]))
    v_stage = np.var(np.log(1 + 0.05 * np.arange(6)))
    idx = sob["indices"]
    assert idx["wound_depth"]["S1"] == pytest.approx(v_depth / (v_depth + v_stage), abs=0.03)
    assert idx["stage"]["ST"] == pytest.approx(v_stage / (v_depth + v_stage), abs=0.03)
    for name in ("skin_type", "orientation_deg", "dermal_thickness_mm", "wound_shape"):
        assert idx[name]["ST"] < 0.01, name
    assert sob["fixed"] == {"mesh_size_factor": 0.5}
    assert set(np.round(depth_level(rows), 9)) == {0.3, 0.5, 0.7}


def test_sobol_indices_of_the_ishigami_function() -> None:
    a, b = 7.0, 0.1

    def ishigami(U: np.ndarray) -> np.ndarray:
        x = SobolInput("x", -math.pi, math.pi).scale(U)
        return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])

    # Known variances (Ishigami & Homma 1990; Sobol' & Levitan 1999).
    p4, p8 = math.pi**4, math.pi**8
    v1, v2, v13 = 0.5 * (1 + b * p4 / 5) ** 2, a**2 / 8, b**2 * p8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    res = sobol_indices(ishigami, ["x1", "x2", "x3"], 4096, seed=3)["indices"]
    expect = {"x1": (v1 / v, (v1 + v13) / v), "x2": (v2 / v, v2 / v), "x3": (0.0, v13 / v)}
    assert expect["x1"] == pytest.approx((0.3139, 0.5576), abs=1e-3)
    for name, (s1, st) in expect.items():
        assert res[name]["S1"] == pytest.approx(s1, abs=0.05), name
        assert res[name]["ST"] == pytest.approx(st, abs=0.05), name


def test_discrete_inputs_take_each_level_equally_often() -> None:
    c = SobolInput("stage", 0.0, 1.0, (1.0, 2.0, 3.0))
    u = (np.arange(3000) + 0.5) / 3000
    assert np.bincount(c.scale(u).astype(int)).tolist() == [0, 1000, 1000, 1000]
    assert c.scale(np.array([1.0])).tolist() == [3.0]


# -- the failure model -------------------------------------------------------------------


def _jobs(p_fail: np.ndarray, seed: int) -> pd.DataFrame:
    jobs = _manifest().copy()
    jobs["stage"] = 1
    failed = np.random.default_rng(seed).random(len(jobs)) < p_fail
    jobs["failure_class"] = np.where(failed, "not-converged", "converged")
    return jobs


def test_failure_model_finds_the_parameter_that_drives_failures() -> None:
    m = _manifest()
    thick = (m["dermal_thickness_mm"] == 2).to_numpy()
    jobs = _jobs(np.where(thick, 0.5, 0.02), seed=4)
    jobs.loc[jobs.index[:5], "failure_class"] = "crashed"  # not a convergence outcome
    fit = fit_failure(jobs, SKINS, resolve_settings(FAST))
    assert fit.metrics["trained"] and fit.booster is not None
    assert fit.metrics["jobs"] == len(m) - 5
    assert fit.metrics["jobs_by_failure_class"]["crashed"] == 5
    assert fit.metrics["test"]["auc"] > 0.8
    assert fit.metrics["importance"]["ranking_total_gain"][0] == "dermal_thickness_mm"


def test_too_few_failures_train_no_failure_model() -> None:
    jobs = _jobs(np.zeros(len(_manifest())), seed=0)
    jobs.loc[jobs.index[:3], "failure_class"] = "timeout"
    fit = fit_failure(jobs, SKINS, resolve_settings(FAST))
    assert fit.booster is None and not fit.metrics["trained"]
    assert fit.metrics["failed_jobs"] == 3
    assert fit.metrics["statement"].startswith("no failure model: 3 of 1944 jobs failed")


def test_sobol_indices_and_their_bootstrap_repeat_for_every_seed() -> None:
    def f(U: np.ndarray) -> np.ndarray:
        return U[:, 0] + U[:, 1] ** 2

    for seed in (0, 5):  # SALib leaves a seed of 0 unseeded unless mapped
        assert sobol_indices(f, ["a", "b"], 256, seed) == sobol_indices(f, ["a", "b"], 256, seed)
    assert sobol_indices(f, ["a", "b"], 256, 0) != sobol_indices(f, ["a", "b"], 256, 1)

"""The Gaussian-process stress surrogate (`woundsweep.analysis.interpolant`) against the trees,
on a smooth known truth that does not depend on t_d (`smooth_stress`): training rows on `SMALL_SWEEP`'s grid
(11,664 rows, as tests/analysis/test_surrogate.py), and two synthetic run directories whose
every factor lies between the grid's values (a third and two thirds of each interval, as
sweeps/paper-between-*.yaml), read through the analysis's own reader."""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import SMALL_SWEEP, SMOOTH_NOISE, smooth_stress, write_store

from woundsweep.analysis import encode_features
from woundsweep.analysis.data import load_results, select_rows
from woundsweep.analysis.interpolant import GPSurrogate
from woundsweep.analysis.offgrid import OtherRows, off_grid_test, report_lines
from woundsweep.analysis.regression import fit_surrogate
from woundsweep.config.analysis import resolve_settings
from woundsweep.config.manifest import expand
from woundsweep.config.sweep import DEFAULTS, parse_sweep
from woundsweep.core.errors import AnalysisError, SweepError

FAST = {"n_estimators": 40, "learning_rate": 0.3, "early_stopping_rounds": 5, "nthread": 2}
SKINS = {k: float(v["c_kPa"]) for k, v in DEFAULTS["materials"]["skin_types"].items()}


def _between(third: int, td: float, orientations: list[float]) -> dict:
    """A sweep at a third (1) or two thirds (2) of each interval of `SMALL_SWEEP`'s grid
    (a log third for the subcutis factor); 144 jobs each."""
    at = {
        1: {"s": [0.63, 1.26], "p": [1.33, 2.33], "w": [0.4, 0.6], "a": [0.03, 0.13], "d": [0.37, 0.57]},
        2: {"s": [0.79, 1.59], "p": [1.67, 2.67], "w": [0.35, 0.55], "a": [0.07, 0.17], "d": [0.43, 0.63]},
    }[third]  # fmt: skip
    grid = {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [td],
        "subcutis_thickness_factor": at["s"],
        "patch_size_factor": at["p"],
        "wound_width_factor": at["w"],
        "orientation_deg": orientations,
    }
    shapes = {
        "cylindrical": {"wound_aspect_factor": at["a"]},
        "wedge": {"wound_depth_factor": at["d"]},
    }
    return {**SMALL_SWEEP, "name": f"between-{third}", "grid": grid, "shapes": shapes}


@functools.cache
def _grid() -> tuple[pd.DataFrame, np.ndarray]:
    m = expand(parse_sweep(dict(SMALL_SWEEP), "synthetic.yaml"))
    rows = m.loc[m.index.repeat(6)].reset_index(drop=True)
    rows["stage"] = np.tile(np.arange(1, 7), len(m))
    rows["p99_von_mises_kPa"] = smooth_stress(rows, np.random.default_rng(1))
    return rows, encode_features(rows, SKINS)


def _read(rd: Path) -> OtherRows:
    """A run's rows through the analysis's reader and row selection."""
    rows = select_rows(load_results(rd))[0]
    return OtherRows(str(rd), rows, encode_features(rows, SKINS))


@pytest.fixture(scope="module")
def off_grid(tmp_path_factory: pytest.TempPathFactory) -> tuple[OtherRows, OtherRows]:
    """The calibration run (thirds, t_d 1.5) and the test run (two thirds, t_d 1.25)."""
    base = tmp_path_factory.mktemp("between")
    write_store(base / "cal", smooth_stress, sweep=_between(1, 1.5, [15, 60]), seed=5,
                failed_fraction=0.0)  # fmt: skip
    write_store(base / "test", smooth_stress, sweep=_between(2, 1.25, [30, 75]), seed=6,
                failed_fraction=0.0)  # fmt: skip
    return _read(base / "cal"), _read(base / "test")


@pytest.fixture(scope="module")
def fits(off_grid: tuple[OtherRows, OtherRows]) -> dict:
    """Both kinds trained on the grid, calibrated on the off-grid calibration run."""
    rows, X = _grid()
    return {
        kind: fit_surrogate(rows, X, resolve_settings(FAST, {"surrogate": kind}), off_grid[0])
        for kind in ("trees", "gp")
    }


def _test(fit, other: OtherRows) -> dict:
    return off_grid_test(fit.model, fit.meta["calibration_scores_log"], other, [])


def test_gp_error_off_the_grid_is_well_below_the_trees(off_grid, fits) -> None:
    test = off_grid[1]
    assert len(test.rows) == 864 and test.rows["geometry_id"].nunique() == 24
    err = {kind: _test(fit, test)["median_relative_error"] for kind, fit in fits.items()}
    # Trees are piecewise constant between the grid's values; the GP interpolates. The
    # noise alone gives a median error of about 0.674 * SMOOTH_NOISE = 3.4 %.
    assert err["gp"] < 0.5 * err["trees"], err
    assert err["gp"] < 2.5 * 0.674 * SMOOTH_NOISE, err


def test_off_grid_calibration_gives_nominal_coverage_off_the_grid(off_grid, fits) -> None:
    cal, test = off_grid
    fit = fits["gp"]
    assert "normalised scores" in fit.metrics["calibration"]
    assert str(cal.source) in fit.metrics["calibration"]
    assert fit.metrics["calibration_rows"] == len(cal.rows) == 864
    n_cal = min(len(v) for v in fit.meta["calibration_scores_log"].values())  # 144 per stage
    n_stages = len(fit.meta["calibration_scores_log"])
    got = _test(fit, test)["coverage"]
    for level in (0.8, 0.95):
        c = got[str(level)]
        assert c["rows"] == len(test.rows) == 864
        # Two sources of spread (binomial): the test rows' and the calibration's (per stage,
        # averaged over the stages' independent calibrations). Three standard errors: about
        # 5.7 points at 80 % and 3.2 at 95 % for these sizes.
        var = level * (1 - level) * (1 / c["rows"] + 1 / ((n_cal + 2) * n_stages))
        tol = 3 * math.sqrt(var)
        assert tol < 0.06
        assert abs(c["empirical"] - level) <= tol, (level, c["empirical"], tol)


def test_gp_ignores_the_dermal_thickness_and_averages_its_replicates(fits) -> None:
    fit = fits["gp"]
    rows, X = _grid()
    gp = fit.model
    sample = X[:: len(X) // 300]
    base = gp.predict_log(sample)
    for td in (0.3, 1.7, 40.0):  # inside and far outside the trained 1..2 mm
        moved = sample.copy()
        moved[:, list(gp.features).index("dermal_thickness_mm")] = td
        changed = gp.predict_log(moved)
        assert np.array_equal(changed[0], base[0]) and np.array_equal(changed[1], base[1])
    summary = fit.metrics["gp"]
    assert all("dermal_thickness_mm" not in v for v in summary["inputs"].values())
    assert summary["groups"] == 2 * 3 * 6
    # Two thicknesses: every dimensionless point holds two rows.
    assert summary["rows"] == 2 * summary["points"] == fit.metrics["training_rows"]
    # The replicates' spread is the truth's noise (log-normal sigma 0.05).
    assert summary["noise_floor_log_sd"] == pytest.approx(SMOOTH_NOISE, rel=0.1)
    # The fitted white noise is that of a mean of two rows.
    assert summary["fitted_noise_log_sd"]["median"] == pytest.approx(
        SMOOTH_NOISE / math.sqrt(2), rel=0.3
    )


def test_mean_offset_measures_a_shift_of_the_stresses(off_grid, fits) -> None:
    """The GP is unbiased on the smooth truth between the grid's values; a run whose every
    stress is 5 % higher reads an offset 5 % lower, to rounding."""
    test = off_grid[1]
    base = _test(fits["gp"], test)
    assert abs(base["mean_log_error"]) < 0.01, base["mean_log_error"]
    rows = test.rows.copy()
    rows["p99_von_mises_kPa"] *= 1.05
    moved = _test(fits["gp"], OtherRows(test.source, rows, test.X))
    assert moved["mean_log_error"] == pytest.approx(base["mean_log_error"] - math.log(1.05))
    line = report_lines({"off_grid_test": moved, "surrogate": {"surrogate": "gp"}})[3]
    assert f"mean offset is {100 * math.expm1(moved['mean_log_error']):+.1f}%" in line


def test_gp_interpolates_the_orientation_in_cos_2t(fits) -> None:
    """The truth moves with the orientation t as 0.3 cos 2t (`smooth_stress`, like every result
    by the wound's symmetry): between the grid's 0, 45 and 90 deg the GP follows it, where an
    interpolant linear in t would miss by 0.3 x 0.2 = 0.06 at 15 and 75 deg."""
    _, X = _grid()
    gp = fits["gp"].model
    j = list(gp.features).index("orientation_deg")
    sample = X[X[:, j] == 0.0][::10]
    assert len(sample) > 300
    base = gp.predict_log(sample)[0]
    for t in (15.0, 30.0, 60.0, 75.0):
        moved = sample.copy()
        moved[:, j] = t
        change = gp.predict_log(moved)[0] - base
        truth = 0.3 * (math.cos(math.radians(2 * t)) - 1.0)
        assert abs(np.mean(change) - truth) < 0.015, (t, np.mean(change), truth)
    assert fits["gp"].metrics["gp"]["inputs"]["wedge"][-1] == "cos 2 orientation_deg"


def test_gp_split_keeps_the_replicates_of_a_wound_together(fits) -> None:
    rows, _ = _grid()
    fit = fits["gp"]
    key = ["wound_shape", "subcutis_thickness_factor", "patch_size_factor",
           "wound_width_factor", "wound_depth_factor", "wound_aspect_factor"]  # fmt: skip
    wound = rows[key].fillna(-1.0).astype(str).agg("|".join, axis=1).to_numpy()
    sets = [set(wound[idx]) for idx in fit.split]
    assert all(not (a & b) for i, a in enumerate(sets) for b in sets[i + 1 :])


def test_saved_gp_reloads_to_identical_predictions(fits, tmp_path: Path) -> None:
    _, X = _grid()
    gp = fits["gp"].model
    path = tmp_path / "surrogate.json"
    path.write_bytes(gp.to_bytes())
    doc = json.loads(path.read_text())
    assert set(doc) == {"format", "kernel", "features", "shapes", "groups"}
    assert set(doc["groups"][0]) >= {"constant", "length_scales", "noise", "inputs", "log_p99"}
    back = GPSurrogate.read(path)
    for a, b in zip(gp.predict_log(X[::7]), back.predict_log(X[::7])):
        assert np.array_equal(a, b)


def _damaged(doc: dict) -> list[tuple[str, dict | str]]:
    """(what, damaged document or text): one of each class of damage."""

    def with_group(change: dict) -> dict:
        return {**doc, "groups": [{**doc["groups"][0], **change}, *doc["groups"][1:]]}

    g0 = doc["groups"][0]
    return [
        ("not JSON", "{oops"),
        ("another format", {**doc, "format": "woundsweep-gp-surrogate/0"}),
        ("no groups", {k: v for k, v in doc.items() if k != "groups"}),
        ("a length scale short", with_group({"length_scales": g0["length_scales"][:-1]})),
        ("a negative noise", with_group({"noise": -1.0})),
        ("a string target", with_group({"log_p99": ["x"] * len(g0["log_p99"])})),
        ("an input row short", with_group({"inputs": [g0["inputs"][0][:-1], *g0["inputs"][1:]]})),
        ("a stage as text", with_group({"stage": "1"})),
        ("shapes damaged", {**doc, "shapes": {"wedge": {"names": ["nope"]}}}),
        ("non-positive log input", with_group({"inputs": [[0.0] * len(g0["inputs"][0]), *g0["inputs"][1:]]})),
    ]  # fmt: skip


def test_damaged_gp_files_are_refused_in_one_line(fits, tmp_path: Path) -> None:
    doc = json.loads(fits["gp"].model.to_bytes())
    for i, (what, damaged) in enumerate(_damaged(doc)):
        path = tmp_path / f"s{i}.json"
        path.write_text(damaged if isinstance(damaged, str) else json.dumps(damaged))
        with pytest.raises(AnalysisError) as err:
            GPSurrogate.read(path)
        text = str(err.value)
        assert text.startswith(str(path)) and "\n" not in text, (what, text)


def test_the_surrogate_setting_is_checked_where_settings_are() -> None:
    assert resolve_settings({"surrogate": "gp"}).surrogate == "gp"
    assert resolve_settings().surrogate == "trees"
    with pytest.raises(AnalysisError, match="analysis.surrogate: expected one of trees, gp"):
        resolve_settings({"surrogate": "forest"})
    with pytest.raises(AnalysisError, match="analysis.surrogate: expected a name"):
        resolve_settings({"surrogate": 3})
    sweep = parse_sweep({**SMALL_SWEEP, "analysis": {"surrogate": "gp"}}, "s.yaml")
    assert sweep.analysis.surrogate == "gp"
    with pytest.raises(SweepError, match="analysis.surrogate"):
        parse_sweep({**SMALL_SWEEP, "analysis": {"surrogate": "forest"}}, "s.yaml")

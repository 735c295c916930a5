"""Stress-quantile analysis: binning, splits and metrics against hand calculations, and the
model on synthetic stores whose truth is known (stress = f(depth) + noise, or pure noise)."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import SMALL_SWEEP, depth_stress, random_stress, write_store

from woundsweep.analysis import (
    FEATURES,
    REQUIRED_COLUMNS,
    assign_quantiles,
    encode_features,
    evaluate,
    fit_scheme,
    geometry_groups,
    geometry_split,
    load_results,
    normalised_locations,
    quantile_edges,
    random_split,
    select_rows,
    skin_codes,
    stiff_vs_soft,
)
from woundsweep.analysis.data import require_columns
from woundsweep.config.analysis import ModelSettings, resolve_settings
from woundsweep.config.manifest import expand
from woundsweep.config.sweep import parse_sweep
from woundsweep.core.errors import AnalysisError, StoreError
from woundsweep.store.reader import result_schema

# Few, fast rounds: the assertions are about what the data allow, not about tuning.
FAST = {"n_estimators": 40, "learning_rate": 0.3, "early_stopping_rounds": 5, "nthread": 2}


# -- quantiles -----------------------------------------------------------------------------


def test_quantile_edges_split_1_to_800_into_equal_classes() -> None:
    stress = np.random.default_rng(3).permutation(np.arange(1.0, 801.0))
    edges = quantile_edges(stress, 8)
    # Linear-interpolation quantiles of 1..800: 1 + p * 799.
    assert edges == pytest.approx([1 + k / 8 * 799 for k in range(9)])
    assert np.bincount(assign_quantiles(stress, edges)).tolist() == [100] * 8


def test_assign_quantiles_sends_outliers_to_end_classes_and_edges_up() -> None:
    edges = np.array([1.0, 2.0, 3.0, 4.0])
    assert assign_quantiles(np.array([-5.0, 1.5, 2.0, 2.5, 3.0, 99.0]), edges).tolist() == [
        0,
        0,
        1,
        1,
        2,
        2,
    ]


def test_tied_stresses_cannot_fill_the_quantiles() -> None:
    with pytest.raises(AnalysisError, match="tied quantile edges"):
        quantile_edges(np.array([1.0] * 50 + [2.0] * 50), 8)
    with pytest.raises(AnalysisError, match="cannot fill 8 quantiles"):
        quantile_edges(np.arange(5.0), 8)


# -- splits --------------------------------------------------------------------------------


def test_random_split_sizes_and_partition() -> None:
    s = random_split(1000, 0.63, 0.27, seed=4)
    assert [len(s.train), len(s.validation), len(s.test)] == [630, 270, 100]
    assert np.array_equal(np.sort(np.concatenate(s)), np.arange(1000))
    other = random_split(1000, 0.63, 0.27, seed=5)
    assert not np.array_equal(s.test, other.test)


def _manifest(**grid_changes: list) -> pd.DataFrame:
    doc = {**SMALL_SWEEP, "grid": {**SMALL_SWEEP["grid"], **grid_changes}}
    return expand(parse_sweep(doc))


def test_geometry_groups_merge_mesh_sizes_only() -> None:
    man = _manifest(mesh_size_factor=[0.3, 0.5])
    groups = geometry_groups(man)
    per_group = pd.Series(man["geometry_id"].to_numpy()).groupby(groups).nunique()
    # 216 physical geometries, each meshed twice; jobs of one geometry_id never split.
    assert len(per_group) == 216 and (per_group == 2).all()
    assert (pd.Series(groups).groupby(man["geometry_id"].to_numpy()).nunique() == 1).all()


def test_geometry_split_never_shares_a_geometry() -> None:
    man = _manifest(mesh_size_factor=[0.3, 0.5])
    rows = man.loc[man.index.repeat(6)].reset_index(drop=True)  # six stages per job
    groups = geometry_groups(rows)
    s = geometry_split(groups, 0.63, 0.27, seed=0)
    assert np.array_equal(np.sort(np.concatenate(s)), np.arange(len(rows)))
    ids = [set(rows["geometry_id"].iloc[idx]) for idx in s]
    keys = [set(groups[idx]) for idx in s]
    for a, b in ((0, 1), (0, 2), (1, 2)):
        assert not ids[a] & ids[b]
        assert not keys[a] & keys[b]
    # Whole groups of 108 rows: each set within one group of its target size.
    n = len(rows)
    for idx, frac in zip(s, (0.63, 0.27, 0.10)):
        assert abs(len(idx) - frac * n) <= 108


# -- metrics -------------------------------------------------------------------------------


def test_evaluate_against_hand_computed_values() -> None:
    y = np.array([0, 0, 1, 1])
    prob = np.array([[0.9, 0.1], [0.3, 0.7], [0.35, 0.65], [0.2, 0.8]])
    m = evaluate(y, prob)
    # Class 1 positives score 0.65, 0.8 against negatives 0.1, 0.7: 3 of 4 pairs ordered.
    assert m["auc_per_quantile"] == pytest.approx([0.75, 0.75])
    assert m["auc_macro"] == pytest.approx(0.75)
    # Pooled: positives 0.9, 0.3, 0.65, 0.8 against negatives 0.1, 0.7, 0.35, 0.2: 13 of 16.
    assert m["auc_micro"] == pytest.approx(13 / 16)
    assert m["accuracy"] == pytest.approx(0.75)
    assert m["log_loss"] == pytest.approx(
        -(math.log(0.9) + math.log(0.3) + math.log(0.65) + math.log(0.8)) / 4
    )
    assert m["confusion_matrix"] == [[1, 1], [0, 2]]


def test_evaluate_leaves_absent_quantiles_without_auc() -> None:
    y = np.array([0, 1, 0, 1])
    prob = np.array([[0.6, 0.3, 0.1], [0.2, 0.7, 0.1], [0.5, 0.4, 0.1], [0.3, 0.5, 0.2]])
    m = evaluate(y, prob)
    assert m["auc_per_quantile"][2] is None
    assert m["auc_macro"] == pytest.approx(1.0)
    assert m["class_counts"] == [2, 2, 0]


def test_stiff_vs_soft_on_a_hand_built_table() -> None:
    def r(geo: str, shape: str, angle: float, stage: int, skin: str, s: float) -> dict:
        return dict(
            geometry_id=geo,
            wound_shape=shape,
            orientation_deg=angle,
            stage=stage,
            skin_type=skin,
            p99_von_mises_kPa=s,
        )

    rows = pd.DataFrame(
        [
            # wedge: three pairs stiff > soft, one tie
            r("g1", "wedge", 0, 1, "stiff", 5), r("g1", "wedge", 0, 1, "soft", 4),
            r("g1", "wedge", 0, 2, "stiff", 6), r("g1", "wedge", 0, 2, "soft", 1),
            r("g1", "wedge", 45, 1, "stiff", 3), r("g1", "wedge", 45, 1, "soft", 2),
            r("g1", "wedge", 45, 2, "stiff", 7), r("g1", "wedge", 45, 2, "soft", 7),
            r("g1", "wedge", 45, 2, "normal", 99),  # not part of any pair
            r("g1", "wedge", 90, 1, "stiff", 9),  # no soft partner
            # cylindrical: two pairs soft > stiff
            r("g2", "cylindrical", 0, 1, "stiff", 1), r("g2", "cylindrical", 0, 1, "soft", 2),
            r("g2", "cylindrical", 0, 3, "stiff", 1), r("g2", "cylindrical", 0, 3, "soft", 5),
        ]
    )  # fmt: skip
    summary, pairs = stiff_vs_soft(rows)
    assert len(pairs) == 6
    w = summary["wedge"]
    assert (w["pairs"], w["stiff_greater"], w["soft_greater"], w["ties"]) == (4, 3, 0, 1)
    assert w["fraction_stiff_greater"] == pytest.approx(0.75)
    assert w["sign_test_p"] == pytest.approx(2 * 0.5**3)  # two-sided, ties dropped
    c = summary["cylindrical"]
    assert (c["pairs"], c["stiff_greater"], c["soft_greater"]) == (2, 0, 2)
    assert c["sign_test_p"] == pytest.approx(2 * 0.5**2)


def test_a_sign_test_beyond_float_range_reads_as_a_bound() -> None:
    from scipy.stats import binomtest

    from woundsweep.analysis.report import p_text

    # 1,369 pairs all one way: 2 x 0.5^1369 ~ 1e-412 underflows to 0, which is no p-value.
    p = float(binomtest(1369, 1369, 0.5).pvalue)
    assert p == 0.0
    assert p_text(p) == "< 1e-300" and p_text(p, relation=True) == "< 1e-300"
    assert p_text(2 * 0.5**3, relation=True) == "= 0.25" and p_text(None) == "n/a"


def test_normalised_locations_map_patch_corners() -> None:
    L, w, T = 3.0, 1.0, 2.0
    xs = [-L, L + w, w / 2, 0.0]
    ys = [-L, L, L / 3, -L / 3]
    zs = [0.0, -T, -T / 2, -0.5]
    rows = pd.DataFrame(
        {
            "stage": [1, 2, 3, 6],
            "max_location_x_mm": xs, "max_location_y_mm": ys, "max_location_z_mm": zs,
            "patch_half_length_mm": L, "wound_width_mm": w, "total_thickness_mm": T,
        }
    )  # fmt: skip
    loc = normalised_locations(rows)
    assert loc["stage_group"].tolist() == ["stage 1", "stage 2", "stages 3-6", "stages 3-6"]
    assert loc["y_along"].tolist() == pytest.approx([0.0, 1.0, 2 / 3, 1 / 3])
    assert loc["x_across"].tolist() == pytest.approx([-1.0, 1.0, 0.0, -0.5 / 3.5])
    assert loc["z_depth"].tolist() == pytest.approx([0.0, 1.0, 0.5, 0.25])


def test_settings_layers_and_validation() -> None:
    s = resolve_settings({"quantiles": 8, "max_depth": 6}, {"max_depth": "3", "seed": 7})
    assert (s.quantiles, s.max_depth, s.seed) == (8, 3, 7)
    assert s.learning_rate == ModelSettings().learning_rate
    with pytest.raises(AnalysisError, match="unknown setting"):
        resolve_settings({"max_dept": 3})
    with pytest.raises(AnalysisError, match="expected int"):
        resolve_settings({"max_depth": 2.5})
    with pytest.raises(AnalysisError, match="test set"):
        resolve_settings({"train_fraction": 0.7, "validation_fraction": 0.3})


# -- loading -------------------------------------------------------------------------------


def test_required_columns_are_result_columns() -> None:
    assert set(REQUIRED_COLUMNS) <= set(result_schema().names)


def test_load_results_names_missing_columns(tmp_path: Path) -> None:
    rows = write_store(tmp_path, sweep=_tiny_sweep())
    assert load_results(tmp_path).shape == (len(rows), len(result_schema()))
    with pytest.raises(AnalysisError, match=r"missing columns \['stage', 'max_location_z_mm'\]"):
        require_columns(rows.drop(columns=["stage", "max_location_z_mm"]), "rows")
    # A result file without them is refused by the store's reader, naming the file.
    job = rows["job_id"].iloc[0]
    path = tmp_path / "results" / f"job-{job}.parquet"
    rows[rows["job_id"] == job].drop(columns=["stage", "max_location_z_mm"]).to_parquet(path)
    with pytest.raises(StoreError, match=rf"{path.name}: corrupt result file \(columns differ"):
        load_results(tmp_path)


def test_load_results_without_result_files(tmp_path: Path) -> None:
    write_store(tmp_path, sweep=_tiny_sweep())
    for p in (tmp_path / "results").iterdir():
        p.unlink()
    with pytest.raises(AnalysisError, match="holds no result files"):
        load_results(tmp_path)
    (tmp_path / "results").rmdir()
    with pytest.raises(AnalysisError, match="no result store"):
        load_results(tmp_path)


def test_select_rows_counts_and_refusals(tmp_path: Path) -> None:
    rows = write_store(tmp_path, sweep=_tiny_sweep(), failed_fraction=0.3, seed=2)
    used, counts = select_rows(load_results(tmp_path))
    assert counts["store_rows"] == len(rows)
    assert counts["used_rows"] == int((rows["status"] == "converged").sum()) == len(used)
    assert counts["status"]["not-run"] == int((rows["status"] == "not-run").sum()) > 0
    bad = rows.copy()
    bad["status"] = "diverged"
    with pytest.raises(AnalysisError, match="no converged rows"):
        select_rows(bad)
    with pytest.raises(AnalysisError, match="duplicate"):
        select_rows(pd.concat([rows, rows.iloc[:3]]))


def _tiny_sweep() -> dict:
    grid = {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
    }
    return {**SMALL_SWEEP, "grid": grid}


# -- the model on stores with a known truth ------------------------------------------------


@functools.cache
def _rows(store: Path) -> tuple[pd.DataFrame, dict[str, float], np.ndarray]:
    """The store's used rows, skin codes and model matrix, read once per store."""
    rows, _ = select_rows(load_results(store))
    skins = skin_codes(store)
    return rows, skins, encode_features(rows, skins)


def _fit(store: Path, scheme: str, **overrides: object):
    rows, skins, X = _rows(store)
    return fit_scheme(scheme, rows, X, skins, resolve_settings(FAST, overrides)), rows, X


@pytest.fixture(scope="module")
def depth_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("depth")
    write_store(rd, depth_stress, seed=1)
    return rd


@pytest.fixture(scope="module")
def random_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("random")
    write_store(rd, random_stress, seed=2)
    return rd


@pytest.mark.parametrize("scheme", ["random", "geometry"])
def test_depth_driven_stress_is_learned_and_depth_ranks_first(
    depth_store: Path, scheme: str
) -> None:
    fit, rows, _ = _fit(depth_store, scheme)
    test = fit.metrics["test"]
    assert test["rows"] > 1000
    assert test["auc_macro"] > 0.9
    assert all(a > 0.85 for a in test["auc_per_quantile"])
    imp = fit.metrics["importance"]
    assert imp["ranking_weight"][0] == "wound_depth"
    assert imp["ranking_total_gain"][0] == "wound_depth"
    # The second truth in the data is the stage.
    assert imp["ranking_total_gain"][1] == "stage"
    # Edges come from the training rows: exactly an eighth of them per class.
    counts = np.bincount(fit.y[fit.split.train], minlength=8)
    assert counts.max() - counts.min() <= 1


@pytest.mark.parametrize("scheme", ["random", "geometry"])
def test_random_stress_gives_chance_auc(random_store: Path, scheme: str) -> None:
    fit, _, _ = _fit(random_store, scheme)
    test = fit.metrics["test"]
    assert test["rows"] > 1000
    assert 0.45 <= test["auc_macro"] <= 0.55
    assert test["accuracy"] < 0.2


def test_geometry_fit_keeps_geometries_apart_in_the_store(depth_store: Path) -> None:
    fit, rows, _ = _fit(depth_store, "geometry")
    sets = [set(rows["geometry_id"].iloc[idx]) for idx in fit.split]
    assert not (sets[0] & sets[1]) and not (sets[0] & sets[2]) and not (sets[1] & sets[2])
    assert fit.metrics["split_geometries"] == {
        k: len(s) for k, s in zip(("train", "validation", "test"), sets)
    }


def test_same_seed_same_model_other_seed_other_split(depth_store: Path) -> None:
    a, _, _ = _fit(depth_store, "random")
    b, _, _ = _fit(depth_store, "random")
    c, _, _ = _fit(depth_store, "random", seed=1)
    assert a.metrics == b.metrics
    assert not np.array_equal(a.split.test, c.split.test)
    assert a.metrics["test"] != c.metrics["test"]


def test_feature_matrix_encoding(depth_store: Path) -> None:
    rows, _, _ = _rows(depth_store)
    X = encode_features(rows, {"soft": 10.7, "normal": 21.3, "stiff": 42.6})
    col = {f: i for i, f in enumerate(FEATURES)}
    wedge = rows["wound_shape"].to_numpy() == "wedge"
    assert np.array_equal(X[:, col["wound_shape"]], wedge.astype(float))
    assert np.isnan(X[wedge, col["wound_aspect_factor"]]).all()
    assert np.isnan(X[~wedge, col["wound_depth_factor"]]).all()
    stiff = rows["skin_type"].to_numpy() == "stiff"
    assert (X[stiff, col["skin_type"]] == 42.6).all()
    with pytest.raises(AnalysisError, match="unknown values"):
        encode_features(rows, {"soft": 1.0, "normal": 2.0})

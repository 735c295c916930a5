"""``woundsweep analyze`` and ``predict`` with the stress surrogate, through the CLI: the
interval around the estimate, the saved booster's own answer, interpolation flags, the
failure statement, the report's sections and one-line refusals."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import PREDICT_FAST, PREDICT_SWEEP, depth_stress, write_store

from woundsweep.cli import main
from woundsweep.config.sweep import DEFAULTS
from woundsweep.store.reader import read_results

SWEEP, FAST = PREDICT_SWEEP, PREDICT_FAST
FEATURES = [
    "wound_shape", "dermal_thickness_mm", "subcutis_thickness_factor", "patch_size_factor",
    "wound_width_factor", "wound_depth_factor", "wound_aspect_factor", "mesh_size_factor",
    "orientation_deg", "skin_type", "stage",
]  # fmt: skip


@pytest.fixture(scope="module")
def analyzed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("surrogate") / "run"
    write_store(rd, depth_stress, sweep=SWEEP, seed=3, failed_fraction=0.0)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["analyze", str(rd), "--split", "geometry", *FAST]) == 0
    return rd


def _args(row: pd.Series, **change: object) -> list[str]:
    r = {**row.to_dict(), **change}
    args = [
        "--shape", r["wound_shape"], "--dermal-thickness", r["dermal_thickness_mm"],
        "--subcutis-thickness-factor", r["subcutis_thickness_factor"],
        "--patch-size-factor", r["patch_size_factor"], "--wound-width-factor", r["wound_width_factor"],
        "--mesh-size-factor", r["mesh_size_factor"], "--orientation", r["orientation_deg"],
        "--skin-type", r["skin_type"], "--stage", int(r["stage"]),
    ]  # fmt: skip
    if r["wound_shape"] == "wedge":
        args += ["--wound-depth-factor", r["wound_depth_factor"]]
    else:
        args += ["--wound-aspect-factor", r["wound_aspect_factor"]]
    return [str(a) for a in args]


def _training_row(rd: Path, shape: str) -> pd.Series:
    """A converged row inside the trained ranges of the classifier and the surrogate."""
    rows = read_results(rd)
    rows = rows[(rows["wound_shape"] == shape) & (rows["status"] == "converged")]
    for stem in ("model_geometry", "surrogate"):
        meta = json.loads((rd / "analysis" / f"{stem}_meta.json").read_text())
        for col, (lo, hi) in meta["ranges"][shape].items():
            rows = rows[rows[col].between(lo, hi)]
    return rows.iloc[3]


@pytest.mark.parametrize("shape", ["wedge", "cylindrical"])
def test_predict_interval_contains_the_saved_surrogates_estimate(
    analyzed: Path, shape: str, run_main
) -> None:
    import xgboost as xgb

    row = _training_row(analyzed, shape)
    rc, out, err = run_main("predict", analyzed, *_args(row), "--json", "--level", "0.8")
    assert rc == 0, err
    answer = json.loads(out)
    (pred,) = answer["predictions"]
    lo, hi = pred["interval_kPa"]
    assert lo < pred["stress_kPa"] < hi and pred["level"] == 0.8
    # The saved booster's own answer, from the documented encoding.
    booster = xgb.Booster()
    booster.load_model(str(analyzed / "analysis" / "surrogate.json"))
    c_kPa = DEFAULTS["materials"]["skin_types"][row.skin_type]["c_kPa"]
    x = [1.0 if shape == "wedge" else 0.0, row.dermal_thickness_mm, row.subcutis_thickness_factor,
         row.patch_size_factor, row.wound_width_factor, row.wound_depth_factor, row.wound_aspect_factor,
         row.mesh_size_factor, row.orientation_deg, c_kPa, float(row.stage)]  # fmt: skip
    log_est = float(booster.predict(xgb.DMatrix(np.array([x]), feature_names=FEATURES))[0])
    assert pred["stress_kPa"] == pytest.approx(math.exp(log_est), rel=1e-6)
    # Symmetric in log stress: the estimate is the geometric mean of the bounds.
    assert math.sqrt(lo * hi) == pytest.approx(pred["stress_kPa"], rel=1e-9)
    rc, out, _ = run_main("predict", analyzed, *_args(row), "--json", "--level", "0.95")
    lo95, hi95 = json.loads(out)["predictions"][0]["interval_kPa"]
    assert lo95 <= lo and hi95 >= hi
    assert answer["interpolated"] == [] and pred["extrapolated"] == []
    assert answer["failure_probability"] is None
    assert answer["failure_note"].startswith("no failure model: 0 of 108 jobs failed")


def test_predict_flags_an_orientation_between_the_grid_values(analyzed: Path, run_main) -> None:
    row = _training_row(analyzed, "wedge")
    rc, out, err = run_main("predict", analyzed, *_args(row, orientation_deg=25))
    assert rc == 0, err
    assert "stress" in out and "% interval" in out and "failure probability: n/a" in out
    assert (
        "INTERPOLATED" in out
        and "orientation_deg=25 (interpolated between trained values 0 and 45)" in out
    )
    rc, _, err = run_main("predict", analyzed, *_args(row), "--level", "1.5")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "interval level 1.5" in err


def test_metrics_and_report_hold_coverage_failure_and_sobol(analyzed: Path) -> None:
    a = analyzed / "analysis"
    m = json.loads((a / "metrics.json").read_text())
    s = m["surrogate"]
    assert set(s["test"]["coverage"]) == {"0.8", "0.95"}
    assert sum(s["split_rows"].values()) == m["rows"]["used_rows"]
    assert s["test"]["coverage"]["0.8"]["rows"] == s["split_rows"]["test"]
    assert m["failure"]["trained"] is False and m["failure"]["failed_jobs"] == 0
    ranking = s["sensitivity"]["ranking_total"]
    assert ranking[0] == "wound_depth"
    report = (a / "report.md").read_text()
    assert "| 80% |" in report and "| 95% |" in report
    assert f"Top three by Sobol total index: {', '.join(ranking[:3])}." in report
    assert "no failure model: 0 of 108 jobs" in report
    for stem in ("sobol", "surrogate_test"):
        assert (a / f"{stem}.png").read_bytes()[:4] == b"\x89PNG"
    assert (a / "surrogate_meta.json").is_file() and not (a / "failure_model.json").exists()


def _copy_analysis(analyzed: Path, dest: Path) -> Path:
    """A model directory holding a copy of the run's analysis files (no run: no stale check)."""
    import shutil

    shutil.copytree(analyzed / "analysis", dest)
    return dest


def test_predict_labels_every_number_and_says_what_it_rests_on(analyzed: Path, run_main) -> None:
    row = _training_row(analyzed, "wedge")
    rc, out, err = run_main("predict", analyzed, *_args(row))
    assert rc == 0, err
    sur = json.loads((analyzed / "analysis" / "surrogate_meta.json").read_text())
    n_cal = sum(len(v) for v in sur["calibration_scores_log"].values())
    assert (
        f"split-conformal on {n_cal} calibration rows of {sur['calibration_geometries']} geometries"
        in out
    )
    assert "p99 of the volume (stress surrogate):" in out and "quantile class (classifier):" in out
    assert "class probabilities (class:probability): 1:" in out and "p = [" not in out
    rc, out, _ = run_main("predict", analyzed, *_args(row), "--json")
    answer = json.loads(out)
    pred = answer["predictions"][0]
    edges = json.loads((analyzed / "analysis" / "model_geometry_meta.json").read_text())[
        "quantile_edges_kPa"
    ]
    k = pred["estimate_quantile"]
    assert edges[k - 1] <= pred["stress_kPa"] < edges[k] or k in (1, len(edges) - 1)
    assert answer["basis"]["calibration_rows"] == n_cal


def test_an_extrapolated_answer_has_no_interval(analyzed: Path, run_main) -> None:
    row = _training_row(analyzed, "wedge")
    far = _args(row, wound_width_factor=1.9)
    rc, _, err = run_main("predict", analyzed, *far)
    assert rc == 2 and "--allow-extrapolation" in err
    rc, out, err = run_main("predict", analyzed, *far, "--allow-extrapolation", "--json")
    assert rc == 0, err
    pred = json.loads(out)["predictions"][0]
    assert pred["extrapolated"] and pred["interval_kPa"] == [None, None]
    assert "extrapolated" in pred["interval_note"] and pred["stress_kPa"] > 0
    rc, out, _ = run_main("predict", analyzed, *far, "--allow-extrapolation")
    assert "interval: none: extrapolated" in out and "EXTRAPOLATED" in out


@pytest.mark.parametrize(
    "change, needle",
    [
        ({"dermal_thickness_mm": -1.0}, "dermal_thickness_mm=-1 (must be positive)"),
        ({"wound_depth_factor": 1.0}, "wound_depth_factor=1 (a fraction of the thickness"),
        ({"wound_depth_factor": 1.5}, "wound_depth_factor=1.5"),
        ({"wound_width_factor": 0.0}, "wound_width_factor=0 (must be positive)"),
    ],
)
def test_impossible_wounds_are_refused_even_when_extrapolating(
    analyzed: Path, run_main, change: dict, needle: str
) -> None:
    row = _training_row(analyzed, "wedge")
    rc, out, err = run_main("predict", analyzed, *_args(row, **change), "--allow-extrapolation")
    assert rc == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "not a possible wound" in err and needle in err


def test_an_excision_of_length_factor_one_is_refused() -> None:
    from woundsweep.analysis.prediction import check_physical
    from woundsweep.core.errors import AnalysisError

    with pytest.raises(AnalysisError, match=r"wound_length_factor=1 \(a multiple of the width"):
        check_physical({"wound_length_factor": 1.0, "wound_depth_factor": 0.5})
    check_physical({"wound_length_factor": 3.0, "wound_depth_factor": 0.5})  # a possible one


def test_an_angle_outside_the_trained_ones_is_refused_in_the_users_terms(
    analyzed: Path, tmp_path: Path, run_main
) -> None:
    d = _copy_analysis(analyzed, tmp_path / "a")
    meta_path = d / "model_geometry_meta.json"
    meta = json.loads(meta_path.read_text())
    meta["ranges"]["wedge"]["orientation_deg"] = [90.0, 90.0]  # trained along the Langer line
    meta_path.write_text(json.dumps(meta))
    row = _training_row(analyzed, "wedge")
    args = [a for a in _args(row) if a not in ("--orientation", str(row["orientation_deg"]))]
    rc, _, err = run_main("predict", d / "model_geometry.json", *args, "--angle-to-langer", "25")
    assert rc == 2
    assert "angle to the Langer line 25 deg (trained on 0..0 deg)" in err
    assert "orientation_deg" not in err


def _damaged_variants() -> list[tuple[str, str, object]]:
    """(file, key, damage): every top-level key of each metadata file removed or set to null,
    plus the classes round 4 found (a count of 0, a missing surrogate booster, nesting)."""
    keys = {
        "model_geometry_meta.json": [
            "scheme", "quantiles", "features", "stages", "quantile_edges_kPa",
            "skin_codes_c_kPa", "ranges", "levels",
        ],
        "surrogate_meta.json": ["calibration_scores_log", "features", "ranges"],
        "failure_model_meta.json": ["statement"],
    }  # fmt: skip
    out: list[tuple[str, str, object]] = []
    for name, ks in keys.items():
        for k in ks:
            out += [(name, k, "remove"), (name, k, None)]
    out += [
        ("model_geometry_meta.json", "quantiles", 0),
        ("model_geometry_meta.json", "quantiles", "8"),
        ("model_geometry_meta.json", "quantile_edges_kPa", [1.0, 2.0]),
        ("model_geometry_meta.json", "ranges", {"wedge": {"wound_width_factor": [1]}}),
        ("surrogate_meta.json", "calibration_scores_log", {"1": ["x"]}),
        ("surrogate.json", "", "delete"),
        ("model_geometry_meta.json", "", "nested"),
        ("model_geometry.json", "", "garbage"),
    ]
    return out


def test_damaged_analysis_files_give_one_line(analyzed: Path, tmp_path: Path, run_main) -> None:
    """Every damaged variant: exit 2 and one line on stderr, never a traceback."""
    row = _training_row(analyzed, "wedge")
    variants = _damaged_variants()
    assert len(variants) >= 18
    for i, (name, key, damage) in enumerate(variants):
        d = _copy_analysis(analyzed, tmp_path / f"v{i}")
        path = d / name
        if damage == "delete":
            path.unlink()
        elif damage == "nested":
            path.write_text('{"format": ' + "[" * 100000 + "]" * 100000 + "}")
        elif damage == "garbage":
            path.write_text("{not json")
        else:
            meta = json.loads(path.read_text())
            if damage == "remove":
                del meta[key]
            else:
                meta[key] = damage
            path.write_text(json.dumps(meta))
        rc, out, err = run_main("predict", d / "model_geometry.json", *_args(row))
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and lines[0].startswith("woundsweep: error:"), (
            name, key, damage, rc, err[-400:],
        )  # fmt: skip

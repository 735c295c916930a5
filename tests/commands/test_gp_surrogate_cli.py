"""``woundsweep analyze --param surrogate=gp --calibrate-on RUN2 --test-on RUN3`` and
``predict`` with the Gaussian-process surrogate, through the CLI: metrics and report of the
off-grid calibration and test, the saved GP's own answer, scale invariance, one-line
refusals of damaged GP files and of runs that do not match the analysed one."""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import SMALL_SWEEP, smooth_stress, write_results, write_store

from woundsweep.analysis.interpolant import GPSurrogate
from woundsweep.cli import main
from woundsweep.config.sweep import DEFAULTS
from woundsweep.store.reader import read_results

# test_surrogate_cli.py's sweep with two thicknesses (t_d replicates): 12 dimensionless
# geometries x 2 thicknesses x 3 skins x 3 orientations = 216 jobs x 6 stages = 1,296 rows.
SWEEP = {
    **SMALL_SWEEP,
    "grid": {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1, 2],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
    },
}
FAST = ["--param", "n_estimators=20", "--param", "learning_rate=0.3",
        "--param", "early_stopping_rounds=5", "--param", "sobol_samples=256"]  # fmt: skip
GP = ["--param", "surrogate=gp"]


def _between(td: float, widths: list[float], aspect: list[float], depth: list[float],
             orientations: list[float]) -> dict:  # fmt: skip
    """Wounds between the grid's widths, depths (offsets) and orientations of `SWEEP`."""
    grid = {**SWEEP["grid"], "dermal_thickness_mm": [td], "wound_width_factor": widths,
            "orientation_deg": orientations}  # fmt: skip
    shapes = {
        "cylindrical": {"wound_aspect_factor": aspect},
        "wedge": {"wound_depth_factor": depth},
    }
    return {**SWEEP, "name": "between", "grid": grid, "shapes": shapes}


# 48 jobs (288 rows) and 24 (144 rows) to calibrate on, 24 + 24 (144 + 144 rows) to test on.
CAL = _between(1.5, [0.37, 0.45], [0.03, 0.13], [0.37, 0.57], [15, 60])
CAL2 = _between(1.75, [0.41], [0.05, 0.15], [0.41, 0.61], [20, 70])
TEST = _between(1.25, [0.43], [0.07, 0.17], [0.43, 0.63], [30, 75])
TEST2 = _between(1.1, [0.39], [0.09, 0.19], [0.47, 0.67], [40, 80])


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The analysed run (GP surrogate, calibrated on two off-grid runs pooled and tested on two
    others pooled), the four others, and what analyze printed (``stdout``)."""
    base = tmp_path_factory.mktemp("gp")
    rd = {k: base / k for k in ("run", "cal", "cal2", "test", "test2")}
    write_store(rd["run"], smooth_stress, sweep=SWEEP, seed=3, failed_fraction=0.0)
    write_store(rd["cal"], smooth_stress, sweep=CAL, seed=4, failed_fraction=0.0)
    write_store(rd["cal2"], smooth_stress, sweep=CAL2, seed=6, failed_fraction=0.0)
    write_store(rd["test"], smooth_stress, sweep=TEST, seed=5, failed_fraction=0.0)
    write_store(rd["test2"], smooth_stress, sweep=TEST2, seed=7, failed_fraction=0.0)
    args = ["analyze", str(rd["run"]), "--split", "geometry", *FAST, *GP,
            "--calibrate-on", str(rd["cal"]), "--calibrate-on", str(rd["cal2"]),
            "--test-on", str(rd["test"]), "--test-on", str(rd["test2"]), "--no-figures"]  # fmt: skip
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(args) == 0
    rd["stdout"] = base / "analyze.txt"
    rd["stdout"].write_text(out.getvalue())
    return rd


def test_metrics_and_report_state_the_gp_and_the_off_grid_runs(runs: dict[str, Path]) -> None:
    a = runs["run"] / "analysis"
    m = json.loads((a / "metrics.json").read_text())
    s = m["surrogate"]
    assert s["surrogate"] == "gp" and m["settings"]["surrogate"] == "gp"
    assert "normalised scores" in s["calibration"]
    assert f"{runs['cal']} and {runs['cal2']} pooled" in s["calibration"]
    assert s["calibration_rows"] == 288 + 144 and "importance" not in s
    assert s["gp"]["groups"] == 36 and s["gp"]["rows"] == 2 * s["gp"]["points"]
    # The GP cannot see t_d: its Sobol total index is zero exactly, not merely small.
    assert s["sensitivity"]["indices"]["dermal_thickness_mm"]["ST"] == pytest.approx(0, abs=1e-12)
    off = m["off_grid_test"]
    assert off["run"] == f"{runs['test']} and {runs['test2']} pooled" and off["rows"] == 288
    alone = off["by_run"]
    assert [(r["run"], r["rows"]) for r in alone] == [
        (str(runs["test"]), 144),
        (str(runs["test2"]), 144),
    ]
    for level in ("0.8", "0.95"):
        c = off["coverage"][level]
        assert c["rows"] == 288 and 0 <= c["empirical"] <= 1
        # Its bootstrap interval over the test runs' 4 + 4 geometries (widths x offsets).
        assert c["geometries"] == 8 and c["interval"][0] <= c["empirical"] <= c["interval"][1]
        assert c["covered"] == sum(r["coverage"][level]["covered"] for r in alone)
    assert 0 < off["median_relative_error"] < 0.2
    # Equal sizes: the pooled mean offset is the runs' mean.
    assert off["mean_log_error"] == pytest.approx(np.mean([r["mean_log_error"] for r in alone]))
    q = off["quantile_classes"]["geometry"]
    assert set(q) >= {"surrogate_accuracy", "classifier_accuracy"}
    assert all(0 <= q[k] <= 1 for k in q if k != "edges_from")
    report = (a / "report.md").read_text()
    assert f"## Off the grid: {runs['test']} and {runs['test2']} pooled (`--test-on`)" in report
    assert f"| {runs['test2']} | 144 (4) |" in report.split("Each run alone:")[1]
    assert "Gaussian processes of log p99" in report and "Top three by Sobol total index" in report
    meta = json.loads((a / "surrogate_meta.json").read_text())
    assert meta["surrogate"] == "gp" and meta["calibration"] == s["calibration"]
    assert json.loads((a / "surrogate.json").read_text())["format"] == "woundsweep-gp-surrogate/2"


@pytest.fixture(scope="module")
def row(runs: dict[str, Path]) -> pd.Series:
    """A wedge row inside the trained ranges of the classifier and the surrogate."""
    rd = runs["run"]
    rows = read_results(rd)
    rows = rows[(rows["wound_shape"] == "wedge") & (rows["stage"] == 3)]
    for stem in ("model_geometry", "surrogate"):
        meta = json.loads((rd / "analysis" / f"{stem}_meta.json").read_text())
        for col, (lo, hi) in meta["ranges"]["wedge"].items():
            rows = rows[rows[col].between(lo, hi)]
    return rows.iloc[0]


def _args(row: pd.Series, **change: object) -> list[str]:
    r = {**row.to_dict(), **change}
    return [str(a) for a in (
        "--shape", "wedge", "--dermal-thickness", r["dermal_thickness_mm"],
        "--subcutis-thickness-factor", r["subcutis_thickness_factor"],
        "--patch-size-factor", r["patch_size_factor"], "--wound-width-factor", r["wound_width_factor"],
        "--wound-depth-factor", r["wound_depth_factor"], "--mesh-size-factor", r["mesh_size_factor"],
        "--orientation", r["orientation_deg"], "--skin-type", r["skin_type"], "--stage", int(r["stage"]),
    )]  # fmt: skip


def _gp_answer(rd: Path, row: pd.Series, **change: float) -> float:
    """The saved GP's own log p99 for the row, from the documented encoding."""
    gp = GPSurrogate.read(rd / "analysis" / "surrogate.json")
    r = {**row.to_dict(), **change}
    c_kPa = DEFAULTS["materials"]["skin_types"][r["skin_type"]]["c_kPa"]
    values = {**r, "wound_shape": 1.0, "skin_type": c_kPa, "wound_aspect_factor": np.nan}
    x = np.array([[float(values[f]) for f in gp.features]])
    return float(gp.predict_log(x)[0][0])


def test_predict_with_the_gp_answers_inside_its_interval(
    runs: dict[str, Path], row: pd.Series, run_main
) -> None:
    rd = runs["run"]
    rc, out, err = run_main("predict", rd, *_args(row), "--json", "--level", "0.8")
    assert rc == 0, err
    answer = json.loads(out)
    (pred,) = answer["predictions"]
    lo, hi = pred["interval_kPa"]
    assert lo < pred["stress_kPa"] < hi
    assert math.sqrt(lo * hi) == pytest.approx(pred["stress_kPa"], rel=1e-9)
    assert pred["stress_kPa"] == pytest.approx(math.exp(_gp_answer(rd, row)), rel=1e-12)
    assert answer["basis"]["surrogate"] == "gp"
    assert str(runs["cal"]) in answer["basis"]["calibration"]
    # Scale invariance: the other trained thickness gives the same answer, interval and all.
    other_td = 3.0 - float(row["dermal_thickness_mm"])  # 1 <-> 2
    rc, out2, err = run_main("predict", rd, *_args(row, dermal_thickness_mm=other_td), "--json",
                             "--level", "0.8")  # fmt: skip
    assert rc == 0, err
    pred2 = json.loads(out2)["predictions"][0]
    assert (pred2["stress_kPa"], pred2["interval_kPa"]) == (
        pred["stress_kPa"],
        pred["interval_kPa"],
    )
    rc, text, _ = run_main("predict", rd, *_args(row))
    assert "stress surrogate: gp; calibration: split-conformal, normalised scores" in text


def test_predict_evaluates_the_gp_at_the_asked_angle(
    runs: dict[str, Path], row: pd.Series, run_main
) -> None:
    rd = runs["run"]
    rc, out, err = run_main("predict", rd, *_args(row, orientation_deg=25.0), "--json")
    assert rc == 0, err
    answer = json.loads(out)
    assert [a for a, _ in answer["orientation_weights"]] == [0.0, 45.0]  # the classifier's
    pred = answer["predictions"][0]
    at = _gp_answer(rd, row, orientation_deg=25.0)
    assert pred["stress_kPa"] == pytest.approx(math.exp(at), rel=1e-12)
    lo, hi = pred["interval_kPa"]
    assert lo < pred["stress_kPa"] < hi


def _damage(d: Path, name: str, how: str) -> None:
    path = d / name
    doc = json.loads(path.read_text())
    if how == "garbage":
        path.write_text("[1, 2")
        return
    if how == "format":
        doc["format"] = "woundsweep-gp-surrogate/9"
    elif how == "kind":
        doc["surrogate"] = "forest"
    elif how == "features":
        doc["features"] = doc["features"][::-1]
    elif how == "lengths":
        del doc["groups"][3]["length_scales"]
    elif how == "noise":
        doc["groups"][0]["noise"] = 0.0
    elif how == "targets":
        doc["groups"][5]["log_p99"] = doc["groups"][5]["log_p99"][:-1]
    elif how == "shapes":
        doc["shapes"]["wedge"]["low"] = None
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize(
    "name, how",
    [
        ("surrogate.json", "garbage"), ("surrogate.json", "format"), ("surrogate.json", "lengths"),
        ("surrogate.json", "noise"), ("surrogate.json", "targets"), ("surrogate.json", "shapes"),
        ("surrogate_meta.json", "kind"), ("surrogate_meta.json", "features"),
    ],
)  # fmt: skip
def test_a_damaged_gp_file_is_one_line(
    runs: dict[str, Path], row: pd.Series, tmp_path: Path, run_main, name: str, how: str
) -> None:
    d = tmp_path / "a"
    shutil.copytree(runs["run"] / "analysis", d)
    _damage(d, name, how)
    rc, out, err = run_main("predict", d / "model_geometry.json", *_args(row))
    lines = err.strip().splitlines()
    assert rc == 2 and out == "" and len(lines) == 1, (how, err[-400:])
    assert lines[0].startswith("woundsweep: error:") and name in lines[0], lines[0]


def _other_store(base: Path, what: str, runs: dict[str, Path]) -> Path:
    """A calibration run that differs from the analysed one in ``what``."""
    rd = base / what
    if what == "element":
        write_store(rd, smooth_stress, sweep={**CAL, "solver": {"element_degree": 2}},
                    failed_fraction=0.0)  # fmt: skip
    elif what == "skin":
        normal = DEFAULTS["materials"]["skin_types"]["normal"]
        sweep = {**CAL, "grid": {**CAL["grid"], "skin_type": ["normal", "tough"]},
                 "materials": {"skin_types": {"tough": {**normal, "c_kPa": 30.0}}}}  # fmt: skip
        write_store(rd, lambda df, rng: np.full(len(df), 50.0), sweep=sweep, failed_fraction=0.0)
    elif what == "columns":  # the same wounds, without the nodal p99 column's values
        rd.mkdir()
        for f in ("sweep.yaml", "manifest.parquet"):
            shutil.copy(runs["cal"] / f, rd / f)
        rows = read_results(runs["cal"])
        write_results(rd, rows.assign(p99_von_mises_nodal_kPa=np.nan))
    return rd


@pytest.mark.parametrize(
    "what, option, needle",
    [
        ("element", "--calibrate-on", "element degree 2, the analysed run's is 1"),
        ("skin", "--test-on", "skin types tough the models did not train on"),
        ("columns", "--calibrate-on", "its rows hold the stress columns"),
    ],
)
def test_runs_unlike_the_analysed_one_are_refused_in_one_line(
    runs: dict[str, Path], tmp_path: Path, run_main, what: str, option: str, needle: str
) -> None:
    other = _other_store(tmp_path, what, runs)
    rc, _, err = run_main("analyze", runs["run"], *GP, option, other)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and needle in lines[0] and option in lines[0], err[-400:]


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--calibrate-on", "{run}"], "--calibrate-on {run}: the same run as the analysed run"),
        (["--test-on", "{cal}", "--calibrate-on", "{cal}"], "--test-on {cal}: the same run as --calibrate-on's"),
        (["--test-on", "{missing}"], "--test-on {missing}: no such run directory"),
        (["--calibrate-on", "{cal}", "--calibrate-on", "{cal}"], "--calibrate-on {cal}: the same run as --calibrate-on's"),
    ],
)  # fmt: skip
def test_a_missing_or_repeated_run_is_refused_before_reading(
    runs: dict[str, Path], tmp_path: Path, run_main, args: list[str], needle: str
) -> None:
    names = {"run": runs["run"], "cal": runs["cal"], "missing": tmp_path / "nope"}
    rc, _, err = run_main("analyze", runs["run"], *GP, *(a.format(**names) for a in args))
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and needle.format(**names) in lines[0], err[-400:]


def test_two_calibration_runs_pool_and_cross_calibrate(runs: dict[str, Path]) -> None:
    """``--calibrate-on`` twice: the intervals rest on both runs' rows (288 + 144), and each
    run is tested with intervals calibrated on the other alone."""
    a = runs["run"] / "analysis"
    m = json.loads((a / "metrics.json").read_text())
    meta = json.loads((a / "surrogate_meta.json").read_text())
    assert sum(len(v) for v in meta["calibration_scores_log"].values()) == 288 + 144
    x = m["off_grid_cross_calibration"]
    assert x["runs"] == [str(runs["cal"]), str(runs["cal2"])]
    first, second = x["folds"]
    fold = ("test_run", "calibrated_on", "rows", "calibration_rows")
    assert [first[k] for k in fold] == [str(runs["cal"]), [str(runs["cal2"])], 288, 144]
    assert [second[k] for k in fold] == [str(runs["cal2"]), [str(runs["cal"])], 144, 288]
    for level in ("0.8", "0.95"):
        p = x["pooled"]["coverage"][level]
        assert p["rows"] == 432
        covered = first["coverage"][level]["covered"] + second["coverage"][level]["covered"]
        assert p["covered"] == covered
        assert p["interval"][0] <= p["empirical"] <= p["interval"][1]
    assert "## Off the grid: cross-calibration by run" in (a / "report.md").read_text()
    out = runs["stdout"].read_text()
    assert "cross-calibration off the grid (all folds pooled; 432 rows)" in out
    assert f"off the grid ({runs['test']} and {runs['test2']} pooled, 288 rows): coverage" in out
    assert f"  {runs['test2']} (144 rows): coverage" in out

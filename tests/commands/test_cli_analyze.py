"""``woundsweep analyze`` and ``woundsweep predict`` through the CLI: outputs, determinism,
prediction against the saved booster, and one-line refusals of bad input (exit 2)."""

from __future__ import annotations

import contextlib
import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import (
    CLI_FAST,
    CLI_SWEEP,
    SMALL_SWEEP,
    depth_stress,
    write_results,
    write_store,
)

from woundsweep.cli import main
from woundsweep.config.sweep import DEFAULTS
from woundsweep.store.reader import read_results

FIGURES = [
    *(
        f"{stem}_{s}"
        for s in ("random", "geometry")
        for stem in ("training", "importance", "roc", "confusion")
    ),
    "stress_distribution",
    "stiff_vs_soft",
    "max_location",
    "max_location_profiles",
]
TRAINING_COLUMNS = [
    "wound_shape", "dermal_thickness_mm", "subcutis_thickness_factor", "patch_size_factor",
    "wound_width_factor", "wound_depth_factor", "wound_aspect_factor", "mesh_size_factor",
    "orientation_deg", "skin_type", "stage",
]  # fmt: skip


def assert_refused(rc: int, err: str, *needles: str) -> None:
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("woundsweep: error:"), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("cli") / "run"
    write_store(rd, depth_stress, sweep=CLI_SWEEP, seed=5)
    return rd


@pytest.fixture(scope="module")
def analyzed(store: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A copy of the store, analyzed once through the CLI (which reads the run's manifest
    once); and its stdout."""
    rd = tmp_path_factory.mktemp("analyzed") / "run"
    shutil.copytree(store, rd)
    buf = io.StringIO()
    manifest_reads = []
    read_parquet = pd.read_parquet

    def counted(path: object, *args: object, **kwargs: object) -> pd.DataFrame:
        # A path, or an open file (its name is the path).
        if Path(str(getattr(path, "name", path))).name == "manifest.parquet":
            manifest_reads.append(path)
        return read_parquet(path, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(buf):
        mp.setattr(pd, "read_parquet", counted)
        rc = main(["analyze", str(rd), *CLI_FAST])
    assert rc == 0
    assert len(manifest_reads) == 1
    return rd, buf.getvalue()


@pytest.fixture(scope="module")
def results(analyzed: tuple[Path, str]) -> pd.DataFrame:
    """The analyzed store's rows, read once through the store's validated reader."""
    return read_results(analyzed[0])


def test_analyze_writes_every_output(analyzed: tuple[Path, str], results: pd.DataFrame) -> None:
    rd, out = analyzed
    assert "random split" in out and "geometry split" in out and "test macro AUC" in out
    a = rd / "analysis"
    for stem in FIGURES:
        png, svg = a / f"{stem}.png", a / f"{stem}.svg"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", stem
        assert png.stat().st_size > 5000, stem
        assert b"<svg" in svg.read_bytes()[:2000], stem
    metrics = json.loads((a / "metrics.json").read_text())
    # The element of the rows (the writer stored the sweep's default, P1).
    assert (results["element_degree"] == 1).all()
    assert metrics["element_degree"] == 1 and metrics["element"].startswith("P1")
    # Settings: the sweep's analysis section, overridden by --param.
    assert metrics["settings"]["max_depth"] == 4
    assert metrics["settings"]["n_estimators"] == 30
    written = results
    assert metrics["rows"]["store_rows"] == len(written)
    assert metrics["rows"]["used_rows"] == int((written["status"] == "converged").sum()) - int(
        metrics["rows"]["duplicate_rows"]
    )
    for scheme in ("random", "geometry"):
        m = metrics["schemes"][scheme]
        assert sum(m["split_rows"].values()) == metrics["rows"]["used_rows"]
        assert len(m["quantile_edges_kPa"]) == 9
        assert len(m["eval_log"]["train"]["mlogloss"]) == m["rounds_run"]
        assert len(m["eval_log"]["validation"]["merror"]) == m["rounds_run"]
        assert np.asarray(m["test"]["confusion_matrix"]).sum() == m["split_rows"]["test"]
        assert m["test"]["auc_macro"] > 0.9
        assert (a / f"model_{scheme}.json").is_file() and (
            a / f"model_{scheme}_meta.json"
        ).is_file()
    report = (a / "report.md").read_text()
    assert "macro-average AUC" in report and "93.5%" in report and "79.9%" in report
    # The synthetic store has one mesh size factor and no stored line maxima.
    assert "No matched geometries" in report and not (a / "mesh_sensitivity.png").exists()
    assert (
        metrics["max_location_profiles"]["groups"]["stage 1"]["lines"]["along_wound"][
            "rows_without_position"
        ]
        == metrics["rows"]["used_rows_by_stage"]["1"]
    )


def test_identical_seeds_give_identical_metrics_with_or_without_figures(
    analyzed: tuple[Path, str], store: Path, tmp_path: Path, run_main
) -> None:
    rd = tmp_path / "again"
    shutil.copytree(store, rd)
    rc, out, err = run_main("analyze", rd, *CLI_FAST, "--no-figures")
    assert rc == 0, err
    a = rd / "analysis"
    assert not [p.name for p in a.iterdir() if p.suffix in (".png", ".svg")]
    # The same report but for its list of figures.
    first_report = (analyzed[0] / "analysis" / "report.md").read_text().split("## Figures")
    report = (a / "report.md").read_text().split("## Figures")
    assert report[0] == first_report[0]
    assert "[roc_random.png](roc_random.png)" in first_report[1]
    assert report[1].strip() == "None drawn (`analyze --no-figures`)."
    # The time it took: the last line, on stderr; stdout ends with the files written.
    assert out.splitlines()[-1].startswith("wrote ")
    assert re.fullmatch(
        r"analyze: [\d,]+ of 3,888 rows used, 2 splits, in \d+\.\d s", err.splitlines()[-1]
    ), err
    first = (analyzed[0] / "analysis" / "metrics.json").read_bytes()
    assert (rd / "analysis" / "metrics.json").read_bytes() == first
    assert (rd / "analysis" / "model_geometry.json").read_bytes() == (
        analyzed[0] / "analysis" / "model_geometry.json"
    ).read_bytes()


def _predict_args(row: pd.Series) -> list[str]:
    args = [
        "--shape", row.wound_shape,
        "--dermal-thickness", row.dermal_thickness_mm,
        "--subcutis-thickness-factor", row.subcutis_thickness_factor,
        "--patch-size-factor", row.patch_size_factor,
        "--wound-width-factor", row.wound_width_factor,
        "--mesh-size-factor", row.mesh_size_factor,
        "--orientation", row.orientation_deg,
        "--skin-type", row.skin_type,
        "--stage", int(row.stage),
    ]  # fmt: skip
    if row.wound_shape == "wedge":
        args += ["--wound-depth-factor", row.wound_depth_factor]
    else:
        args += ["--wound-aspect-factor", row.wound_aspect_factor]
    return [str(a) for a in args]


@pytest.mark.parametrize("shape", ["wedge", "cylindrical"])
def test_predict_returns_the_model_class_for_a_training_row(
    analyzed: tuple[Path, str],
    results: pd.DataFrame,
    shape: str,
    run_main,
) -> None:
    import xgboost as xgb

    rd = analyzed[0]
    rows = results
    row = rows[(rows["wound_shape"] == shape) & (rows["status"] == "converged")].iloc[7]
    rc, out, err = run_main("predict", rd, *_predict_args(row), "--json")
    assert rc == 0, err
    answer = json.loads(out)
    assert answer["scheme"] == "geometry"
    (pred,) = answer["predictions"]

    # The booster's own answer for the same row, from the documented encoding.
    booster = xgb.Booster()
    booster.load_model(str(rd / "analysis" / "model_geometry.json"))
    assert booster.feature_names == TRAINING_COLUMNS
    c_kPa = DEFAULTS["materials"]["skin_types"][row.skin_type]["c_kPa"]
    x = [1.0 if shape == "wedge" else 0.0, row.dermal_thickness_mm, row.subcutis_thickness_factor,
         row.patch_size_factor, row.wound_width_factor, row.wound_depth_factor, row.wound_aspect_factor,
         row.mesh_size_factor, row.orientation_deg, c_kPa, float(row.stage)]  # fmt: skip
    prob = booster.predict(xgb.DMatrix(np.array([x], dtype=float), feature_names=TRAINING_COLUMNS))[
        0
    ]
    assert pred["quantile"] == int(np.argmax(prob)) + 1
    assert pred["probabilities"] == pytest.approx(prob / prob.sum(), abs=1e-6)
    edges = json.loads((rd / "analysis" / "metrics.json").read_text())["schemes"]["geometry"][
        "quantile_edges_kPa"
    ]
    assert pred["stress_range_kPa"] == pytest.approx(
        edges[pred["quantile"] - 1 : pred["quantile"] + 1]
    )
    assert pred["extrapolated"] == []


def test_predict_refuses_or_flags_extrapolation(
    analyzed: tuple[Path, str], results: pd.DataFrame, run_main
) -> None:
    rd = analyzed[0]
    rows = results
    row = rows[rows["wound_shape"] == "wedge"].iloc[0].copy()
    row["dermal_thickness_mm"] = 3.0  # trained on 1 mm only
    rc, _, err = run_main("predict", rd, *_predict_args(row))
    assert_refused(rc, err, "dermal_thickness_mm=3", "--allow-extrapolation")
    rc, out, err = run_main(
        "predict", rd, *_predict_args(row), "--allow-extrapolation", "--split", "random"
    )
    assert rc == 0, err
    assert "EXTRAPOLATED" in out and "dermal_thickness_mm=3" in out and "random split" in out


def test_predict_refuses_the_other_shapes_factor(
    analyzed: tuple[Path, str], results: pd.DataFrame, run_main
) -> None:
    rows = results
    row = rows[rows["wound_shape"] == "wedge"].iloc[0]
    rc, _, err = run_main(
        "predict", analyzed[0], *_predict_args(row), "--wound-aspect-factor", "0.1"
    )
    assert_refused(rc, err, "wound_aspect_factor does not apply")
    rc, _, err = run_main("predict", analyzed[0].parent / "nowhere", *_predict_args(row))
    assert_refused(rc, err, "no such model file or run directory")


# -- bad input -----------------------------------------------------------------------------

TINY = {
    **SMALL_SWEEP,
    "grid": {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
    },
}


def test_analyze_without_results(tmp_path: Path, run_main) -> None:
    write_store(tmp_path, sweep=TINY)
    shutil.rmtree(tmp_path / "results")
    assert_refused(*run_main("analyze", tmp_path)[::2], "no result store")


def test_analyze_names_a_result_file_with_missing_columns(tmp_path: Path, run_main) -> None:
    rows = write_store(tmp_path, sweep=TINY)
    job = rows["job_id"].iloc[0]
    rows[rows["job_id"] == job].drop(columns=["p99_von_mises_kPa"]).to_parquet(
        tmp_path / "results" / f"job-{job}.parquet"
    )
    assert_refused(
        *run_main("analyze", tmp_path)[::2],
        f"job-{job}.parquet",
        "columns differ from the result schema",
    )


def test_analyze_without_converged_rows(tmp_path: Path, run_main) -> None:
    rows = write_store(tmp_path, sweep=TINY)
    write_results(tmp_path, rows.assign(status="diverged"))
    assert_refused(*run_main("analyze", tmp_path)[::2], "no converged rows")


def test_analyze_with_too_few_rows(tmp_path: Path, run_main) -> None:
    # 12 geometries x 9 jobs x 1 stage = 108 rows < 10 per class x 12 classes.
    write_store(tmp_path / "a", sweep=TINY, stages=(1,), failed_fraction=0.0)
    assert_refused(
        *run_main("analyze", tmp_path / "a", "--quantiles", "12")[::2],
        "108 usable rows",
        "at least 120",
    )
    # One geometry (54 rows): enough for 5 classes, but not for three sets of geometries.
    one = {
        **TINY,
        "grid": {**TINY["grid"], "wound_width_factor": [0.3]},
        "shapes": {"wedge": {"wound_depth_factor": [0.5]}},
    }
    write_store(tmp_path / "b", sweep=one, failed_fraction=0.0)
    rc, _, err = run_main("analyze", tmp_path / "b", "--quantiles", "5", "--split", "geometry")
    assert_refused(rc, err, "geometry split: empty validation set from 54 rows (1 geometries)")


def test_analyze_rejects_unknown_settings(tmp_path: Path, run_main) -> None:
    write_store(tmp_path, sweep=TINY)
    assert_refused(
        *run_main("analyze", tmp_path, "--param", "max_dept=3")[::2], "analysis.max_dept"
    )
    assert_refused(*run_main("analyze", tmp_path, "--param", "max_depth")[::2], "KEY=VALUE")

"""``woundsweep predict`` without MODEL: the shipped models (`analysis.shipped`), built by
scripts/ship_models.py from a packed table, answer exactly as the run they were analysed in,
say what they were trained on, and are refused in one line when missing or damaged."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any, NamedTuple

import pandas as pd
import pytest
from synthetic_store import PREDICT_FAST, PREDICT_FLAGS, PREDICT_SWEEP, depth_stress, write_store

from woundsweep.analysis import shipped
from woundsweep.cli import main
from woundsweep.core.errors import AnalysisError
from woundsweep.store.identity import file_sha256

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "ship_models.py"
SHIPPED = {
    "model_geometry.json", "model_geometry_meta.json", "surrogate.json", "surrogate_meta.json",
    "failure_model.json", "failure_model_meta.json", "trained_on.json",
}  # fmt: skip


class Shipped(NamedTuple):
    models: Path  # what ship_models.py wrote
    run: Path  # the run it analysed (kept with --work)
    rows: pd.DataFrame  # the store's rows of the packed jobs, as written
    sweep_jobs: int


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Shipped:
    """A third of the jobs left out of the packed table, a quarter of them failed (so a
    failure model is trained and shipped), then ship_models.py on the table."""
    base = tmp_path_factory.mktemp("shipped")
    store = base / "store"
    rows = write_store(store, depth_stress, sweep=PREDICT_SWEEP, seed=3, failed_fraction=0.25)
    left_out = rows.loc[rows["job_index"] % 3 == 0, "job_id"].unique()
    for jid in left_out:
        (store / "results" / f"job-{jid}.parquet").unlink()
    table = base / "table.parquet"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["pack", str(store), str(table)]) == 0
    models, work = base / "models", base / "work"
    argv = [sys.executable, str(SCRIPT), "--table", str(table), "--sweep",
            str(store / "sweep.yaml"), "--split", "geometry", *PREDICT_FAST,
            "--out", str(models), "--work", str(work)]  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    kept = rows[~rows["job_id"].isin(left_out)]
    return Shipped(models, work / "sweep", kept, int(rows["job_id"].nunique()))


@pytest.fixture
def use(monkeypatch: pytest.MonkeyPatch):
    """``use(path)``: the package's shipped models are those in ``path``."""

    def point(path: Path) -> None:
        monkeypatch.setattr(shipped, "models_dir", lambda: path)

    return point


def _wound(sh: Shipped, shape: str, at: float) -> dict[str, Any]:
    """A packed converged row inside the trained ranges, as the one-wound options' columns,
    at the fraction ``at`` of the trained orientations' range."""
    rows = sh.rows[(sh.rows["wound_shape"] == shape) & (sh.rows["status"] == "converged")]
    angles = [0.0, 90.0]
    for stem in ("model_geometry", "surrogate"):
        meta = json.loads((sh.models / f"{stem}_meta.json").read_text())
        for col, (lo, hi) in meta["ranges"][shape].items():
            rows = rows[rows[col].between(lo, hi)]
        lo, hi = meta["ranges"][shape]["orientation_deg"]
        angles = [max(angles[0], lo), min(angles[1], hi)]
    orientation = angles[0] + at * (angles[1] - angles[0])
    r = rows.iloc[0]
    own = "wound_depth_factor" if shape == "wedge" else "wound_aspect_factor"
    cols = ["dermal_thickness_mm", "subcutis_thickness_factor", "patch_size_factor",
            "wound_width_factor", own]  # fmt: skip
    return {"wound_shape": shape, **{c: float(r[c]) for c in cols},
            "orientation_deg": orientation, "skin_type": r["skin_type"]}  # fmt: skip


def _argv(wound: dict[str, Any]) -> list[str]:
    return [a for c, v in wound.items() for a in (PREDICT_FLAGS[c], str(v))]


def _expected_line(sh: Shipped) -> str:
    """The trained-on line, from the store's rows (not from any file ship_models wrote)."""
    jobs = sh.rows["job_id"].nunique()
    converged = int((sh.rows["status"] == "converged").sum())
    # depth_stress: every converged stress positive and distinct, so every such row is used
    return (
        f"shipped model: trained on {jobs:,} of {sh.sweep_jobs:,} synthetic jobs "
        f"({100 * jobs / sh.sweep_jobs:.3g} %; {converged:,} of their {converged:,} converged "
        "rows used); trees surrogate"
    )


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_the_shipped_files_are_the_analysed_runs(built: Shipped) -> None:
    assert {p.name for p in built.models.iterdir()} == SHIPPED
    for name in SHIPPED - {"trained_on.json"}:
        assert (built.models / name).read_bytes() == (built.run / "analysis" / name).read_bytes()
    record = json.loads((built.models / "trained_on.json").read_text())
    assert record["jobs"] == 72 == built.rows["job_id"].nunique()
    assert record["sweep_jobs"] == built.sweep_jobs == 108
    (table,) = record["tables"]
    assert table["sha256"] == file_sha256(Path(table["path"]))
    assert record["settings"]["n_estimators"] == 20 and record["surrogate"] == "trees"
    assert not any(built.models.parent.glob(".models.*"))  # the staging directory is gone


@pytest.mark.parametrize(("shape", "at"), [("wedge", 0.4), ("cylindrical", 1.0)])
def test_predict_without_model_answers_as_the_analysed_run(
    built: Shipped, use, run_main, shape: str, at: float
) -> None:
    use(built.models)
    wound = _argv(_wound(built, shape, at))
    rc, out, err = run_main("predict", built.run, *wound, "--json", "--level", "0.8")
    assert rc == 0 and err == "", err
    given = json.loads(out)
    rc, out, err = run_main("predict", *wound, "--json", "--level", "0.8")
    assert rc == 0 and err == "", err
    answer = json.loads(out)
    assert answer["model"] == str(built.models / "model_geometry.json")
    assert given["shipped_model"] is None
    assert answer["shipped_model"]["description"] == _expected_line(built)
    assert answer["shipped_model"]["trained_on"]["jobs"] == 72
    for doc in (given, answer):
        del doc["model"], doc["shipped_model"]
    assert answer == given
    assert answer["failure_probability"] is not None  # the failure model answered too


def test_the_text_answer_says_what_the_shipped_model_was_trained_on(
    built: Shipped, use, run_main
) -> None:
    use(built.models)
    wound = _argv(_wound(built, "wedge", 0.0))
    rc, out, err = run_main("predict", *wound)
    assert rc == 0, err
    lines = out.splitlines()
    assert lines[0].startswith(f"model: {built.models / 'model_geometry.json'} (geometry split")
    assert lines[1] == _expected_line(built)
    rc, given, _ = run_main("predict", built.run, *wound)
    assert given.splitlines()[1:] == lines[2:]  # the rest of the answer is the run's


def test_a_table_without_model_is_answered_as_with_the_run(
    built: Shipped, use, run_main, tmp_path: Path
) -> None:
    use(built.models)
    wounds = [_wound(built, "wedge", 0.4), _wound(built, "cylindrical", 0.0)]
    table = tmp_path / "wounds.csv"
    with table.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(dict.fromkeys(c for w in wounds for c in w)))
        writer.writeheader()
        writer.writerows(wounds)
    rc, given, err = run_main("predict", built.run, "--table", table, "--stage", "6")
    assert rc == 0 and err.splitlines() == ["2 of 2 wounds answered"], err
    rc, out, err = run_main("predict", "--table", table, "--stage", "6")
    assert rc == 0, err
    assert err.splitlines() == [_expected_line(built), "2 of 2 wounds answered"]
    assert out == given and len(out.splitlines()) == 3


@pytest.mark.parametrize("where", ["missing", "empty"])
def test_no_shipped_models_is_one_line(where: str, use, run_main, tmp_path: Path) -> None:
    d = tmp_path / where
    if where == "empty":
        d.mkdir()
    use(d)
    wound = ["--shape", "wedge", "--dermal-thickness", "1", "--subcutis-thickness-factor", "1",
             "--patch-size-factor", "2", "--wound-width-factor", "0.3",
             "--wound-depth-factor", "0.5", "--orientation", "0", "--skin-type", "normal"]  # fmt: skip
    rc, out, err = run_main("predict", *wound)
    line = _one_line(err)
    assert rc == 2 and out == ""
    assert line.startswith("woundsweep: error: no models shipped with woundsweep")
    assert str(d) in line and "make models" in line


def test_a_split_not_shipped_is_one_line(built: Shipped, use, run_main) -> None:
    use(built.models)
    rc, out, err = run_main("predict", *_argv(_wound(built, "wedge", 0.0)), "--split", "random")
    assert rc == 2 and out == ""
    assert "--split random: no shipped model of that split (shipped: geometry)" in _one_line(err)


def _damage(d: Path, how: str) -> None:
    path = d / "trained_on.json"
    record = json.loads(path.read_text())
    if how == "not JSON":
        path.write_text(path.read_text()[:100])
    elif how == "deleted":
        path.unlink()
    elif how == "jobs a string":
        path.write_text(json.dumps({**record, "jobs": "72"}))
    elif how == "no sweep_jobs":
        path.write_text(json.dumps({k: v for k, v in record.items() if k != "sweep_jobs"}))
    elif how == "more jobs than the sweep":
        path.write_text(json.dumps({**record, "jobs": record["sweep_jobs"] + 1}))
    elif how == "a model file changed":
        meta = d / "surrogate_meta.json"
        meta.write_text(meta.read_text() + " ")
    elif how == "a model file added":
        shutil.copyfile(d / "model_geometry.json", d / "model_random.json")


@pytest.mark.parametrize(
    ("how", "says"),
    [
        ("not JSON", "missing or unreadable"),
        ("deleted", "missing or unreadable"),
        ("jobs a string", "a malformed 'jobs'"),
        ("no sweep_jobs", "no 'sweep_jobs'"),
        ("more jobs than the sweep", "more jobs than its sweep has"),
        ("a model file changed", "surrogate_meta.json differs from the file it was written"),
        ("a model file added", "model_random.json is not among its files"),
    ],
)
def test_a_damaged_record_is_one_line(
    built: Shipped, use, run_main, tmp_path: Path, how: str, says: str
) -> None:
    d = tmp_path / "models"
    shutil.copytree(built.models, d)
    _damage(d, how)
    use(d)
    rc, out, err = run_main("predict", *_argv(_wound(built, "wedge", 0.0)))
    line = _one_line(err)
    assert rc == 2 and out == ""
    assert line.startswith(f"woundsweep: error: {d / 'trained_on.json'}: ")
    assert says in line and line.endswith("rebuild them with `make models`")


def test_install_replaces_the_directory_whole(built: Shipped, tmp_path: Path) -> None:
    dest = tmp_path / "models"
    dest.mkdir()
    (dest / "model_random.json").write_text("an older set")
    record = json.loads((built.models / "trained_on.json").read_text())
    files = shipped.install(built.run / "analysis", record, dest)
    assert {p.name for p in files} == SHIPPED  # the older file is gone with its set
    assert json.loads((dest / "trained_on.json").read_text()) == record
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models"]
    with pytest.raises(AnalysisError, match="no model_<split>.json to ship"):
        shipped.install(tmp_path / "nothing", record, dest)
    assert {p.name for p in dest.iterdir()} == SHIPPED  # a refused install changes nothing


def test_the_line_names_pooled_calibration_runs_and_their_cross_calibration() -> None:
    base = {"jobs": 10, "sweep_jobs": 100, "sweep": "paper", "used_rows": 50,
            "converged_rows": 60, "surrogate": "gp"}  # fmt: skip
    train = {"role": "training", "sweep": "paper"}
    one = {**base, "tables": [train, {"role": "calibration", "sweep": "cal"}]}
    assert shipped.describe(one).endswith("; gp surrogate, intervals calibrated on cal")
    cov = {"0.8": {"empirical": 0.819}, "0.95": {"empirical": 0.942}}
    two = {
        **base,
        "tables": [train, *({"role": "calibration", "sweep": n} for n in ("cal", "test"))],
        "off_grid_coverage": {"pooled": {"coverage": cov}},
    }
    assert shipped.describe(two).endswith(
        "; gp surrogate, intervals calibrated on cal and test pooled (coverage off the grid "
        "by cross-calibration: 82% at 80%, 94% at 95%)"
    )

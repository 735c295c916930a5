"""What `analyze` was trained on: recorded in metrics.json and the models, compared by
`predict` and `atlas` with the run as it is now; and `analyze` replaces analysis/ whole."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
from pathlib import Path

import pytest
import yaml
from dir_snapshot import snapshot
from synthetic_store import CLI_FAST, CLI_SWEEP, depth_stress, write_store

from woundsweep.cli import main

QUICK = [*CLI_FAST, "--param", "sobol_samples=16"]

pytestmark = pytest.mark.slow  # a store analyzed three times

PREDICT = [
    "--shape", "wedge", "--skin-type", "stiff", "--dermal-thickness", "1",
    "--subcutis-thickness-factor", "1", "--patch-size-factor", "2", "--wound-width-factor",
    "0.3", "--wound-depth-factor", "0.3", "--mesh-size-factor", "0.5", "--orientation", "0",
]  # fmt: skip


def _cli(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def analyzed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("stale") / "run"
    write_store(rd, depth_stress, sweep=CLI_SWEEP, seed=5)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["analyze", str(rd), *QUICK, "--no-figures"]) == 0
    return rd


def _warnings(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("woundsweep: warning:")]


def test_a_materials_change_makes_predict_and_atlas_warn(
    analyzed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rd = tmp_path / "run"
    shutil.copytree(analyzed, rd)
    record = json.loads((rd / "analysis" / "metrics.json").read_text())["trained_on"]
    meta = json.loads((rd / "analysis" / "model_geometry_meta.json").read_text())
    assert meta["trained_on"] == record and len(record["results_fingerprint"]) == 64
    assert not list(rd.glob(".analysis*"))  # the staging directory was swapped in
    site = tmp_path / "site"
    for argv in (["predict", rd, *PREDICT], ["atlas", rd, "--views", "none", "--out", site]):
        rc, _, err = _cli(capsys, *argv)
        assert rc == 0 and not _warnings(err), err

    sweep = yaml.safe_load((rd / "sweep.yaml").read_text())
    original = tmp_path / "original.yaml"
    original.write_text(yaml.safe_dump(sweep))
    sweep["materials"] = {"subcutis": {"C10_kPa": 0.8}}
    changed = tmp_path / "changed.yaml"
    changed.write_text(yaml.safe_dump(sweep))
    assert _cli(capsys, "generate", changed, "--out", rd, "--force")[0] == 0
    for argv in (["predict", rd, *PREDICT], ["atlas", rd, "--views", "none", "--out", site]):
        rc, out, err = _cli(capsys, *argv)
        warned = _warnings(err)
        assert rc == 0 and len(warned) == 1 and "is stale" in warned[0], err
        assert "sweep or manifest changed" in warned[0]
    # Back to the sweep it was trained on: current again.
    assert _cli(capsys, "generate", original, "--out", rd, "--force")[0] == 0
    rc, _, err = _cli(capsys, "predict", rd, *PREDICT)
    assert rc == 0 and not _warnings(err), err


def test_atlas_warns_when_the_results_changed_since_analyze(
    analyzed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rd = tmp_path / "run"
    shutil.copytree(analyzed, rd)
    for p in sorted((rd / "results").glob("job-*.parquet"))[:3]:
        p.unlink()
    rc, _, err = _cli(capsys, "atlas", rd, "--views", "none", "--out", tmp_path / "site")
    warned = _warnings(err)
    assert rc == 0 and len(warned) == 1 and "other results" in warned[0], err


def test_an_interrupted_analyze_leaves_the_old_analysis_whole(
    analyzed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rd = tmp_path / "run"
    shutil.copytree(analyzed, rd)
    before = snapshot(rd / "analysis")
    from woundsweep.analysis import figures

    def interrupted(*args: object, **kwargs: object) -> None:
        raise RuntimeError("killed")  # after the models were written, before metrics and report

    monkeypatch.setattr(figures, "write_all", interrupted)
    with pytest.raises(RuntimeError), contextlib.redirect_stdout(io.StringIO()):
        main(["analyze", str(rd), *QUICK, "--split", "random", "--seed", "7"])
    assert snapshot(rd / "analysis") == before
    monkeypatch.undo()
    with contextlib.redirect_stdout(io.StringIO()):
        argv = ["analyze", str(rd), *QUICK, "--split", "random", "--seed", "7", "--no-figures"]
        assert main(argv) == 0
    metrics = json.loads((rd / "analysis" / "metrics.json").read_text())
    meta = json.loads((rd / "analysis" / "model_random_meta.json").read_text())
    assert metrics["settings"]["seed"] == 7 and meta["trained_on"] == metrics["trained_on"]
    assert not list(rd.glob(".analysis*"))  # the interrupted one's staging directory is gone

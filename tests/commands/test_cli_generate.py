"""`woundsweep generate` through the real console entry point: outputs, bad input, idempotence."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pandas as pd
import pytest
import yaml
from cli_run import DEMO, ws


def test_help_and_version() -> None:
    out = ws("--help")
    assert out.returncode == 0 and "generate" in out.stdout
    ver = ws("--version")
    assert ver.returncode == 0 and "woundsweep, version" in ver.stdout


def test_generate_writes_manifest_sweep_and_provenance(tmp_path: Path) -> None:
    rd = tmp_path / "run"
    res = ws("generate", str(DEMO), "--out", str(rd))
    assert res.returncode == 0, res.stderr
    man = pd.read_parquet(rd / "manifest.parquet")
    assert len(man) == 32 and man["job_index"].tolist() == list(range(32))
    assert (rd / "sweep.yaml").read_text() == DEMO.read_text()
    prov = json.loads((rd / "provenance.json").read_text())
    assert prov["jobs"] == 32 and prov["woundsweep_version"]
    assert prov["units"]["length"] == "mm" and prov["units"]["stress"] == "kPa"
    assert prov["packages"]["numpy"] and prov["python"]


def test_regenerate_same_sweep_is_noop(tmp_path: Path) -> None:
    rd = tmp_path / "run"
    assert ws("generate", str(DEMO), "--out", str(rd)).returncode == 0
    stamp = os.stat(rd / "manifest.parquet").st_mtime_ns
    # Same content with other formatting and comments: still the same sweep.
    other = tmp_path / "demo-reformatted.yaml"
    other.write_text("# reformatted\n" + yaml.safe_dump(yaml.safe_load(DEMO.read_text())))
    res = ws("generate", str(other), "--out", str(rd))
    assert res.returncode == 0 and "nothing to do" in res.stdout
    assert os.stat(rd / "manifest.parquet").st_mtime_ns == stamp


def test_regenerate_other_sweep_refused_then_forced_keeps_results(tmp_path: Path) -> None:
    rd = tmp_path / "run"
    assert ws("generate", str(DEMO), "--out", str(rd)).returncode == 0
    (rd / "results").mkdir()
    (rd / "results" / "job-x.parquet").write_bytes(b"precious")
    data = yaml.safe_load(DEMO.read_text())
    data["grid"]["orientation_deg"] = [0, 45, 90]  # 32 -> 96 jobs
    other = tmp_path / "bigger.yaml"
    other.write_text(yaml.safe_dump(data))
    res = ws("generate", str(other), "--out", str(rd))
    assert res.returncode == 2 and "--force" in res.stderr
    assert len(pd.read_parquet(rd / "manifest.parquet")) == 32
    res = ws("generate", str(other), "--out", str(rd), "--force")
    assert res.returncode == 0, res.stderr
    assert len(pd.read_parquet(rd / "manifest.parquet")) == 96
    assert (rd / "results" / "job-x.parquet").read_bytes() == b"precious"


def _mutate(path: Path, edit) -> Path:  # type: ignore[no-untyped-def]
    data = yaml.safe_load(DEMO.read_text())
    edit(data)
    path.write_text(yaml.safe_dump(data))
    return path


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


BAD = {
    "syntax": (lambda p: _write(p, "grid: [1, 2\n"), "YAML syntax"),
    "unknown-top-key": (lambda p: _mutate(p, lambda d: d.update(gird={})), "gird"),
    "unknown-axis": (lambda p: _mutate(p, lambda d: d["grid"].update(colour=[1])), "grid.colour"),
    "unknown-material-key": (
        lambda p: _mutate(p, lambda d: d.update(materials={"subcutis": {"C01_kPa": 1}})),
        "materials.subcutis.C01_kPa",
    ),
    "wrong-type": (
        lambda p: _mutate(p, lambda d: d["grid"].update(dermal_thickness_mm=["thick"])),
        "grid.dermal_thickness_mm",
    ),
    "wrong-type-setting": (
        lambda p: _mutate(p, lambda d: d.update(stages={"contact_penalty_GPa": "high"})),
        "stages.contact_penalty_GPa",
    ),
    "unknown-contact-model": (
        lambda p: _mutate(p, lambda d: d.update(stages={"contact_model": "magic"})),
        "stages.contact_model",
    ),
    "empty-axis": (
        lambda p: _mutate(p, lambda d: d["grid"].update(mesh_size_factor=[])),
        "grid.mesh_size_factor",
    ),
    "negative-axis": (
        lambda p: _mutate(p, lambda d: d["grid"].update(wound_width_factor=[-0.3])),
        "grid.wound_width_factor",
    ),
    "unknown-skin": (
        lambda p: _mutate(p, lambda d: d["grid"].update(skin_type=["leathery"])),
        "grid.skin_type",
    ),
    "rule-unknown-name": (
        lambda p: _mutate(p, lambda d: d.update(exclude=["wound_volume_mm3 > 1"])),
        "exclude[0]",
    ),
    "zero-jobs": (
        lambda p: _mutate(p, lambda d: d.update(exclude=["wound_width_mm > 0"])),
        "zero jobs",
    ),
    "not-a-mapping": (lambda p: _write(p, "- 1\n- 2\n"), "mapping"),
    "missing-file": (lambda p: p.parent / "nope.yaml", "cannot read"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_sweep_is_one_line_exit_2(case: str, tmp_path: Path) -> None:
    make, expected = BAD[case]
    path = make(tmp_path / f"{case}.yaml")
    rd = tmp_path / "run"
    res = ws("generate", str(path), "--out", str(rd))
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert path.name in lines[0] and expected in lines[0]
    assert not (rd / "manifest.parquet").exists()


def test_bad_cli_arguments_exit_2(tmp_path: Path) -> None:
    res = ws("generate", str(DEMO))  # no --out
    assert res.returncode == 2 and "Traceback" not in res.stderr and "--out" in res.stderr
    res = ws("frobnicate")
    assert res.returncode == 2 and "Traceback" not in res.stderr

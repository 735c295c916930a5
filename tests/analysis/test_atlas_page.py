"""scripts/atlas_page.py: docs/atlas.md's side-by-side table holds the charted table's counts
(checked against the store, not against the script's own arithmetic), Figure 2's share at the
zone's ends recomputed from the stored line maxima, the hand-written part kept on regeneration,
the figures copied, and a run without analysis refused in one line."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import math
import re
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from synthetic_store import PREDICT_FAST, PREDICT_SWEEP, depth_stress, write_results, write_store

from woundsweep.cli import main

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "atlas_page.py"


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("atlas_page", SCRIPT)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def charted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, object]:
    root = tmp_path_factory.mktemp("atlas-page")
    rd = root / "run"
    rows = write_store(rd, depth_stress, sweep=PREDICT_SWEEP, seed=5, failed_fraction=0.1)
    # The line maxima along the wound (Figure 2's input): the global maximum's y, which the
    # synthetic store puts at the zone's ends in stage 2 and anywhere in the others.
    rows["profile_along_wound_max_at_mm"] = rows["max_location_y_mm"]
    write_results(rd, rows)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["analyze", str(rd), *PREDICT_FAST]) == 0
        assert main(["pack", str(rd), str(root / "table.parquet")]) == 0
    return rd, root / "table.parquet", rows


def _row(text: str, label: str) -> list[str]:
    line = next(x for x in text.splitlines() if x.startswith(f"| {label}"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_table_counts_match_the_store(charted, tmp_path: Path) -> None:
    rd, table, rows = charted
    out = tmp_path / "docs" / "atlas.md"
    with contextlib.redirect_stdout(io.StringIO()):
        assert _script().main([str(rd), "--table", str(table), "--out", str(out)]) == 0
    text = out.read_text()
    jobs = rows["job_id"].nunique()
    assert _row(text, "jobs x stages")[2].startswith(f"{jobs:,} x 6 = {len(rows):,}")
    converged = int((rows["status"] == "converged").sum())
    assert _row(text, "converged stage results")[2].startswith(f"{converged:,} (")
    assert converged < len(rows)  # the store has failures, so the count is not trivially all
    six = rows.groupby("job_id")["status"].agg(lambda s: (s == "converged").all())
    orient = rows.groupby("job_id")["orientation_deg"].first()
    for o in sorted(orient.unique()):
        sel = orient == o
        assert f"{o:g} deg {int(six[sel].sum())}/{int(sel.sum())}" in text

    # Figure 2: the share of converged stage-2 rows whose along-wound maximum lies within
    # 0.05 of the line's length of 1/3 or 2/3 (the zone's ends at y_fraction 1/3).
    s2 = rows[(rows["stage"] == 2) & (rows["status"] == "converged")]
    L = s2["patch_half_length_mm"].to_numpy(dtype=float)
    t = (s2["profile_along_wound_max_at_mm"].to_numpy(dtype=float) + L) / (2 * L)
    near = np.minimum(abs(t - 1 / 3), abs(t - 2 / 3)) <= 0.05
    cell = _row(text, "Figure 2, along-wound maximum")[2]
    assert cell.startswith(f"{100 * near.mean():.0f} % of {len(s2):,};")
    for name in ("training_random.png", "importance_random.png", "roc_random.png"):
        assert (out.parent / "figures" / "atlas" / name).is_file()
        assert f"figures/atlas/{name}" in text


def test_hand_written_part_is_kept(charted, tmp_path: Path) -> None:
    rd, table, _ = charted
    mod = _script()
    out = tmp_path / "atlas.md"
    out.write_text(f"old generated text\n{mod.MARK}\nWhy ours differs: a reason.\n")
    with contextlib.redirect_stdout(io.StringIO()):
        assert mod.main([str(rd), "--table", str(table), "--out", str(out)]) == 0
    text = out.read_text()
    assert "old generated text" not in text
    assert text.endswith(f"{mod.MARK}\nWhy ours differs: a reason.\n")
    assert len(re.findall(re.escape(mod.MARK), text)) == 1


def test_the_commands_section_states_each_timing_and_the_sizes(charted, tmp_path: Path) -> None:
    import json

    import woundsweep

    rd, table, rows = charted
    timings = tmp_path / "timings.json"
    timings.write_text(json.dumps([
        {"command": "status RUN", "wall_s": 1.73, "cpu_s": 1.5, "peak_memory_MB": 210},
        {"command": "status RUN", "wall_s": 0.4, "cpu_s": 0.3, "peak_memory_MB": 90, "note": "again"},
        {"command": "atlas RUN --views 0-9", "wall_s": 5.2, "cpu_s": 4.96, "peak_memory_MB": 1650},
    ]))  # fmt: skip
    out = tmp_path / "atlas.md"
    with contextlib.redirect_stdout(io.StringIO()):
        argv = [str(rd), "--table", str(table), "--out", str(out), "--timings", str(timings)]
        assert _script().main(argv) == 0
    text = out.read_text()
    assert "| `woundsweep status RUN` | 1.7 | 1.5 | 210 |" in text
    assert "| `woundsweep status RUN` (again) | 0.4 | 0.3 | 90 |" in text
    assert "| `woundsweep atlas RUN --views 0-9` | 5.2 | 5.0 | 1,650 |" in text
    assert f"On the run of the {rows['job_id'].nunique():,} charted jobs" in text
    assert f"The kept table is {table.stat().st_size / 1e6:.2f} MB" in text
    models = Path(woundsweep.__file__).parent / "models"
    size = sum(p.stat().st_size for p in models.iterdir())
    jobs = json.loads((models / "trained_on.json").read_text())["jobs"]
    assert f"are {size / 1e6:.2f} MB, trained on {jobs:,} jobs." in text.replace("\n", " ")


def test_atlas_build_times_a_command_and_stops_on_its_failure(monkeypatch, tmp_path) -> None:
    monkeypatch.syspath_prepend(str(SCRIPT.parent))
    spec = importlib.util.spec_from_file_location("atlas_build", SCRIPT.parent / "atlas_build.py")
    assert spec is not None and spec.loader is not None
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    held = np.ones(2**25)  # 256 MiB held by this process, not by the command
    with contextlib.redirect_stdout(io.StringIO()):
        demo = str(SCRIPT.parents[1] / "sweeps" / "demo.yaml")
        t = build.timed("generate", ["generate", demo, "--out", "run"], tmp_path)
        assert t["command"] == "generate" and t["wall_s"] > 0 and t["cpu_s"] > 0
        assert (tmp_path / "run" / "manifest.parquet").is_file()
        # A Python process with pandas, in MB (not kB), without the 256 MiB this process holds.
        assert 50 < t["peak_memory_MB"] < 256
        with pytest.raises(SystemExit, match=r"`woundsweep status nosuch` exited 2"):
            build.timed("status", ["status", "nosuch"], tmp_path)
    del held


def test_run_without_analysis_is_refused(tmp_path: Path, capsys) -> None:
    rd = tmp_path / "bare"
    rd.mkdir()
    assert _script().main([str(rd), "--out", str(tmp_path / "a.md")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "has no analysis" in err
    assert not (tmp_path / "a.md").exists()


def _cov(empirical: float, rows: int, interval: list[float] | None) -> dict:
    out = {"empirical": empirical, "covered": round(empirical * rows), "rows": rows}
    return {**out, "interval": interval, "interval_level": 0.9} if interval else out


def test_off_grid_rows_carry_the_coverage_interval_and_each_fold() -> None:
    mod = _script()
    cov = {"0.8": _cov(0.75, 800, [0.70, 0.81]), "0.95": _cov(0.915, 800, [0.886, 0.942])}
    assert mod._coverage(cov) == (
        "0.750 (600/800; 90 % 0.700-0.810) / 0.915 (732/800; 90 % 0.886-0.942)"
    )
    # Metrics written before the interval existed still render.
    assert mod._coverage({"0.8": _cov(0.5, 10, None)}) == "0.500 (5/10) / n/a"
    fold = {"rows": 800, "geometries": 24, "median_relative_error": 0.035, "coverage": cov,
            "mean_log_error": math.log(0.981)}  # fmt: skip
    m = {
        "surrogate": {"calibration": "... on the rows of A and B pooled (off the grid)"},
        "off_grid_cross_calibration": {
            "runs": ["A", "B"],
            "folds": [
                {**fold, "test_run": "A", "calibrated_on": ["B"]},
                {**fold, "test_run": "B", "calibrated_on": ["A"]},
            ],
            "pooled": {**fold, "rows": 1600, "geometries": 48},
        },
    }
    rows = mod._off_grid(m)
    assert len(rows) == 4 and all(r.startswith("| surrogate off the grid") for r in rows)
    assert "A (calibrated on B)" in rows[0] and "B (calibrated on A)" in rows[1]
    assert "calibrated on both runs pooled" in rows[2] and "48 geometries" in rows[2]
    assert "90 % 0.700-0.810" in rows[2]
    assert rows[3].endswith("| 3.5 %, mean offset -1.9 % |")
    # Metrics without the offset still render.
    del m["off_grid_cross_calibration"]["pooled"]["mean_log_error"]
    assert mod._off_grid(m)[3].endswith("| 3.5 %, mean offset n/a |")
    assert mod.analyze_command(m).endswith("--calibrate-on CAL1 --calibrate-on CAL2")
    m["off_grid_test"] = {"run": "T and U pooled", "by_run": [{"run": "T"}, {"run": "runs/U"}]}
    assert mod.analyze_command(m).endswith("--calibrate-on CAL2 --test-on TEST1 --test-on TEST2")
    # Runs not on this machine are named by their folders.
    assert mod.off_grid_runs(m).endswith("TEST2: `sweeps/U.yaml`, `charted/U.parquet`).")


def test_a_closure_beside_is_compared_on_the_jobs_both_runs_have(charted, tmp_path: Path) -> None:
    """A paper-code run of a slice (orientation 0) beside the charted run: a row for the run's
    closure on every job, then both closures on the slice's jobs, each share recomputed."""
    rd, table, rows = charted
    code = tmp_path / "code"
    sweep = {
        **PREDICT_SWEEP,
        "grid": {**PREDICT_SWEEP["grid"], "orientation_deg": [0]},
        "stages": {
            "closure_zone": {"y_fraction": 0.5, "depth_fraction": 0.5, "depth_per_w": 0.35},
            "closure_load": "paper-code",
        },
    }
    crow = write_store(code, depth_stress, sweep=sweep, seed=6)
    crow["profile_along_wound_max_at_mm"] = crow["max_location_y_mm"]
    write_results(code, crow)
    out = tmp_path / "atlas.md"
    argv = [str(rd), "--table", str(table), "--out", str(out), "--beside", str(code)]
    with contextlib.redirect_stdout(io.StringIO()):
        assert _script().main(argv) == 0
    text = out.read_text()
    shared = set(rows["job_id"]) & set(crow["job_id"])
    assert 0 < len(shared) == rows.loc[rows["orientation_deg"] == 0, "job_id"].nunique()

    def share(r, stage: int, ends: tuple[float, float]) -> str:
        s = r[(r["stage"] == stage) & (r["status"] == "converged") & r["job_id"].isin(shared)]
        L = s["patch_half_length_mm"].to_numpy(dtype=float)
        t = (s["profile_along_wound_max_at_mm"].to_numpy(dtype=float) + L) / (2 * L)
        near = np.minimum(abs(t - ends[0]), abs(t - ends[1])) <= 0.05
        return f"{100 * near.mean():.0f} % of {len(s):,};"

    n = f"{len(shared):,}"
    assert _row(text, "Figure 2, along-wound maximum at the zone's ends (reactions closure, every")
    own = _row(
        text, f"Figure 2, along-wound maximum at the zone's ends (reactions closure, the {n}"
    )
    assert own[2].startswith(share(rows, 2, (1 / 3, 2 / 3)))
    theirs = _row(
        text, f"Figure 2, along-wound maximum at the zone's ends (paper-code closure, the {n}"
    )
    assert theirs[2].startswith(share(crow, 2, (0.25, 0.75)))
    # Stiff > soft under the closure beside, from its own rows (every converged one with a
    # stress, paired by geometry, orientation and stage).
    ok = crow[(crow["status"] == "converged") & (crow["p99_von_mises_kPa"] > 0)]
    key = ["geometry_id", "orientation_deg", "stage"]
    st, so = (ok[ok["skin_type"] == k].set_index(key) for k in ("stiff", "soft"))
    both = st.join(so["p99_von_mises_kPa"].rename("soft"), how="inner")
    for shape, label in (("cylindrical", "curved wounds"), ("wedge", "wedges")):
        p = both[both["wound_shape"] == shape]
        up = int((p["p99_von_mises_kPa"] > p["soft"]).sum())
        cell = _row(text, f"stiff > soft, {label} (paper-code closure")[2]
        assert cell.startswith(f"{100 * up / len(p):.1f} % ({up:,}/{len(p):,})")
    flat = text.replace("\n", " ")
    assert "--beside BESIDE1`" in flat and "BESIDE1: `sweeps/synthetic.yaml`" in flat

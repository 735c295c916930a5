"""The packed results table: pack, unpack and what `run` then does with the unpacked jobs."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest
import yaml
from store_files import store_converged
from synthetic_store import SMALL_SWEEP, write_store

from woundsweep.cli import main
from woundsweep.commands.generate import generate
from woundsweep.config.manifest import load_run
from woundsweep.core.errors import StoreError
from woundsweep.core.runlock import hold_run, release
from woundsweep.core.versions import RESULT_FORMAT_VERSION
from woundsweep.execution.planning import needs_run
from woundsweep.store.packed import PACKED_KEY, pack, read_packed, unpack
from woundsweep.store.reader import read_results
from woundsweep.store.writer import Store

# 2 skins x 2 orientations x (3 + 3) shape values = 24 jobs.
SWEEP = {
    **SMALL_SWEEP,
    "name": "packed",
    "grid": {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
        "wound_width_factor": [0.5],
        "skin_type": ["normal", "stiff"],
        "orientation_deg": [0, 90],
    },
}
FIELD_COLUMNS = ["fields", "fields_file", "mesh_file", "fields_file_sha256", "mesh_file_sha256"]


def _fresh_run(tmp_path: Path, name: str, sweep: dict | None = None) -> Path:
    """An empty run directory of ``sweep`` (default `SWEEP`), made by `generate`."""
    yml = tmp_path / f"{name}.yaml"
    yml.write_text(yaml.safe_dump(sweep or SWEEP, sort_keys=False))
    rd = tmp_path / name
    generate(yml, rd)
    return rd


def _rows(rd: Path) -> pd.DataFrame:
    df = read_results(rd).sort_values(["job_index", "stage"]).reset_index(drop=True)
    return df.drop(columns=FIELD_COLUMNS)


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("packed") / "source"
    write_store(rd, sweep=SWEEP, failed_fraction=0.25, seed=3)
    return rd


def test_pack_then_unpack_gives_the_same_rows_and_run_skips_them(
    source: Path, tmp_path: Path
) -> None:
    table = tmp_path / "charted" / "results.parquet"
    c = pack(source, table)
    n = len(load_run(source).manifest)
    assert (c.added, c.replaced, c.unchanged, c.jobs, c.rows) == (n, 0, 0, n, 6 * n)
    assert pack(source, table)[:3] == (0, 0, n)  # the same run again: nothing changes
    rd = _fresh_run(tmp_path, "continued")
    u = unpack(table, rd)
    assert (u.written, u.present, u.other_settings, u.not_in_manifest) == (n, 0, 0, 0)
    assert unpack(table, rd).present == n
    pd.testing.assert_frame_equal(_rows(rd), _rows(source))
    back = read_results(rd)
    assert set(back["fields"]) == {"none"} and set(back["fields_file"]) == {""}
    store, run = Store(rd), load_run(rd)
    assert not any(
        needs_run(store, row, (1, 6), rerun_failed=False) for row in run.manifest.to_dict("records")
    )
    # The failed jobs are stored too: rerun-failed picks exactly them.
    failed = sum(
        needs_run(store, row, (1, 6), rerun_failed=True) for row in run.manifest.to_dict("records")
    )
    failed_jobs = back.groupby("job_id")["failure_class"].first().ne("converged").sum()
    assert failed == failed_jobs > 0


def test_a_table_grows_part_by_part_and_a_recomputed_job_replaces_its_rows(
    source: Path, tmp_path: Path
) -> None:
    table = tmp_path / "t.parquet"
    part = _fresh_run(tmp_path, "part")
    for i in (0, 1, 2):
        store_converged(part, i, fields="final")
    assert pack(part, table)[:4] == (3, 0, 0, 3)
    assert read_packed(table)[0].column("fields_file").to_pylist() == [""] * 18
    assert pack(source, table)[:3] == (21, 3, 0)  # the source computed jobs 0-2 anew
    assert pack(part, table)[:3] == (0, 3, 0)  # and part's are newer again
    store_converged(part, 3, tag="b")
    c = pack(part, table)
    assert (c.added, c.replaced, c.unchanged, c.jobs) == (0, 1, 3, 24)


def test_other_settings_and_other_sweeps_are_left_out(source: Path, tmp_path: Path) -> None:
    table = tmp_path / "t.parquet"
    pack(source, table)
    stiffer = {
        **SWEEP,
        "materials": {"skin_types": {"stiff": {"c_kPa": 85.2}, "soft": {}, "normal": {}}},
    }
    rd = _fresh_run(tmp_path, "stiffer", stiffer)
    u = unpack(table, rd)
    assert (u.written, u.other_settings, u.not_in_manifest) == (12, 12, 0)
    assert set(read_results(rd)["skin_type"]) == {"normal"}
    other = {**SWEEP, "grid": {**SWEEP["grid"], "orientation_deg": [45]}}
    u = unpack(table, _fresh_run(tmp_path, "other", other))
    assert (u.written, u.not_in_manifest) == (0, 24)


def test_damaged_or_foreign_tables_are_refused_in_one_line(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table = tmp_path / "t.parquet"
    pack(source, table)
    raw = pq.read_table(table)
    meta = json.loads(raw.schema.metadata[PACKED_KEY])

    def rewrite(t: object, m: dict) -> Path:
        bad = tmp_path / f"bad{len(list(tmp_path.glob('bad*')))}.parquet"
        pq.write_table(t.replace_schema_metadata({PACKED_KEY: json.dumps(m)}), bad)  # type: ignore[attr-defined]
        return bad

    p99 = raw.schema.get_field_index("p99_von_mises_kPa")
    changed = raw.set_column(p99, "p99_von_mises_kPa", pc_scale(raw.column(p99)))
    cases = {
        rewrite(changed, meta): "the values' sha256 differs",
        rewrite(raw, {**meta, "result_format": RESULT_FORMAT_VERSION - 1}): "result format",
        rewrite(raw.drop(["host"]), meta): "columns differ",
        rewrite(raw, {}): "not a packed results table",
        tmp_path / "missing.parquet": "no packed results table there",
    }
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(table.read_bytes()[: table.stat().st_size // 2])
    cases[junk] = "not a packed results table"
    rd = _fresh_run(tmp_path, "target")
    for path, why in cases.items():
        with pytest.raises(StoreError, match=why):
            read_packed(path)
        assert main(["unpack", str(path), str(rd)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and why in err and str(path) in err
    assert not (rd / "results").exists() or not list((rd / "results").iterdir())


def pc_scale(col: object) -> object:
    import pyarrow.compute as pc

    return pc.multiply(col, 1.0001)


def test_unpack_is_refused_while_a_run_holds_the_directory(source: Path, tmp_path: Path) -> None:
    table = tmp_path / "t.parquet"
    pack(source, table)
    rd = _fresh_run(tmp_path, "busy")
    lock = hold_run(rd, exclusive=False)
    try:
        assert main(["unpack", str(table), str(rd)]) == 2
    finally:
        release(lock)
    assert main(["unpack", str(table), str(rd)]) == 0
    assert main(["status", str(rd)]) == 0


def test_pack_bad_arguments_are_one_line(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "adir").mkdir()
    cases = [
        (["pack", str(tmp_path / "nowhere"), str(tmp_path / "t.parquet")], "not a run directory"),
        (["unpack", str(tmp_path / "t.parquet"), str(source)], "no packed results table"),
    ]
    table = tmp_path / "t2.parquet"
    pack(source, table)
    cases.append((["unpack", str(table), str(tmp_path / "nowhere")], "not a run directory"))
    for argv, why in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and why in err[0], err
    assert not (tmp_path / "t.parquet").exists()

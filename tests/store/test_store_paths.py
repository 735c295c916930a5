"""The store under any spelling of its path, and file names from data confined to the run.

A run directory whose path holds ``=`` and spaces is solved, counted and resumed like any
other (pyarrow must not read ``x=y`` path parts as partitions); a result footer that names a
fields file outside the store, and a manifest whose ``job_id`` is a path, are refused without
anything outside the run being moved or read.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from cli_run import WS, ForkCli
from dir_snapshot import snapshot
from runner_sweep import make_run
from store_files import manifest, store_converged

from woundsweep.execution.shards import partition
from woundsweep.store.reader import META_KEY, content_digest, read_results
from woundsweep.store.writer import Store


def _status(rd: Path) -> dict:
    res = subprocess.run([*WS, "status", str(rd), "--json"], capture_output=True, text=True)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    return json.loads(res.stdout)


@pytest.mark.fem
@pytest.mark.slow
def test_run_dir_with_equals_and_spaces_is_one_store_with_the_solver(tmp_path: Path) -> None:
    parent = tmp_path / "exp=1" / "my run=b c"
    parent.mkdir(parents=True)
    rd = make_run(parent, "run")  # 9 jobs; shard 0/9 holds one
    cmd = [*WS, "run", str(rd), "--no-progress", "--stages", "1-1", "--shard", "0/9"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert first.returncode == 0 and "0 already done, 1 run (1 converged)" in first.stdout, (
        first.stdout + first.stderr
    )
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert second.returncode == 0 and "1 already done, 0 run" in second.stdout, second.stderr
    assert second.stderr == "" and not (rd / "corrupt").exists()
    # The same store through another spelling of its path: a symlink without '='.
    alias = tmp_path / "alias"
    alias.symlink_to(rd)
    for where in (rd, alias, Path(os.path.relpath(rd))):
        s = _status(where)
        assert (s["jobs_done"], s["jobs_damaged"], s["jobs_pending"]) == (1, 0, 8), where
    df = read_results(rd)
    assert list(df.columns) == list(pd.read_parquet(alias / "results").columns)
    assert "exp" not in df.columns and "my run" not in df.columns and len(df) == 1


def _craft_footer(path: Path, **fields: str) -> None:
    """Rewrite a result file consistently (columns, footer, row digest) with other names."""
    table = pq.read_table(path)
    meta = json.loads(table.schema.metadata[META_KEY])
    for key, value in fields.items():
        meta[key] = value
        col = table.schema.get_field_index(key)
        table = table.set_column(col, key, pa.array([value] * len(table), pa.string()))
    table = table.replace_schema_metadata(None)
    meta["sha256"] = content_digest(table)
    table = table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
    pq.write_table(table, path, write_page_checksum=True)


@pytest.mark.parametrize("where", ["absolute", "dotdot", "other-job"])
def test_footer_naming_a_file_outside_the_store_moves_nothing_outside(
    cli: ForkCli, empty_run: Path, tmp_path: Path, where: str
) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("not the store's")
    store_converged(empty_run, 0)
    store_converged(empty_run, 1)
    other = Store(empty_run).result_path(manifest(empty_run)["job_id"].iloc[1])
    jid = manifest(empty_run)["job_id"].iloc[0]
    path = Store(empty_run).result_path(jid)
    name = {
        "absolute": str(victim),
        "dotdot": "../../victim.txt",
        "other-job": f"{manifest(empty_run)['job_id'].iloc[1]}.h5",
    }[where]
    _craft_footer(path, fields_file=name)
    outside = victim.read_bytes()
    fields_before = snapshot(empty_run / "fields")
    s = json.loads(cli(["status", str(empty_run), "--json"], tmp_path).stdout)
    assert (s["jobs_done"], s["jobs_damaged"]) == (1, 1)
    assert "footer's fields_file" in s["damaged_example"] and str(path) in s["damaged_example"]
    assert victim.read_bytes() == outside and snapshot(empty_run / "fields") == fields_before
    # run moves the crafted result file aside, and only it; the job is redone (a fault exit).
    # The shard of 32 that holds job 0.
    shard = next(i for i, idx in enumerate(partition(manifest(empty_run), 32)) if 0 in idx)
    env = {**os.environ, "WOUNDSWEEP_FAULT": "exit:2"}
    res = subprocess.run(
        [*WS, "run", str(empty_run), "--no-progress", "--no-warmup", "--shard", f"{shard}/32"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert victim.read_bytes() == outside
    moved = sorted(p.name for p in (empty_run / "corrupt").iterdir())
    assert len(moved) == 1 and moved[0].startswith(path.name)
    assert other.is_file() and snapshot(empty_run / "fields") == fields_before


def test_manifest_job_id_that_is_a_path_is_refused(cli: ForkCli, empty_run: Path) -> None:
    m = pd.read_parquet(empty_run / "manifest.parquet")
    m.loc[3, "job_id"] = "../../x"
    m.to_parquet(empty_run / "manifest.parquet", index=False)
    before = snapshot(empty_run.parent)
    for argv in (
        ["run", str(empty_run)],
        ["status", str(empty_run)],
        ["mesh", str(empty_run), "--job", "3"],
    ):
        res = cli(argv, empty_run.parent)
        lines = res.stderr.splitlines()
        assert res.code == 2 and len(lines) == 1 and "damaged manifest" in lines[0], res.stderr
        assert "job_id is not 16 hex digits" in lines[0]
    assert snapshot(empty_run.parent) == before


def test_a_job_process_checks_its_own_row_and_the_manifest_s_shape(empty_run: Path) -> None:
    """`load_run(rd, job)` recomputes only that job's ids (the runner checked every row):
    an edited row 3 is refused for job 3 and by the full check, not for job 5; a structural
    damage (an index out of order) is refused for every job."""
    from woundsweep.config.manifest import load_run
    from woundsweep.core.errors import StoreError

    path = empty_run / "manifest.parquet"
    m = pd.read_parquet(path)
    m.loc[3, "orientation_deg"] = 90.0 if m.loc[3, "orientation_deg"] != 90.0 else 0.0
    m.to_parquet(path, index=False)
    for job in (None, 3):
        with pytest.raises(StoreError, match="job 3: job_id is not the hash"):
            load_run(empty_run, job)
    assert len(load_run(empty_run, 5).manifest) == len(m)
    m.loc[[0, 1], "job_index"] = [1, 0]
    m.to_parquet(path, index=False)
    with pytest.raises(StoreError, match="job_index is not"):
        load_run(empty_run, 5)

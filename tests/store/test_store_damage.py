"""Damaged, stale and stray files in a run directory: how the store, `status`, the readers and
`run` find them, set them aside and redo the jobs.

Results are stored from solver outputs written by the test (tests/support/store_files.py).
`run` is real, with every solve replaced by the test-only fault switch (exit status 2, class
`invalid`), so the runner's resume, quarantine and store logic run without DOLFINx. `status`
and `generate` run through the CLI fork server (tests/support/cli_run.py).
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from cli_run import WS, ForkCli, demo_doc, generate_run
from store_files import manifest, outcome, solver_file, store_converged

from woundsweep.config.manifest import load_run
from woundsweep.core.errors import StoreError
from woundsweep.store.identity import result_fingerprint
from woundsweep.store.reader import read_results
from woundsweep.store.solverfile import read_solver_file
from woundsweep.store.writer import Store

DEMO = demo_doc()
SMALL = {
    **DEMO,
    "grid": {**DEMO["grid"], "dermal_thickness_mm": [1], "wound_width_factor": [0.3]},
    "shapes": {"cylindrical": {"wound_aspect_factor": [0, 0.2]}},
}  # 2 geometries x 2 skin types = 4 jobs


@pytest.fixture
def stored_run(tmp_path: Path) -> Path:
    """A 4-job run whose every job is stored as converged, fields and mesh files included."""
    rd = generate_run(SMALL, tmp_path)
    store = Store(rd)
    for i, job in manifest(rd).iterrows():
        src = tmp_path / f"solver-{i}.h5"
        solver_file(src, job, range(1, 7), mesh_seed=hash(job["geometry_id"]) % 1000)
        out = read_solver_file(src, job["job_id"], (1, 6))
        store.write_job(job.to_dict(), outcome("converged", out), (1, 6), "final", "0/1")
    return rd


def status(cli: ForkCli, rd: Path) -> dict[str, Any]:
    """`woundsweep status RD --json`, which must succeed without a word on stderr."""
    res = cli(["status", str(rd), "--json"], rd.parent)
    assert res.code == 0 and res.stderr == "", res.stderr
    return json.loads(res.stdout)


def run_with_fault(rd: Path) -> subprocess.CompletedProcess[str]:
    """`woundsweep run` whose solves exit at once with status 2 (class `invalid`)."""
    env = {**os.environ, "WOUNDSWEEP_FAULT": "exit:2"}
    return subprocess.run(
        [*WS, "run", str(rd), "--no-progress", "--no-warmup", "--workers", "2"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip


def footer_fingerprint(path: Path) -> str:
    return json.loads(pq.read_schema(path).metadata[b"woundsweep"])["fingerprint"]


def skin_of(path: Path) -> str:
    return str(pq.read_table(path, columns=["skin_type"]).column(0)[0])


# ---- stale results ------------------------------------------------------------------------
def test_job_state_is_stale_when_more_stages_are_asked_for(empty_run: Path) -> None:
    store = Store(empty_run)
    jid = manifest(empty_run)["job_id"].iloc[0]
    assert store.job_state(jid, (1, 6)).state == "missing"
    store_converged(empty_run, 0, stages=(1, 3))
    assert store.job_state(jid, (1, 3)) == ("done", "converged", "")
    assert store.job_state(jid, (2, 3)).state == "done"
    assert store.job_state(jid, (1, 6)).state == "stale"  # stages 4-6 asked for too


def test_fingerprint_covers_what_determines_a_result(empty_run: Path) -> None:
    """Each material value of the job's own skin type, the subcutis, every stage and solver
    setting change the fingerprint; another skin type's values, the analysis settings and the
    sweep's name do not; the job id never does."""
    from woundsweep.config.sweep import parse_sweep

    run = load_run(empty_run)
    job = run.manifest[run.manifest["skin_type"] == "stiff"].iloc[0]
    solver = {"element_degree": run.sweep.solver.element_degree}
    doc = {"grid": dict(run.sweep.grid), "shapes": dict(run.sweep.shapes), "solver": solver}
    base = result_fingerprint(parse_sweep(doc), job)
    assert len(base) == 64 and base == result_fingerprint(run.sweep, job)

    def fp(section: str, value: dict) -> str:
        return result_fingerprint(
            parse_sweep({**doc, section: {**doc.get(section, {}), **value}}), job
        )

    changed = [
        fp("materials", {"skin_types": {"stiff": {"c_kPa": 42.7}, "soft": {}}}),
        fp("materials", {"skin_types": {"stiff": {"mu_kPa": [35.6, 11.8, 11.9]}, "soft": {}}}),
        fp("materials", {"skin_types": {"stiff": {"tsf": 1.06}, "soft": {}}}),
        fp("materials", {"subcutis": {"K_kPa": 51}}),
        fp("stages", {"closure_zone": {"depth_fraction": 0.4}}),
        fp("stages", {"contact_penalty_GPa": [1, 5, 50]}),
        fp("stages", {"closure_zone": {"y_fraction": 0.5}}),
        fp("solver", {"quadrature_degree": 2}),
        fp("solver", {"rtol": 1e-9}),
    ]
    assert base not in changed and len(set(changed)) == len(changed)
    assert fp("materials", {"skin_types": {"stiff": {}, "soft": {"c_kPa": 99.0}}}) == base
    assert fp("analysis", {"max_depth": 3}) == base
    assert result_fingerprint(parse_sweep({**doc, "name": "other"}), job) == base
    other = run.manifest[run.manifest["skin_type"] == "soft"].iloc[0]
    assert result_fingerprint(run.sweep, other) != base


def test_fingerprint_covers_the_statistics_version(empty_run: Path, monkeypatch) -> None:
    """Results whose stress statistics were computed another way are stale."""
    from woundsweep.store import identity

    run = load_run(empty_run)
    job = run.manifest.iloc[0]
    base = identity.result_fingerprint(run.sweep, job)
    monkeypatch.setattr(identity, "STATISTICS_VERSION", identity.STATISTICS_VERSION + 1)
    assert identity.result_fingerprint(run.sweep, job) != base


def test_materials_change_makes_results_stale_and_run_recomputes_them(
    cli: ForkCli, stored_run: Path, tmp_path: Path
) -> None:
    rd = stored_run
    man0 = load_run(rd).manifest
    s = status(cli, rd)
    assert (s["jobs_done"], s["jobs_stale"], s["jobs_pending"]) == (4, 0, 0)
    soft = {p: p.read_bytes() for p in (rd / "results").iterdir() if "soft" in skin_of(p)}
    # Other values for the stiff skin: the same job ids, other results.
    doc = copy.deepcopy(SMALL)
    doc["materials"] = {"skin_types": {"stiff": {"c_kPa": 50.0}, "soft": {}}}
    (tmp_path / "s2.yaml").write_text(yaml.safe_dump(doc))
    refused = cli(["generate", "s2.yaml", "--out", "run"], tmp_path)
    assert refused.code == 2 and "--force" in refused.stderr
    forced = cli(["generate", "s2.yaml", "--out", "run", "--force"], tmp_path)
    assert forced.code == 0, forced.stderr
    assert "stored results: 2 stale" in forced.stdout
    run = load_run(rd)
    assert run.manifest["job_id"].tolist() == man0["job_id"].tolist()  # job_id: parameters only
    s = status(cli, rd)
    assert (s["jobs_done"], s["jobs_stale"], s["jobs_pending"]) == (2, 2, 2)
    assert set(read_results(rd)["skin_type"]) == {"soft"}  # analyze sees only current rows
    res = run_with_fault(rd)
    assert res.returncode == 0, res.stderr
    assert "4 jobs in shard: 2 already done, 2 run (2 invalid)" in res.stdout
    for _, job in run.manifest.iterrows():
        path = rd / "results" / f"job-{job['job_id']}.parquet"
        assert footer_fingerprint(path) == result_fingerprint(run.sweep, job)
    for p, data in soft.items():
        assert p.read_bytes() == data  # current results are not touched
    df = read_results(rd)
    assert set(df.loc[df["skin_type"] == "stiff", "failure_class"]) == {"invalid"}
    s = status(cli, rd)
    assert (s["jobs_done"], s["jobs_stale"], s["jobs_pending"]) == (4, 0, 0)


# ---- damaged result, fields and mesh files ------------------------------------------------
def test_silent_bit_flip_in_a_result_is_corrupt_and_quarantined(empty_run: Path) -> None:
    """A one-bit flip in a data page that a plain read does not notice: the page checksums do."""
    store = Store(empty_run)
    jid = manifest(empty_run)["job_id"].iloc[0]
    store_converged(empty_run, 0)
    path = store.result_path(jid)
    orig, table = path.read_bytes(), pq.read_table(path).to_pandas()
    for off in range(4, len(orig)):
        data = bytearray(orig)
        data[off] ^= 0x01
        path.write_bytes(bytes(data))
        try:
            plain = pq.read_table(path).to_pandas()
        except Exception:  # noqa: BLE001 - loud failures are not what this looks for
            continue
        if not plain.equals(table):  # read without error, wrong values
            break
    else:
        pytest.fail("no silent single-bit corruption found")
    st = store.job_state(jid, (1, 6))
    assert st.state == "corrupt" and str(path) in st.reason
    moved = store.quarantine(jid)
    assert moved is not None and moved.parent.name == "corrupt" and not path.exists()
    assert store.job_state(jid, (1, 6)).state == "missing"


def test_truncated_result_fails_analysis_reads_and_status_counts_it(
    cli: ForkCli, empty_run: Path
) -> None:
    store_converged(empty_run, 0)
    store_converged(empty_run, 1)
    path = Store(empty_run).result_path(manifest(empty_run)["job_id"].iloc[1])
    path.write_bytes(path.read_bytes()[:-30])
    with pytest.raises(StoreError, match="corrupt result file") as err:
        read_results(empty_run)
    assert str(path) in str(err.value) and "woundsweep run" in str(err.value)
    s = status(cli, empty_run)
    assert (s["jobs_done"], s["jobs_damaged"], s["jobs_pending"]) == (1, 1, 31)
    assert str(path) in s["damaged_example"]


@pytest.mark.parametrize("damage", ["truncated", "same-size"])
def test_damaged_fields_file_is_found_and_redone(
    cli: ForkCli, stored_run: Path, damage: str
) -> None:
    rd = stored_run
    jid = manifest(rd)["job_id"].iloc[0]
    fpath = rd / "fields" / f"{jid}.h5"
    data = fpath.read_bytes()
    if damage == "truncated":
        fpath.write_bytes(data[:1000])
    else:
        fpath.write_bytes(np.random.default_rng(1).integers(0, 256, len(data), np.uint8).tobytes())
        assert fpath.stat().st_size == len(data)
    st = Store(rd).job_state(jid, (1, 6))
    assert st.state == "damaged" and "fields" in st.reason
    s = status(cli, rd)
    assert (s["jobs_done"], s["jobs_damaged"], s["jobs_pending"]) == (3, 1, 1)
    assert str(fpath) in s["damaged_example"]
    if damage == "same-size":
        assert "sha256" in s["damaged_example"]
    res = run_with_fault(rd)
    assert res.returncode == 0, res.stderr
    assert "4 jobs in shard: 3 already done, 1 run (1 invalid)" in res.stdout
    moved = sorted(p.name.rsplit(".", 1)[0] for p in (rd / "corrupt").iterdir())
    assert moved == [f"{jid}.h5", f"job-{jid}.parquet"]
    df = read_results(rd)
    assert df.loc[df["job_id"] == jid, "failure_class"].unique().tolist() == ["invalid"]
    assert status(cli, rd)["jobs_damaged"] == 0


def test_truncated_mesh_file_redoes_the_jobs_of_its_geometry(
    cli: ForkCli, stored_run: Path
) -> None:
    rd = stored_run
    man = manifest(rd)
    gid = man["geometry_id"].iloc[0]
    mid = load_run(rd).geometry(man.iloc[0]).mesh_id
    mpath = rd / "fields" / f"mesh-{mid}.h5"
    mpath.write_bytes(mpath.read_bytes()[:-64])
    s = status(cli, rd)
    jobs = int((man["geometry_id"] == gid).sum())
    assert (s["jobs_done"], s["jobs_damaged"]) == (4 - jobs, jobs)
    res = run_with_fault(rd)
    assert res.returncode == 0, res.stderr
    assert f"{4 - jobs} already done, {jobs} run ({jobs} invalid)" in res.stdout
    assert len(list((rd / "corrupt").glob(f"mesh-{mid}.h5.*"))) == 1
    assert status(cli, rd)["jobs_damaged"] == 0


def test_generate_force_repairs_a_damaged_manifest(
    cli: ForkCli, demo_run: Path, tmp_path: Path
) -> None:
    shutil.copytree(demo_run, tmp_path / "run")
    (tmp_path / "demo.yaml").write_text(yaml.safe_dump(DEMO))
    man = tmp_path / "run" / "manifest.parquet"
    man.write_bytes(man.read_bytes()[:-100])
    assert cli(["status", "run"], tmp_path).code == 2
    res = cli(["generate", "demo.yaml", "--out", "run", "--force"], tmp_path)
    assert res.code == 0 and "32 jobs written" in res.stdout, res.stderr
    again = cli(["generate", "demo.yaml", "--out", "run"], tmp_path)
    assert again.code == 0 and "nothing to do" in again.stdout
    assert status(cli, tmp_path / "run")["jobs_pending"] == 32


# ---- stray and temporary files ------------------------------------------------------------
def test_dataset_reader_ignores_temporaries(empty_run: Path) -> None:
    import pandas as pd

    store_converged(empty_run, 0)
    # What a writer killed mid-write leaves: a dot-named partial file beside the results.
    (empty_run / "results" / ".job-deadbeef.parquet.x1.tmp").write_bytes(b"PAR1 partial")
    assert len(pd.read_parquet(empty_run / "results")) == 6
    assert len(read_results(empty_run)) == 6


def test_clean_tmp_removes_only_dead_runners_files(empty_run: Path) -> None:
    store = Store(empty_run)
    store.ensure_dirs()
    dead = subprocess.Popen(["true"])
    dead.wait()
    mine = store.tmp_path("aaaa", 1)
    theirs = store.tmp_dir / f"bbbb~{store.host}~{dead.pid}~1.h5"
    other_host = store.tmp_dir / f"cccc~elsewhere.example~{dead.pid}~1.h5"
    for p in (mine, theirs, other_host):
        p.write_bytes(b"x")
    assert store.clean_tmp() == 1
    assert mine.exists() and not theirs.exists() and other_host.exists()


def test_stray_files_in_results_are_ignored_by_every_reader(cli: ForkCli, stored_run: Path) -> None:
    rd = stored_run
    res_dir = rd / "results"
    (res_dir / "notes.txt").write_text("mine")
    (res_dir / "job-zz.parquet").write_bytes(b"PAR1 not a result PAR1")
    (res_dir / "job-0123456789abcdef.parquet.bak").write_bytes(b"x")
    (res_dir / "old").mkdir()
    os.mkfifo(res_dir / "job-0123456789abcdef.parquet")  # the store's name, not a file: no hang
    s = status(cli, rd)
    assert (s["jobs_done"], s["stray_files"], s["jobs_damaged"]) == (4, 5, 0)
    assert len(read_results(rd)) == 4 * 6
    res = run_with_fault(rd)
    assert res.returncode == 0 and "4 already done, 0 run" in res.stdout, res.stderr
    # A named pipe under a manifest job's result name: corrupt, moved aside, redone; no hang.
    victim = next(p for p in res_dir.glob("job-*.parquet") if p.is_file())
    victim.unlink()
    os.mkfifo(victim)
    s = status(cli, rd)
    assert (s["jobs_done"], s["jobs_pending"]) == (3, 1)
    res = run_with_fault(rd)
    assert res.returncode == 0 and "3 already done, 1 run" in res.stdout, res.stderr
    assert victim.is_file()

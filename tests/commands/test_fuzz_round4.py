"""Fuzz round 4 through the real CLI: the run directory as a boundary (no link followed out of
it for a write or a delete), files that are not regular where the run expects one, the
viewers' checks (checksums, stale solver files, crafted files), bookkeeping that fails
after a submission, a non-UTF-8 filesystem encoding, stale outputs of `case` and `atlas`,
closed standard streams, write errors, an unusable TMPDIR, control characters on stdout,
and the status of a large manifest. The bad inputs that need nothing stored are in
tests/support/bad_input_cases_round4.py (run by test_bad_inputs.py).

Runs: the viz fixture's store (tests/support/viz_store.py, gmsh, no DOLFINx), one-job runs
whose solves are replaced by the test-only fault switch, and the demo run's manifest.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from cli_run import WS, ForkCli, generate_run
from dir_snapshot import snapshot
from runner_sweep import SWEEP as RUNNER_SWEEP
from store_files import store_converged
from viz_store import SWEEP as VIZ_SWEEP
from viz_store import displacement, make_store, von_mises

from woundsweep.config.manifest import load_run
from woundsweep.core.diagnostics import StageReport
from woundsweep.mesh.cache import get_mesh, mesh_path
from woundsweep.store.identity import fingerprints, result_fingerprint
from woundsweep.store.solverfile import write_solver_file

ONE_JOB = {
    **RUNNER_SWEEP,
    "grid": {**RUNNER_SWEEP["grid"], "skin_type": ["stiff"], "orientation_deg": [0]},
    "shapes": {"cylindrical": {"wound_aspect_factor": [0]}},
}
FAULT = {"WOUNDSWEEP_FAULT": "exit:2"}  # a job that got as far as its solve ends at once


def one_line(res, code: int = 2, word: str = "") -> str:  # noqa: ANN001
    assert not res.timed_out, "hung"
    assert "Traceback" not in res.stderr, res.stderr
    # the viewers' progress bars share stderr: the command's own lines are the message
    lines = [line for line in res.stderr.splitlines() if line.startswith("woundsweep")]
    assert len(lines) == 1 and lines[0].startswith("woundsweep: error: "), res.stderr
    assert res.code == code, (res.code, res.stderr)
    assert word in lines[0], lines[0]
    return lines[0]


def outside(tmp_path: Path) -> Path:
    """A directory outside the run with a file older than a day (what `clean_tmp` removes)."""
    d = tmp_path / "outside"
    d.mkdir()
    f = d / "precious"
    f.write_text("keep me\n")
    old = time.time() - 3 * 86400
    os.utime(f, (old, old))
    return d


@pytest.fixture(scope="module")
def viz_template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_store(tmp_path_factory.mktemp("r4viz") / "run")


@pytest.fixture
def viz_run(viz_template: Path, tmp_path: Path) -> Path:
    rd = tmp_path / "run"
    shutil.copytree(viz_template, rd, symlinks=True)
    return rd


def fields_of(rd: Path, job: int) -> Path:
    return rd / "fields" / f"{load_run(rd).job(job)['job_id']}.h5"


# ---- the run directory is a boundary -------------------------------------------------------
@pytest.mark.parametrize("name", ["tmp", "logs", "results", "fields", "corrupt", "meshes"])
def test_run_follows_no_linked_store_directory(
    name: str, cli: ForkCli, empty_run: Path, tmp_path: Path
) -> None:
    out = outside(tmp_path)
    before = snapshot(out)
    link = empty_run / name
    shutil.rmtree(link, ignore_errors=True)
    link.symlink_to(out)
    res = cli(["run", str(empty_run), "--no-progress", "--no-warmup"], tmp_path, env=FAULT)
    one_line(res, 2, "symbolic link")
    assert snapshot(out) == before  # nothing deleted, nothing written outside the run


@pytest.mark.parametrize("kind", ["link-outside", "link-dev-zero", "fifo"])
def test_run_appends_to_no_log_but_a_regular_file(kind: str, cli: ForkCli, tmp_path: Path) -> None:
    rd = generate_run(ONE_JOB, tmp_path)
    out = outside(tmp_path)
    before = snapshot(out)
    log = rd / "logs" / f"job-{load_run(rd).job(0)['job_id']}.log"
    log.parent.mkdir()
    if kind == "fifo":
        os.mkfifo(log)
    else:
        log.symlink_to("/dev/zero" if kind == "link-dev-zero" else out / "precious")
    res = cli(["run", str(rd), "--no-progress", "--timeout", "5"], tmp_path, env=FAULT, timeout=60)
    one_line(res, 2, "not a regular file")
    assert snapshot(out) == before
    assert not (rd / "results").exists() or not any((rd / "results").iterdir())


# ---- files that are not regular where the run expects one --------------------------------
def test_named_pipes_and_devices_do_not_hang_the_viewers(
    cli: ForkCli, viz_run: Path, tmp_path: Path
) -> None:
    run = load_run(viz_run)
    log = viz_run / "logs" / f"job-{run.job(0)['job_id']}.log"
    log.unlink()
    os.mkfifo(log)
    res = cli(["atlas", str(viz_run), "--views", "0"], tmp_path, timeout=60)
    assert not res.timed_out and res.code == 0, res.stderr
    page = (viz_run / "atlas" / "jobs" / "job-0.html").read_text()
    assert "log not shown" in page and "a named pipe" in page
    cache = mesh_path(viz_run, run.geometry(run.job(0)).mesh_id)
    cache.unlink()
    cache.symlink_to("/dev/zero")  # rebuilt and replaced (the link, not /dev/zero)
    res = cli(["export", str(viz_run), "--job", "0", "--out", "exp"], tmp_path, timeout=60)
    assert not res.timed_out and res.code == 0, res.stderr
    assert cache.is_file() and not cache.is_symlink()
    fields = fields_of(viz_run, 0)
    fields.unlink()
    os.mkfifo(fields)
    res = cli(["view", str(viz_run), "--job", "0", "--out", "v.html"], tmp_path, timeout=60)
    one_line(res, 2, "fields file")


# ---- the viewers check what they read ------------------------------------------------------
@pytest.mark.parametrize("offset", [0.3, 0.9])
@pytest.mark.parametrize("command", ["view", "export", "atlas"])
def test_viewers_refuse_a_flipped_bit(
    command: str, offset: float, cli: ForkCli, viz_run: Path, tmp_path: Path
) -> None:
    f = fields_of(viz_run, 0)
    data = bytearray(f.read_bytes())
    data[int(offset * len(data))] ^= 0x10
    f.write_bytes(bytes(data))
    argv = {
        "view": ["view", str(viz_run), "--job", "0", "--out", "v.html"],
        "export": ["export", str(viz_run), "--all", "--out", "exp"],
        "atlas": ["atlas", str(viz_run), "--views", "0", "--out", "site"],
    }[command]
    one_line(cli(argv, tmp_path, timeout=60), 2, "damaged")


def test_view_refuses_a_damaged_mesh_file(cli: ForkCli, viz_run: Path, tmp_path: Path) -> None:
    (mesh,) = (viz_run / "fields").glob("mesh-*.h5")
    data = bytearray(mesh.read_bytes())
    data[len(data) // 2] ^= 0x01
    mesh.write_bytes(bytes(data))
    res = cli(["view", str(viz_run), "--job", "0", "--out", "v.html"], tmp_path, timeout=60)
    one_line(res, 2, "damaged")


def write_solve_file(rd: Path, job_index: int, path: Path, stamp: str | None = "current") -> Path:
    """A solver file of job ``job_index`` (stage 6 converged, the viz fixture's fields)."""
    run = load_run(rd)
    job = run.job(job_index)
    mesh = get_mesh(rd, run.geometry(job)).mesh
    u = displacement(mesh.points, 6, job_index).astype(np.float32)
    vm = von_mises(mesh.points, mesh.cells, 6, job_index).astype(np.float32)
    row = {"stage": 6, "status": "converged", "cells": len(mesh.cells), "dofs": 300}
    row.update(p99_von_mises_kPa=float(np.percentile(vm, 99)), max_von_mises_kPa=float(vm.max()))
    attrs = {"job_id": job["job_id"], "job_index": job_index, "geometry_id": job["geometry_id"]}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_solver_file(path, attrs, mesh, [StageReport.from_row(row)], {6: (u, vm)})
    if stamp is not None:  # what `woundsweep solve` records (`solverfile.FINGERPRINT_ATTR`)
        with h5py.File(path, "r+") as f:
            f.attrs["result_fingerprint"] = (
                result_fingerprint(run.sweep, job) if stamp == "current" else stamp
            )
    return path


def test_viewers_use_no_solve_file_of_an_earlier_sweep(
    cli: ForkCli, viz_run: Path, tmp_path: Path
) -> None:
    solved = write_solve_file(viz_run, 3, viz_run / "solve" / "job_3.h5")
    view = ["view", str(viz_run), "--job", "3", "--out", "v.html"]
    assert cli(view, tmp_path, timeout=60).code == 0  # solved with the run's sweep: shown
    doc = {**VIZ_SWEEP, "solver": {**VIZ_SWEEP["solver"], "max_iterations": 31}}
    (tmp_path / "changed.yaml").write_text(yaml.safe_dump(doc))
    gen = ["generate", str(tmp_path / "changed.yaml"), "--out", str(viz_run), "--force"]
    assert cli(gen, tmp_path).code == 0
    one_line(cli(view, tmp_path, timeout=60), 2, "other settings")
    export = ["export", str(viz_run), "--job", "3", "--out", "exp"]
    one_line(cli(export, tmp_path, timeout=60), 2, "other settings")
    result = ["view", str(viz_run), "--result", str(solved), "--out", "v2.html"]
    one_line(cli(result, tmp_path, timeout=60), 2, "other settings")
    write_solve_file(viz_run, 3, solved, stamp=None)  # records no fingerprint: not trusted
    one_line(cli(view, tmp_path, timeout=60), 2, "no result fingerprint")


def _craft(path: Path, kind: str) -> None:
    with h5py.File(path, "r+") as f:
        if kind in ("inf-displacement", "nan-displacement"):
            f["stage_6/displacement_mm"][0, 0] = np.inf if kind.startswith("inf") else np.nan
        elif kind == "inf-von-mises":
            f["stage_6/von_mises_kPa"][3] = -np.inf
        elif kind == "inf-points":
            f["mesh/points"][1, 2] = np.inf
        else:  # a dataset declared with 2.1e9 values (never written: the file stays small)
            group, name = (
                ("mesh", "points") if kind == "huge-points" else ("stage_6", "displacement_mm")
            )
            del f[f"{group}/{name}"]
            f[group].create_dataset(name, shape=(700_000_000, 3), dtype="f4", chunks=(4096, 3))


@pytest.mark.parametrize(
    "kind",
    ["inf-displacement", "nan-displacement", "inf-von-mises", "inf-points", "huge-displacement",
     "huge-points"],
)  # fmt: skip
def test_crafted_result_files_are_refused(
    kind: str, cli: ForkCli, viz_run: Path, tmp_path: Path
) -> None:
    path = write_solve_file(viz_run, 3, tmp_path / "crafted.h5")
    _craft(path, kind)
    res = cli(
        ["view", str(viz_run), "--result", str(path), "--out", "v.html"], tmp_path, timeout=60
    )
    one_line(res, 2, "crafted.h5")
    assert not (tmp_path / "v.html").exists()


# ---- bookkeeping that fails: what was submitted or computed is kept ------------------------
def _fake_sbatch(bin_dir: Path) -> Path:
    bin_dir.mkdir()
    log = bin_dir / "calls"
    exe = bin_dir / "sbatch"
    exe.write_text(
        f'#!/bin/sh\necho "$@" >> {log}\nn=$(wc -l < {log})\necho $((100 + n))\n'
    )  # fmt: skip
    exe.chmod(0o755)
    return log


def test_slurm_submits_nothing_over_a_damaged_record(
    cli: ForkCli, empty_run: Path, tmp_path: Path
) -> None:
    calls = _fake_sbatch(tmp_path / "bin")
    (empty_run / "slurm").mkdir()
    (empty_run / "slurm" / "jobs.json").write_text('{"submissions": ')
    env = {"PATH": f"{tmp_path / 'bin'}:/usr/bin:/bin"}
    res = cli(["slurm", str(empty_run), "--shards", "2", "--submit"], tmp_path, env=env)
    one_line(res, 2, "jobs.json")
    assert not calls.exists()  # refused before anything was submitted
    assert (empty_run / "slurm" / "jobs.json").read_text() == '{"submissions": '


def test_slurm_prints_the_ids_when_recording_fails(
    cli: ForkCli, empty_run: Path, tmp_path: Path
) -> None:
    calls = _fake_sbatch(tmp_path / "bin")
    (empty_run / "slurm" / "jobs.json").mkdir(parents=True)  # cannot be replaced by a file
    env = {"PATH": f"{tmp_path / 'bin'}:/usr/bin:/bin"}
    res = cli(["slurm", str(empty_run), "--shards", "2", "--submit"], tmp_path, env=env)
    line = one_line(res, 2, "could not record")
    assert "101, 102, 103" in line and len(calls.read_text().splitlines()) == 3
    assert "array job 102" in res.stdout


def test_a_c_locale_and_a_non_ascii_path_keep_a_valid_result(tmp_path: Path) -> None:
    where = tmp_path / "café"
    where.mkdir()
    rd = generate_run(ONE_JOB, where)
    store_converged(rd, 0)
    env = {**os.environ, **FAULT, "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONIOENCODING": ""}
    env.pop("LANG", None)
    for argv in (["status", str(rd), "--json"], ["run", str(rd), "--no-progress"]):
        res = subprocess.run(
            [*WS, *argv], capture_output=True, env=env, timeout=120, stdin=subprocess.DEVNULL
        )
        assert res.returncode == 0 and b"Traceback" not in res.stderr, res.stderr
    assert b"1 already done" in res.stdout
    assert not (rd / "corrupt").exists()


def test_a_failed_case_sets_the_previous_report_aside(
    run_main, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:  # noqa: ANN001
    import woundsweep.studies.case as study
    from woundsweep.core.errors import WoundsweepError

    out = tmp_path / "case"
    out.mkdir()
    (out / "report.md").write_text("# the previous case\n")
    (out / "case.json").write_text("{}")

    def fail(*args: object, **kwargs: object) -> None:
        raise WoundsweepError("the solve did not converge")

    monkeypatch.setattr(study, "run_case", fail)
    code, stdout, stderr = run_main("case", "--out", out, "--no-compare", "--element", "1")
    assert code == 2 and stderr.strip() == "woundsweep: error: the solve did not converge"
    assert not (out / "report.md").exists()
    assert (out / "previous" / "report.md").read_text() == "# the previous case\n"


def test_atlas_drops_the_pages_of_removed_jobs(cli: ForkCli, viz_run: Path, tmp_path: Path) -> None:
    site = ["atlas", str(viz_run), "--views", "none"]
    assert cli(site, tmp_path, timeout=60).code == 0
    pages = viz_run / "atlas" / "jobs"
    assert sorted(p.name for p in pages.iterdir()) == [f"job-{j}.html" for j in range(6)]
    doc = {**VIZ_SWEEP, "grid": {**VIZ_SWEEP["grid"], "orientation_deg": [0]}}  # 3 jobs
    (tmp_path / "fewer.yaml").write_text(yaml.safe_dump(doc))
    gen = ["generate", str(tmp_path / "fewer.yaml"), "--out", str(viz_run), "--force"]
    assert cli(gen, tmp_path).code == 0
    res = cli(site, tmp_path, timeout=60)
    assert res.code == 0 and "removed 3 pages" in res.stdout, res.stderr
    assert sorted(p.name for p in pages.iterdir()) == [f"job-{j}.html" for j in range(3)]


# ---- the process around a command ----------------------------------------------------------
@pytest.mark.parametrize(
    ("redirect", "code", "stderr"),
    [(">&-", 2, "woundsweep: error: standard output is closed\n"), ("<&-", 0, ""),
     ("2>&-", 0, "")],
)  # fmt: skip
def test_closed_standard_streams(redirect: str, code: int, stderr: str) -> None:
    cmd = " ".join(WS) + f" --help {redirect}"
    res = subprocess.run(["sh", "-c", cmd], capture_output=True, text=True, timeout=60)
    assert (res.returncode, res.stderr) == (code, stderr)


def test_write_errors_name_the_file_and_leave_no_temporaries(
    cli: ForkCli, viz_run: Path, tmp_path: Path
) -> None:
    res = cli(["atlas", str(viz_run), "--views", "none", "--out", "site"], tmp_path, fsize=3000)
    line = one_line(res, 2, "site/")
    assert "File too large" in line
    assert not [p for p in (tmp_path / "site").rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.parametrize("tmpdir", ["/proc", "/dev/null", "file"])
@pytest.mark.parametrize("command", ["solve", "run", "converge", "case"])
def test_an_unusable_tmpdir_is_one_line(
    command: str, tmpdir: str, cli: ForkCli, empty_run: Path, tmp_path: Path
) -> None:
    if tmpdir == "file":
        tmpdir = str(tmp_path / "a-file")
        Path(tmpdir).write_text("")
    argv = {
        "solve": ["solve", str(empty_run), "--job", "0"],
        "run": ["run", str(empty_run)],
        "converge": ["converge", str(empty_run), "--job", "0"],
        "case": ["case", "--out", "case"],
    }[command]
    before = snapshot(empty_run)
    one_line(cli(argv, tmp_path, env={"TMPDIR": tmpdir}), 2, f"TMPDIR={tmpdir}")
    assert snapshot(empty_run) == before


@pytest.mark.parametrize("char", ["\x07", "\x1b]0;title\x07", "\r", "\x08", "\x7f"])
def test_stdout_escapes_control_characters(char: str, cli: ForkCli, tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(ONE_JOB))
    res = cli(["generate", "s.yaml", "--out", f"run{char}x"], tmp_path)
    assert res.code == 0, res.stderr
    raw = [c for c in res.stdout if ord(c) < 32 and c != "\n" or ord(c) == 127]
    assert not raw and f"\\x{ord(char[0]):02x}" in res.stdout


def test_fingerprints_of_a_large_manifest_are_one_serialisation(paper) -> None:  # noqa: ANN001
    """`status` of a 10^6-job manifest spent minutes serialising the settings once per job:
    the column path gives every job's `result_fingerprint` at a few microseconds a job."""
    from cli_run import PAPER

    from woundsweep.config.manifest import canonical_hash, canonical_hashes, manifest_problem
    from woundsweep.config.sweep import GEOMETRY_KEYS, load_sweep

    sweep = load_sweep(PAPER)
    t0 = time.perf_counter()
    got = fingerprints(sweep, paper)
    elapsed = time.perf_counter() - t0
    rows = paper.to_dict("records")
    assert all(got[r["job_id"]] == result_fingerprint(sweep, r) for r in rows[::7])
    assert elapsed < 2.0, elapsed  # 11,664 jobs (row by row: about 10 s)
    keys = [*GEOMETRY_KEYS, "skin_type", "orientation_deg"]
    hashes = canonical_hashes(paper, keys)
    assert all(
        hashes[i] == canonical_hash({k: rows[i][k] for k in keys}) for i in range(0, len(rows), 7)
    )
    assert manifest_problem(paper, sweep) == ""

"""The commands on the whole paper grid: `status`, `status --json`, `analyze`, `atlas` and
`export` on a run of 11,664 synthetic results, each timed as a whole process.

Usage::

    python benchmarks/scale.py                # sweeps/paper.yaml, 11,664 jobs (about 30 min)
    python benchmarks/scale.py --jobs 500     # a sub-grid of the paper grid (a quick check)
    python benchmarks/scale.py --dir DIR      # build the run in DIR and keep it; a second
                                              # call with the same DIR reuses it

The run is the real one as far as the commands can tell: `woundsweep generate` writes the
manifest of sweeps/paper.yaml (or of a sub-grid: the largest grid axes cut until at most
``--jobs`` jobs remain), and `tests/support/synthetic_store.write_store` writes one result per
job through the store's own writer (a stress smooth in every factor; 3 % of the jobs fail at a
random stage, so status shows a mix). The jobs of ``--views`` then get fields (their meshes
built by gmsh, the known fields of `tests/support/viz_store`), so that the atlas draws their 3D
views and `export` has something to write. Prints per command its wall time, CPU time and
peak RSS (`os.wait4` on the child), the line the command prints about its own time, the
atlas site's size and, when headless Chromium is installed (`make test-deps`), how long the
atlas index takes to load, sort, filter and turn a page there. Asserts nothing about time.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "support"))

from synthetic_store import smooth_stress, write_store  # noqa: E402
from viz_store import displacement, von_mises  # noqa: E402

from woundsweep.config.manifest import expand, job_geometry, load_run  # noqa: E402
from woundsweep.config.sweep import parse_sweep  # noqa: E402

__all__ = ["main"]

WS = [sys.executable, "-m", "woundsweep"]
PAPER = ROOT / "sweeps" / "paper.yaml"
FAILED = 0.03  # share of the jobs that fail at a random stage


def sub_grid(doc: dict[str, Any], jobs: int) -> dict[str, Any]:
    """``doc`` with its longest numeric axes cut (last value first) until at most ``jobs``
    jobs remain; the skin types and both shapes are kept (analyze compares them)."""
    doc = yaml.safe_load(yaml.safe_dump(doc))  # a deep copy
    axes = [doc["grid"]] + list(doc["shapes"].values())
    while len(expand(parse_sweep(doc, "sub-grid"))) > jobs:
        longest = max(
            ((a, k) for a in axes for k, v in a.items() if k != "skin_type" and len(v) > 1),
            key=lambda ak: len(ak[0][ak[1]]),
            default=None,
        )
        if longest is None:
            break
        longest[0][longest[1]] = longest[0][longest[1]][:-1]
    doc["name"] = f"{doc['name']}-sub"
    return doc


def _with_fields(run_dir: Path, rows: pd.DataFrame, jobs: list[int]) -> None:
    """Store ``jobs`` again, their stages unchanged, with fields on their real meshes."""
    from woundsweep.core.diagnostics import StageReport
    from woundsweep.core.schema import ExitCode, FailureClass, StageStatus
    from woundsweep.mesh.cache import get_mesh
    from woundsweep.store.solverfile import read_solver_file, write_solver_file
    from woundsweep.store.writer import AttemptOutcome, Store

    run = load_run(run_dir)
    store = Store(run_dir)
    for j in jobs:
        job = run.manifest.iloc[j].to_dict()
        mesh = get_mesh(run_dir, job_geometry(run.sweep, job)).mesh
        stages = rows[rows["job_index"] == j].to_dict("records")
        reports, fields = [], {}
        for r in stages:
            if r["status"] == StageStatus.NOT_RUN:
                continue
            k = int(r["stage"])
            vm = von_mises(mesh.points, mesh.cells, k, j).astype(np.float32)
            keep = {c: r[c] for c in ("stage", "status", "newton_iterations", "time_s")}
            if r["status"] == StageStatus.CONVERGED:
                fields[k] = (displacement(mesh.points, k, j).astype(np.float32), vm)
                keep |= {"p99_von_mises_kPa": float(np.percentile(vm, 99))}
                keep |= {"max_von_mises_kPa": float(vm.max())}
            reports.append(StageReport.from_row(keep | {"cells": len(mesh.cells)}))
        path = run_dir / "tmp" / f"{job['job_id']}.h5"
        attrs = {"job_id": job["job_id"], "job_index": j, "geometry_id": job["geometry_id"]}
        write_solver_file(path, attrs, mesh, reports, fields)
        out = read_solver_file(path, job["job_id"], (1, 6))
        ok = len(fields) == len(stages)
        cls = FailureClass.CONVERGED if ok else FailureClass.NOT_CONVERGED
        code = ExitCode.OK if ok else ExitCode.NOT_CONVERGED
        outcome = AttemptOutcome(
            cls.value, "", int(code), 1, 1.0, 1.0, 1.0, 1.0, None, 0.0, 1.0, out
        )
        store.write_job(job, outcome, (1, 6), "all", "0/1")
        path.unlink(missing_ok=True)


def build(run_dir: Path, jobs: int, views: list[int]) -> None:
    """The run: generate's manifest, synthetic results for every job, fields for ``views``."""
    doc = yaml.safe_load(PAPER.read_text())
    sweep_file = PAPER
    if jobs < len(expand(parse_sweep(doc, str(PAPER)))):
        doc = sub_grid(doc, jobs)
        sweep_file = run_dir.parent / f"{run_dir.name}-sweep.yaml"
        sweep_file.write_text(yaml.safe_dump(doc, sort_keys=False))
    timed("generate", "generate", str(sweep_file), "--out", str(run_dir))
    # write_store writes its own sweep copy and manifest (the same expansion): generate's are
    # put back, so the run is exactly what generate made.
    kept = {name: (run_dir / name).read_bytes() for name in ("sweep.yaml", "manifest.parquet")}
    t0 = time.perf_counter()
    rows = write_store(run_dir, smooth_stress, sweep=doc, seed=0, failed_fraction=FAILED)
    for name, data in kept.items():
        (run_dir / name).write_bytes(data)
    manifest = load_run(run_dir).manifest
    assert rows["job_id"].drop_duplicates().tolist() == manifest["job_id"].tolist()
    print(f"{'store':<26}{time.perf_counter() - t0:>9.1f} s   {rows['job_id'].nunique():,} "
          f"jobs, {len(rows):,} rows written (synthetic_store.write_store)", flush=True)  # fmt: skip
    t0 = time.perf_counter()
    _with_fields(run_dir, rows, views)
    print(f"{'fields':<26}{time.perf_counter() - t0:>9.1f} s   jobs {views[0]}-{views[-1]}")


def timed(label: str, *args: str) -> dict[str, Any]:
    """Run ``woundsweep ARGS`` as its own process; print and return its wall time, CPU time,
    peak RSS and its own last line on stderr."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([*WS, *args], stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        lines = [ln.rsplit("\r", 1)[-1] for ln in err.read().splitlines()]
    if proc.returncode != 0:
        raise SystemExit(f"{label}: exit {proc.returncode}: {lines[-3:]}")
    cmd = args[0]
    own = next((ln for ln in reversed(lines) if ln.startswith(f"{cmd}:")), "")
    rec = {
        "wall_s": wall,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "rss_MB": usage.ru_maxrss / 1024,  # kB on Linux
        "own": own,
    }
    print(
        f"{label:<26}{wall:>9.1f} s {rec['cpu_s']:>8.1f} s CPU {rec['rss_MB']:>7.0f} MB peak"
        + (f"   [{own}]" if own else ""),
        flush=True,
    )
    return rec


def _tree_bytes(path: Path) -> tuple[int, int]:
    files = [p for p in path.rglob("*") if p.is_file()]
    return len(files), sum(p.stat().st_size for p in files)


def browser_times(index: Path) -> None:
    """Load, sort, filter and page the atlas index in headless Chromium; print the times."""
    import pytest
    from browser import start_chromium

    try:
        driver = start_chromium()
    except pytest.skip.Exception as why:
        print(f"browser: not measured ({why})")
        return
    # Each action as the page sees it: the handler, then a forced layout of the new rows.
    act = (
        "var t=performance.now(); (function(){%s})(); document.body.offsetHeight;"
        "return [performance.now()-t, document.getElementById('count').textContent,"
        " document.querySelectorAll('#index tbody tr').length];"
    )
    try:
        t0 = time.perf_counter()
        driver.get(index.as_uri())
        rows = 0
        while rows == 0 and time.perf_counter() - t0 < 120:
            rows = driver.execute_script(
                "return document.querySelectorAll('#index tbody tr').length"
            )
        load = time.perf_counter() - t0
        nav = driver.execute_script(
            "var n=performance.getEntriesByType('navigation')[0]; return n.domContentLoadedEventEnd;"
        )
        count = driver.find_element("id", "count").text
        print(f"{'index load':<26}{load:>9.2f} s   (DOMContentLoaded {nav / 1e3:.2f} s; "
              f"{rows} DOM rows: {count})")  # fmt: skip
        actions = [
            ("sort by p99 s6", "document.querySelector(\"th[data-col='p99_s6']\").click()"),
            ("sort again (descending)", "document.querySelector(\"th[data-col='p99_s6']\").click()"),
            ("next page", "document.querySelector(\"#pager button[data-page='next']\").click()"),
            ("last page", "document.querySelector(\"#pager button[data-page='last']\").click()"),
            ("filter skin_type soft", _typed("skin_type", "soft")),
            ("filter p99 s6 >100", _typed("p99_s6", ">100")),
            ("1,000 rows per page", "var s=document.getElementById('pagesize'); s.value='1000';"
                                    " s.dispatchEvent(new Event('change'))"),
            ("clear filters", "document.getElementById('clearfilters').click()"),
        ]  # fmt: skip
        for label, js in actions:
            ms, count, n = driver.execute_script(act % js)
            print(f"{'  ' + label:<26}{ms:>9.1f} ms  ({n} DOM rows: {count})")
    finally:
        driver.quit()


def _typed(col: str, value: str) -> str:
    return (
        f"var i=document.querySelector(\"input[data-col='{col}']\"); i.value='{value}';"
        " i.dispatchEvent(new Event('input'))"
    )


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--jobs", type=int, default=11664, help="at most this many jobs (a sub-grid)")
    p.add_argument("--dir", type=Path, help="build the run here and keep it (reused if there)")
    p.add_argument("--views", default="0-9", help="jobs with fields and a 3D view (a-b)")
    p.add_argument("--nthread", type=int, default=2, help="analyze --nthread")
    a = p.parse_args(argv)
    lo, _, hi = a.views.partition("-")
    views = list(range(int(lo), int(hi or lo) + 1))
    base = Path(a.dir) if a.dir else Path(tempfile.mkdtemp(prefix="ws-scale-"))
    run_dir = base / "run"
    try:
        print(f"{'step':<26}{'wall':>11} {'CPU':>12} {'peak RSS':>12}")
        if not (run_dir / "manifest.parquet").exists():
            base.mkdir(parents=True, exist_ok=True)
            build(run_dir, a.jobs, views)
        else:
            print(f"reusing {run_dir} ({len(load_run(run_dir).manifest):,} jobs)")
        rd, site = str(run_dir), base / "atlas"
        timed("status", "status", rd)
        timed("status --json", "status", rd, "--json")
        timed(f"analyze --nthread {a.nthread}", "analyze", rd, "--nthread", str(a.nthread))
        shutil.rmtree(site, ignore_errors=True)
        timed(f"atlas --views {a.views}", "atlas", rd, "--views", a.views, "--out", str(site))
        files, size = _tree_bytes(site)
        index = site / "index.html"
        print(f"{'atlas site':<26}{size / 1e6:>9.1f} MB  {files:,} files; index.html "
              f"{index.stat().st_size / 1e6:.1f} MB")  # fmt: skip
        for j in views[:3]:
            timed(f"export --job {j}", "export", rd, "--job", str(j), "--out", str(base / "exp"))
        browser_times(index)
    finally:
        if not a.dir:
            shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()

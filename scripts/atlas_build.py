"""Build docs/atlas.md from the kept tables (`make atlas-page`).

    python scripts/atlas_build.py --dir runs/atlas-page \
        --cal paper-random-1 --cal paper-random-2 \
        --test paper-between-calibration --test paper-between-test

Makes a run of each sweep (``sweeps/NAME.yaml``) with its kept table (``charted/NAME.parquet``)
unpacked into ``DIR/NAME`` (``DIR`` replaced), analyses the paper run from inside ``DIR`` (so
the reports name the runs by sweep) with the GP surrogate, its intervals calibrated on the
``--cal`` runs pooled and tested on the ``--test`` runs, Figure 2 of each ``--beside`` run (the
same jobs under another closing load) drawn beside its own, then runs ``status`` twice (cold, then
from the read cache) and ``atlas --views 0-9`` on it. Each command on the paper run is timed
(wall, CPU of the process and its children, peak memory; ``DIR/timings.json``), and
scripts/atlas_page.py writes the page with those times.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import atlas_page

PAPER = "paper"


def _hwm_mb(pid: int) -> float:
    """The process's peak resident memory so far (Linux ``VmHWM``), MB; 0 once it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    kb = next((line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:")), 0)
    return int(kb) / 1024


def timed(label: str, args: list[str], cwd: Path) -> dict[str, Any]:
    """Run ``woundsweep ARGS`` in ``cwd``, its stdout shown; its wall time, CPU time (of the
    process and the children it waited for: `os.wait4`) and peak memory. The peak is the
    command's own (``VmHWM``, read while it runs): `os.wait4`'s ``ru_maxrss`` would count this
    script's memory too, which a spawned process inherits on Linux."""
    print(f"atlas_build: woundsweep {' '.join(args)}", flush=True)
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "woundsweep", *args], cwd=cwd)
    peak = 0.0
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        peak = max(peak, _hwm_mb(proc.pid))
        time.sleep(0.02)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"atlas_build: `woundsweep {' '.join(args)}` exited {proc.returncode}")
    return {
        "command": label,
        "wall_s": wall,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "peak_memory_MB": round(peak),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", type=Path, default=Path("runs/atlas-page"),
                    help="work directory (replaced)")  # fmt: skip
    ap.add_argument("--cal", action="append", default=[], metavar="NAME",
                    help="a sweep whose run calibrates the intervals (repeatable)")  # fmt: skip
    ap.add_argument("--test", action="append", default=[], metavar="NAME",
                    help="a sweep whose run tests the models only (repeatable)")  # fmt: skip
    ap.add_argument("--beside", action="append", default=[], metavar="NAME",
                    help="a sweep of paper jobs under another closing load (repeatable)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=Path("docs/atlas.md"))
    a = ap.parse_args(argv)
    names = [PAPER, *a.cal, *a.test, *a.beside]
    for n in names:
        for p in (Path("sweeps") / f"{n}.yaml", Path("charted") / f"{n}.parquet"):
            if not p.is_file():
                ap.error(f"{p}: no such file")
    root = Path.cwd()
    shutil.rmtree(a.dir, ignore_errors=True)
    a.dir.mkdir(parents=True)
    work = a.dir.resolve()
    times = []
    for n in names:
        sweep, table = root / "sweeps" / f"{n}.yaml", root / "charted" / f"{n}.parquet"
        subprocess.run([sys.executable, "-m", "woundsweep", "generate", str(sweep), "--out", n],
                       cwd=work, check=True, stdout=subprocess.DEVNULL)  # fmt: skip
        t = timed(f"unpack charted/{n}.parquet RUN", ["unpack", str(table), n], work)
        if n == PAPER:
            times.append(t)
    off = [x for c in a.cal for x in ("--calibrate-on", c)]
    off += [x for t in a.test for x in ("--test-on", t)]
    off += [x for b in a.beside for x in ("--beside", b)]
    times.append(timed("status RUN", ["status", PAPER], work))
    times.append({**timed("status RUN", ["status", PAPER], work), "note": "again: read cache"})
    analyze = ["analyze", PAPER, "--param", "surrogate=gp", *off]
    times.append(timed(" ".join([*analyze[:1], "RUN", *analyze[2:]]), analyze, work))
    times.append(
        timed("atlas RUN --views 0-9", ["atlas", PAPER, "--out", "atlas", "--views", "0-9"], work)
    )
    (work / "timings.json").write_text(json.dumps(times, indent=1) + "\n")
    return atlas_page.main(
        [str(work / PAPER), "--table", "charted/paper.parquet", "--out", str(a.out),
         "--timings", str(work / "timings.json"),
         *[x for b in a.beside for x in ("--beside", str(work / b))]]
    )  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())

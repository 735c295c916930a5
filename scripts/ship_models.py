"""Train the models shipped with woundsweep from charted tables (`make models`).

Makes a run of ``--sweep`` in a work directory, writes the packed ``--table``'s jobs into it
(`woundsweep unpack`), likewise a run of each ``--calibrate-sweep`` from the
``--calibrate-on-table`` given with it (both repeatable, paired in order), runs `woundsweep
analyze` on it (``--calibrate-on`` each such run: with two or more, the intervals are
calibrated on their rows pooled and their coverage estimated by cross-calibration by run;
``--param`` and ``--split`` passed through), then replaces ``--out`` (default: the
package's ``woundsweep/models/``) whole with the files `predict` reads and
``trained_on.json`` (`woundsweep.analysis.shipped`). The runs are named after their sweep
files and analysed from inside the work directory, so the model files name no temporary
path.

    python scripts/ship_models.py --table charted/paper.parquet --sweep sweeps/paper.yaml \
        --calibrate-on-table charted/paper-random-1.parquet \
        --calibrate-sweep sweeps/paper-random-1.yaml \
        --calibrate-on-table charted/paper-random-2.parquet \
        --calibrate-sweep sweeps/paper-random-2.yaml --param surrogate=gp
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from woundsweep.analysis.shipped import describe, install, trained_on_record
from woundsweep.config.manifest import load_run
from woundsweep.store.identity import file_sha256
from woundsweep.store.packed import read_packed

ROOT = Path(__file__).resolve().parents[1]


def _ws(*args: str, cwd: Path) -> None:
    exe = Path(sys.executable).with_name("woundsweep")
    subprocess.run([str(exe), *args], check=True, cwd=cwd)


def _build_run(table: Path, sweep: Path, work: Path, role: str) -> tuple[str, dict[str, Any]]:
    """A run of ``sweep`` in ``work`` holding ``table``'s jobs; its name and its table's entry."""
    name = sweep.stem
    # One copy is unpacked, counted and hashed: `make chart` may replace the table meanwhile.
    copy = work / f"{name}.parquet"
    shutil.copyfile(table, copy)
    _ws("generate", str(sweep.resolve()), "--out", name, cwd=work)
    _ws("unpack", copy.name, name, cwd=work)
    run = load_run(work / name)
    packed, footer = read_packed(copy)
    entry = {
        "role": role,
        "path": str(table),
        "sha256": file_sha256(copy),
        "values_sha256": footer.get("sha256"),
        "table_jobs": len(set(packed.column("job_id").to_pylist())),
        "sweep": run.sweep.name,
        "sweep_file": str(sweep),
        "sweep_jobs": len(run.manifest),
    }
    return name, entry


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--table", type=Path, required=True, help="packed table to train on")
    ap.add_argument("--sweep", type=Path, required=True, help="the table's sweep file")
    ap.add_argument(
        "--calibrate-on-table",
        type=Path,
        action="append",
        default=[],
        help="packed table of wounds between the grid's values (repeatable)",
    )
    ap.add_argument(
        "--calibrate-sweep",
        type=Path,
        action="append",
        default=[],
        help="its sweep file, one per --calibrate-on-table, in the same order",
    )
    ap.add_argument("--param", action="append", default=[], help="analyze's --param KEY=VALUE")
    ap.add_argument("--split", default="both", choices=["random", "geometry", "both"])
    ap.add_argument("--out", type=Path, default=ROOT / "woundsweep" / "models")
    ap.add_argument("--work", type=Path, default=None, help="build the runs here (kept)")
    a = ap.parse_args()
    if len(a.calibrate_on_table) != len(a.calibrate_sweep):
        ap.error("--calibrate-on-table and --calibrate-sweep go together, one of each per run")
    for p in (a.table, a.sweep, *a.calibrate_on_table, *a.calibrate_sweep):
        if not p.is_file():
            ap.error(f"{p}: no such file")
    stems = [a.sweep.stem, *(s.stem for s in a.calibrate_sweep)]
    if len(set(stems)) != len(stems):
        ap.error("--sweep and --calibrate-sweep name their runs: give files of different names")
    t0 = time.monotonic()
    work = a.work or Path(tempfile.mkdtemp(prefix="ship-models-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        name, entry = _build_run(a.table, a.sweep, work, "training")
        tables = [entry]
        # The shipped set holds no figures: none are drawn.
        args = [f"--param={p}" for p in a.param] + [f"--split={a.split}", "--no-figures"]
        for table, sweep in zip(a.calibrate_on_table, a.calibrate_sweep):
            cal, cal_entry = _build_run(table, sweep, work, "calibration")
            tables.append(cal_entry)
            args.append(f"--calibrate-on={cal}")
        _ws("analyze", name, *args, cwd=work)
        analysis = work / name / "analysis"
        metrics = json.loads((analysis / "metrics.json").read_text())
        record = trained_on_record(metrics, entry["sweep"], entry["sweep_jobs"], tables, args)
        files = install(analysis, record, a.out)
    finally:
        if a.work is None:
            shutil.rmtree(work, ignore_errors=True)
    print(f"ship_models: {a.out}, {time.monotonic() - t0:.0f} s")
    for f in files:
        print(f"  {f.name:28} {f.stat().st_size:>12,} bytes")
    print(f"  total {sum(f.stat().st_size for f in files):,} bytes")
    print(describe(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())

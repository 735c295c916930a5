"""Chart a sweep in parts that survive a change of machine (`make chart`).

The kept table (``--table``, made by `woundsweep pack`) is what has been charted. This script
makes the run directory if missing, writes the table's jobs into it (`woundsweep unpack`),
then runs the shards that still have jobs missing from the table, in a fixed random order
(seeded: a charted prefix is a random sample of shards). It packs once ``--pack-minutes``
have passed since the last pack, at the end, and on SIGTERM or Ctrl-C: packing re-reads the
whole run, about 1 ms a job warm (12 s at the whole grid, a sixth of a 24-job shard's time).
Results not yet packed stay in the run directory, where the next pack or run finds them.
Fields are not kept (``--fields none``): the table holds every column the analysis reads.
Stops after ``--hours`` of wall time or ``--max-shards`` shards; commit the table to keep
what was charted.

    python scripts/chart.py --sweep sweeps/paper.yaml --table charted/paper.parquet \
        --run runs/chart-paper --hours 2
"""

from __future__ import annotations

import argparse
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

from woundsweep.config.manifest import load_run
from woundsweep.execution.shards import partition
from woundsweep.store.packed import read_packed


def _ws(*args: str) -> None:
    exe = Path(sys.executable).with_name("woundsweep")
    subprocess.run([str(exe), *args], check=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sweep", type=Path, required=True)
    ap.add_argument("--table", type=Path, required=True)
    ap.add_argument("--run", type=Path, required=True)
    ap.add_argument("--shards", type=int, default=486, help="shard count N of --shard k/N")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--hours", type=float, default=None, help="stop after this wall time")
    ap.add_argument("--max-shards", type=int, default=None)
    ap.add_argument("--seed", type=int, default=58, help="seed of the shard order")
    ap.add_argument("--pack-minutes", type=float, default=15.0, help="pack at most this often")
    a = ap.parse_args()
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a stop packs first
    t0 = time.monotonic()
    _ws("generate", str(a.sweep), "--out", str(a.run))
    done: set[str] = set()
    if a.table.exists():
        _ws("unpack", str(a.table), str(a.run))
        done = set(read_packed(a.table)[0].column("job_id").to_pylist())
    manifest = load_run(a.run).manifest
    ids = manifest.set_index("job_index")["job_id"]
    shards = partition(manifest, a.shards)
    order = list(range(a.shards))
    random.Random(a.seed).shuffle(order)
    todo = [k for k in order if set(ids.loc[shards[k]]) - done]
    print(f"chart: {a.shards - len(todo)} of {a.shards} shards charted, {len(todo)} to go")
    packed, pending = time.monotonic(), False
    try:
        for n, k in enumerate(todo):
            hours = (time.monotonic() - t0) / 3600
            if (a.max_shards is not None and n >= a.max_shards) or (a.hours and hours >= a.hours):
                break
            print(
                f"chart: shard {k}/{a.shards} ({len(todo) - n} left, {hours:.2f} h in)", flush=True
            )
            pending = True  # a shard run since the last pack
            _ws("run", str(a.run), "--shard", f"{k}/{a.shards}", "--workers", str(a.workers),
                "--fields", "none", "--no-progress")  # fmt: skip
            if time.monotonic() - packed >= 60 * a.pack_minutes:
                _ws("pack", str(a.run), str(a.table))
                packed, pending = time.monotonic(), False
    except (KeyboardInterrupt, subprocess.CalledProcessError) as e:
        print(f"chart: stopped ({type(e).__name__}); packing what is stored", flush=True)
        return_code = 1
    else:
        return_code = 0
    finally:
        if pending:
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            _ws("pack", str(a.run), str(a.table))
    return return_code


if __name__ == "__main__":
    sys.exit(main())

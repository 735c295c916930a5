"""Compare the stored results of two run directories job by job and stage by stage.

Usage: python scripts/compare_stores.py RUN_A RUN_B [--rtol 1e-9]

Jobs are matched by ``job_id`` (the hash of their parameters); only jobs stored in both are
compared, and their counts are printed. Statuses, failure classes and Newton steps must be
equal; every other per-stage number (the `StageResult` fields and the diagnostics of
``stage_extra_json``) must agree within ``rtol`` relative, except times, which differ from
run to run. Exits 1 on the first kind of difference, listing up to 20 of them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import pandas as pd

EXACT = ("status", "failure_class", "failed_stage", "newton_iterations", "attempts")
# Per-run values: times, hosts, versions, paths and the hashes that cover them.
SKIP_SUFFIXES = ("_time_s", "_at_utc", "_sha256", "_MiB")
SKIP = {
    "time_s", "host", "shard", "fields_file", "mesh_file", "result_fingerprint",
    "woundsweep_version", "dolfinx_version", "python_version", "stage_extra_json",
    "failure_detail",
}  # fmt: skip


def _close(a: object, b: object, rtol: float) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if math.isnan(a) and math.isnan(b):
            return True
        return abs(a - b) <= rtol * max(abs(a), abs(b)) or a == b
    return a == b or (pd.isna(a) and pd.isna(b))


def compare(a: pd.DataFrame, b: pd.DataFrame, rtol: float) -> list[str]:
    keys = ["job_id", "stage"]
    m = a.merge(b, on=keys, suffixes=("_a", "_b"))
    bad: list[str] = []
    for col in a.columns:
        if col in keys or col in SKIP or col.endswith(SKIP_SUFFIXES) or f"{col}_b" not in m:
            continue
        for _, r in m.iterrows():
            x, y = r[f"{col}_a"], r[f"{col}_b"]
            ok = (x == y or (pd.isna(x) and pd.isna(y))) if col in EXACT else _close(x, y, rtol)
            if not ok:
                bad.append(f"{r['job_id']} stage {r['stage']}: {col} {x!r} != {y!r}")
    for _, r in m.iterrows():
        ea, eb = (json.loads(r[f"stage_extra_json_{s}"] or "{}") for s in "ab")
        if set(ea) != set(eb):
            bad.append(f"{r['job_id']} stage {r['stage']}: diagnostics keys differ")
            continue
        for k in ea:
            if not k.endswith("_time_s") and not _close(ea[k], eb[k], rtol):
                bad.append(f"{r['job_id']} stage {r['stage']}: {k} {ea[k]!r} != {eb[k]!r}")
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run_a")
    p.add_argument("run_b")
    p.add_argument("--rtol", type=float, default=1e-9)
    args = p.parse_args(argv)
    a = pd.read_parquet(f"{args.run_a}/results")
    b = pd.read_parquet(f"{args.run_b}/results")
    both = set(a["job_id"]) & set(b["job_id"])
    print(
        f"jobs: {a['job_id'].nunique()} in A, {b['job_id'].nunique()} in B, {len(both)} in both;"
        f" rows compared: {int(a['job_id'].isin(both).sum())}"
    )
    bad = compare(a[a["job_id"].isin(both)], b[b["job_id"].isin(both)], args.rtol)
    for line in bad[:20]:
        print(line)
    print("equal" if not bad else f"{len(bad)} differences")
    return 1 if bad or not both else 0


if __name__ == "__main__":
    sys.exit(main())

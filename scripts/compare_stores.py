"""Compare the stored results of two run directories job by job and stage by stage.

Usage: python scripts/compare_stores.py RUN_A RUN_B [--rtol 1e-9]

Jobs are matched by ``job_id`` (the hash of their parameters); only jobs stored in both are
compared, and their counts are printed. Statuses, failure classes and Newton steps must be
equal; every other per-stage number (the `StageResult` fields and the diagnostics) must agree
within ``rtol`` relative, except times, which differ from run to run. Diagnostics are compared
by name, whichever form a store holds them in: one typed column each
(`woundsweep.core.diagnostics`), or the JSON column ``stage_extra_json`` of result format 4;
a diagnostic null or absent on one side must be null or absent on the other. Columns that
only one store has (e.g. ``element_degree``) are listed with their counts of values, not
counted as differences. Exits 1 on the first kind of difference, listing up to 20 of them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import pandas as pd

from woundsweep.core.diagnostics import DIAGNOSTIC_KEYS
from woundsweep.core.layout import RunLayout

EXACT = ("status", "failure_class", "failed_stage", "newton_iterations", "attempts")
# Per-run values: times, hosts, versions, paths and the hashes that cover them.
SKIP_SUFFIXES = ("_time_s", "_at_utc", "_sha256", "_MiB")
SKIP = {
    "time_s", "host", "shard", "fields_file", "mesh_file", "result_fingerprint",
    "woundsweep_version", "dolfinx_version", "python_version", "failure_detail",
}  # fmt: skip
JSON_DIAGNOSTICS = "stage_extra_json"


def _close(a: object, b: object, rtol: float) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if math.isnan(a) and math.isnan(b):
            return True
        return abs(a - b) <= rtol * max(abs(a), abs(b)) or a == b
    return a == b or (pd.isna(a) and pd.isna(b))


def diagnostics(df: pd.DataFrame) -> list[dict[str, Any]]:
    """Per row its diagnostics by name, without null ones: from the typed columns and, where
    a store has it, the JSON column."""
    typed = [c for c in df.columns if c in DIAGNOSTIC_KEYS]
    out = []
    for r in df.to_dict("records"):
        d = {c: r[c] for c in typed if not pd.isna(r[c])}
        text = r.get(JSON_DIAGNOSTICS)
        if isinstance(text, str) and text:
            d.update({k: v for k, v in json.loads(text).items() if v is not None})
        out.append(d)
    return out


def only_in(a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
    """The columns of ``a`` that ``b`` lacks, with their counts of values (diagnostics are
    compared by name, whatever their form)."""
    form = DIAGNOSTIC_KEYS | {JSON_DIAGNOSTICS}
    return [
        f"{c} ({int(a[c].notna().sum())} values)" for c in a.columns if c not in b and c not in form
    ]


def compare(a: pd.DataFrame, b: pd.DataFrame, rtol: float) -> list[str]:
    keys = ["job_id", "stage"]
    a, b = a.sort_values(keys), b.sort_values(keys)
    m = a.merge(b, on=keys, suffixes=("_a", "_b"))
    bad: list[str] = []
    for col in a.columns:
        if col in keys or col in SKIP or col.endswith(SKIP_SUFFIXES) or f"{col}_b" not in m:
            continue
        if col in DIAGNOSTIC_KEYS or col == JSON_DIAGNOSTICS:
            continue  # by name below
        for _, r in m.iterrows():
            x, y = r[f"{col}_a"], r[f"{col}_b"]
            ok = (x == y or (pd.isna(x) and pd.isna(y))) if col in EXACT else _close(x, y, rtol)
            if not ok:
                bad.append(f"{r['job_id']} stage {r['stage']}: {col} {x!r} != {y!r}")
    da = dict(zip(zip(a["job_id"], a["stage"]), diagnostics(a)))
    db = dict(zip(zip(b["job_id"], b["stage"]), diagnostics(b)))
    for job_id, stage in zip(m["job_id"], m["stage"]):
        ea, eb = da[(job_id, stage)], db[(job_id, stage)]
        if set(ea) != set(eb):
            diff = sorted(set(ea) ^ set(eb))
            bad.append(f"{job_id} stage {stage}: diagnostics differ in presence: {diff}")
            continue
        for k in ea:
            if not k.endswith("_time_s") and not _close(ea[k], eb[k], rtol):
                bad.append(f"{job_id} stage {stage}: {k} {ea[k]!r} != {eb[k]!r}")
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run_a")
    p.add_argument("run_b")
    p.add_argument("--rtol", type=float, default=1e-9)
    args = p.parse_args(argv)
    a = pd.read_parquet(RunLayout(args.run_a).results_dir)
    b = pd.read_parquet(RunLayout(args.run_b).results_dir)
    both = set(a["job_id"]) & set(b["job_id"])
    print(
        f"jobs: {a['job_id'].nunique()} in A, {b['job_id'].nunique()} in B, {len(both)} in both;"
        f" rows compared: {int(a['job_id'].isin(both).sum())}"
    )
    a, b = a[a["job_id"].isin(both)], b[b["job_id"].isin(both)]
    for name, cols in (("A", only_in(a, b)), ("B", only_in(b, a))):
        if cols:
            print(f"columns only in {name} (not compared): {', '.join(cols)}")
    bad = compare(a, b, args.rtol)
    for line in bad[:20]:
        print(line)
    print("equal" if not bad else f"{len(bad)} differences")
    return 1 if bad or not both else 0


if __name__ == "__main__":
    sys.exit(main())

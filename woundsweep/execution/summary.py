"""The progress of a run for ``woundsweep status``: counts, failure classes and times, and an
estimate of the CPU time left from the cost model of the shards."""

from __future__ import annotations

from typing import Any

import pandas as pd

from ..core.schema import FailureClass, ResultState, StageStatus
from ..store.reader import StoreScan
from .shards import estimate_cost

__all__ = ["busy_seconds", "summarize"]

_BAD = (ResultState.CORRUPT, ResultState.DAMAGED)  # result states counted as damaged


def busy_seconds(started: pd.Series, finished: pd.Series) -> float:
    """The wall time (s) during which at least one job ran: the length of the union of the
    intervals [started, finished] (jobs without both times left out)."""
    t = pd.DataFrame({"a": pd.to_datetime(started), "b": pd.to_datetime(finished)}).dropna()
    total, end = 0.0, None
    for a, b in t.sort_values("a").itertuples(index=False):
        if end is None or a > end:
            total += max((b - a).total_seconds(), 0.0)
            end = max(a, b)
        elif b > end:
            total += (b - end).total_seconds()
            end = b
    return total


def summarize(
    manifest: pd.DataFrame, results: pd.DataFrame, scan: StoreScan | None = None
) -> dict[str, Any]:
    """Counts and times for ``woundsweep status`` (jobs of the manifest only).

    With a ``scan``, also the stale and damaged results (pending: `run` redoes them), the
    orphans and the stray files it found.
    """
    in_manifest = results["job_id"].isin(set(manifest["job_id"]))
    orphans = int(results.loc[~in_manifest, "job_id"].nunique())
    rows = results[in_manifest]
    jobs = rows.drop_duplicates("job_id")
    done_ids = set(jobs["job_id"])
    pending = manifest[~manifest["job_id"].isin(done_ids)]
    by_class = {c.value: int((jobs["failure_class"] == c.value).sum()) for c in FailureClass}
    by_stage: dict[str, dict[str, int]] = {}
    for stage, g in rows.groupby("stage", sort=True):
        counts = g["status"].value_counts()
        by_stage[str(int(stage))] = {s.value: int(counts.get(s.value, 0)) for s in StageStatus}
    # The closure flag of the converged rows that have one; 0 is a reopened stage
    # (docs/model.md, "Closure measures").
    closed = rows["closed"] if "closed" in rows else pd.Series(float("nan"), index=rows.index)
    flagged = closed[(rows["status"] == StageStatus.CONVERGED.value) & closed.notna()]
    open_stages = rows.loc[flagged.index[flagged == 0], "stage"].value_counts()
    reopened = {str(int(k)): int(v) for k, v in sorted(open_stages.items())}
    not_converged_at = {
        str(int(k)): int(v)
        for k, v in jobs["failed_stage"].dropna().value_counts().sort_index().items()
    }
    cpu_used = float(jobs["total_cpu_time_s"].sum()) if len(jobs) else 0.0
    span = busy = None
    if len(jobs):
        t0 = jobs["started_at_utc"].min()
        t1 = jobs["finished_at_utc"].max()
        span = max((t1 - t0).total_seconds(), 0.0)
        busy = busy_seconds(jobs["started_at_utc"], jobs["finished_at_utc"])
    # Per hour of running, not of the span: a run charted in parts pauses between them.
    throughput = len(jobs) / busy * 3600.0 if busy else None
    cpu_left = None
    if len(jobs) and cpu_used > 0:
        cost = pd.Series(estimate_cost(manifest), index=manifest["job_id"].to_numpy())
        done_cost = float(cost.loc[list(done_ids)].sum())
        cpu_left = cpu_used / done_cost * float(cost.loc[pending["job_id"]].sum())
    return {
        "jobs_total": int(len(manifest)),
        "jobs_done": int(len(jobs)),
        "jobs_pending": int(len(pending)),
        "rows": int(len(rows)),
        "orphan_jobs": orphans if scan is None else len(scan.orphans),
        "jobs_stale": 0 if scan is None else scan.count(ResultState.STALE),
        "jobs_damaged": 0
        if scan is None
        else scan.count(ResultState.CORRUPT) + scan.count(ResultState.DAMAGED),
        "damaged_example": next(
            (c.reason for c in (scan.checks.values() if scan else ()) if c.state in _BAD), None
        ),
        "stray_files": 0 if scan is None else len(scan.stray),
        "by_failure_class": by_class,
        "not_converged_at_stage": not_converged_at,
        "by_stage": by_stage,
        "closed_rows": int((flagged == 1).sum()),
        "closure_rows": int(len(flagged)),
        "reopened_by_stage": reopened,
        "attempts": int(jobs["attempts"].sum()) if len(jobs) else 0,
        "wall_span_s": span,
        "wall_busy_s": busy,
        "throughput_jobs_per_hour": throughput,
        "cpu_time_used_s": cpu_used,
        "cpu_time_left_estimate_s": cpu_left,
    }

"""Which jobs of a shard ``woundsweep run`` starts, and in which order.

A job whose stored result is valid, current and covers the requested stages is skipped (with
``rerun_failed``, only if it converged); a result that fails validation is moved aside
(`Store.quarantine`) and its job run again. Jobs start in manifest order, except that the
cheapest goes first while the runner warms the JIT cache (`woundsweep.execution.runner`).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import pandas as pd

from ..core.errors import one_line
from ..core.schema import FailureClass, ResultState
from .process import Job
from .shards import Shard, estimate_cost, shard_jobs

if TYPE_CHECKING:
    from ..config.manifest import JobRow
    from ..store import Store

__all__ = ["ShardPlan", "mtime_ns", "needs_run", "plan_shard", "start_order"]


class ShardPlan(NamedTuple):
    """The jobs of a shard a run starts, in start order, and how many it skips."""

    jobs: int  # the shard's jobs
    todo: list[Job]
    skipped: int  # complete in the store


def mtime_ns(path: Path) -> int | None:
    """``path``'s modification time (ns), None if it does not exist."""
    try:
        return path.stat().st_mtime_ns
    except FileNotFoundError:
        return None


def start_order(jobs: pd.DataFrame, warmup: bool) -> list[JobRow]:
    """Manifest order, except that the cheapest job goes first to warm the JIT cache."""
    rows: list[JobRow] = jobs.to_dict("records")  # type: ignore[assignment]
    if warmup and rows:
        cost = estimate_cost(jobs)
        first = int(cost.argmin())
        rows.insert(0, rows.pop(first))
    return rows


def needs_run(store: Store, row: JobRow, stages: tuple[int, int], rerun_failed: bool) -> bool:
    """Whether the job of ``row`` runs; a stored result that fails validation is moved
    aside (with its fields and mesh files if those are damaged) and the job runs again."""
    jid = str(row["job_id"])
    st = store.job_state(jid, stages, store.fingerprint(row))
    if st.state in (ResultState.CORRUPT, ResultState.DAMAGED):
        moved = store.quarantine(jid, files=st.state == ResultState.DAMAGED)
        print(
            one_line(f"woundsweep run: {st.reason}; moved to {moved}, rerunning"), file=sys.stderr
        )
        return True
    if st.state != ResultState.DONE:
        return True
    return rerun_failed and st.failure_class != FailureClass.CONVERGED


def plan_shard(
    store: Store,
    manifest: pd.DataFrame,
    shard: Shard,
    *,
    stages: tuple[int, int],
    rerun_failed: bool,
    warmup: bool,
) -> ShardPlan:
    """The jobs of ``shard`` to run, in start order (`start_order`, `needs_run`)."""
    rows = shard_jobs(manifest, shard)
    todo, skipped = [], 0
    for row in start_order(rows, warmup):
        if not needs_run(store, row, stages, rerun_failed):
            skipped += 1
            continue
        seen = mtime_ns(store.result_path(str(row["job_id"])))
        todo.append(Job(row, seen_mtime_ns=seen))
    return ShardPlan(len(rows), todo, skipped)

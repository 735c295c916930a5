"""``woundsweep run RUN_DIR [--shard i/N] [--workers K] ...``: run a shard of the sweep."""

from __future__ import annotations

import os
from pathlib import Path

import click

from ..clitypes import FiniteFloat
from ..core.errors import StoreError
from ..core.layout import RunLayout
from ..core.schema import FailureClass, parse_stage_range
from ..execution.runner import RunOptions, RunSummary, run_shard
from ..execution.shards import parse_shard
from ..store.writer import FIELDS_CHOICES

__all__ = ["cmd"]


def _default_workers() -> int:
    return len(os.sched_getaffinity(0))


def _memory_bytes() -> int:
    """Physical memory, or the cgroup's limit when lower (batch systems set one)."""
    ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as fh:
                text = fh.read().strip()
        except OSError:
            continue
        if text.isdigit():
            ram = min(ram, int(text))
    return ram


def _summary_line(s: RunSummary, run_dir: Path) -> str:
    classes = ", ".join(f"{s.by_class[c]} {c}" for c in FailureClass if s.by_class.get(c))
    return (
        f"{s.jobs} jobs in shard: {s.skipped} already done, {s.ran} run"
        f"{' (' + classes + ')' if classes else ''}, {s.attempts} attempts, "
        f"{s.wall_time_s:.0f} s; results in {RunLayout(run_dir).results_dir}"
    )


@click.command("run")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--shard", default="0/1", show_default=True, help="Run shard i of N (0-based).")
@click.option(
    "--workers", type=click.IntRange(min=1), default=None, help="Jobs at once [default: cores]."
)
@click.option(
    "--timeout",
    "timeout_s",
    type=FiniteFloat(min=1, max=1e7),
    default=1800,
    show_default=True,
    help="Wall-clock limit per job attempt, seconds.",
)
@click.option(
    "--max-memory",
    "max_memory_gb",
    type=FiniteFloat(min=0.05, max=1e6),
    default=None,
    help="Resident memory cap per job, GB [default: 90% of RAM / workers].",
)
@click.option(
    "--retries",
    type=click.IntRange(min=0),
    default=2,
    show_default=True,
    help="Retries of transient failures (timeout, crashed).",
)
@click.option("--rerun-failed", is_flag=True, help="Also rerun jobs stored with a failure class.")
@click.option(
    "--stages",
    "stages_text",
    default="1-6",
    show_default=True,
    help="Stages A-B (1-3: tension and closure, 4-6: contact).",
)
@click.option(
    "--fields",
    type=click.Choice(FIELDS_CHOICES),
    default="final",
    show_default=True,
    help="Which stages' fields to keep in RUN_DIR/fields.",
)
@click.option(
    "--warmup/--no-warmup",
    default=True,
    show_default=True,
    help="Run one job alone first so the JIT cache is filled once.",
)
@click.option(
    "--jit-stale-after",
    "jit_stale_after_s",
    type=FiniteFloat(min=1, max=1e7),
    default=600,
    show_default=True,
    help="Age (s) after which an FFCx JIT lock is considered stale.",
)
@click.option(
    "--progress/--no-progress", default=None, help="Progress bar [default: on a terminal]."
)
def cmd(
    run_dir: Path,
    shard: str,
    workers: int | None,
    timeout_s: float,
    max_memory_gb: float | None,
    retries: int,
    rerun_failed: bool,
    stages_text: str,
    fields: str,
    warmup: bool,
    jit_stale_after_s: float,
    progress: bool | None,
) -> None:
    """Run the jobs of RUN_DIR (or of one shard) not yet in its store, K at a time.

    Each job runs `woundsweep solve` in its own process group, killed at the timeout or the
    memory cap; transient failures are retried. Results go to RUN_DIR/results (Parquet, one
    file per job), RUN_DIR/fields (HDF5) and RUN_DIR/logs. Rerunning resumes; failed jobs
    are kept unless --rerun-failed. Exit status 0 when every job of the shard is stored,
    whatever its failure class.
    """
    try:
        shard_ = parse_shard(shard)
    except ValueError as err:
        raise StoreError(f"--shard: {err}") from None
    k = workers or _default_workers()
    if max_memory_gb is None:
        cap = int(0.9 * _memory_bytes() / k)
        if cap < 0.05e9:
            raise StoreError(
                f"--workers {k}: 90% of the memory / {k} leaves {cap / 1e6:.0f} MB per job, "
                "under the 50 MB minimum; use fewer workers or give --max-memory"
            )
    else:
        cap = int(max_memory_gb * 1e9)
    opts = RunOptions(
        shard=shard_,
        workers=k,
        timeout_s=timeout_s,
        max_memory_bytes=cap,
        retries=retries,
        rerun_failed=rerun_failed,
        stages=parse_stage_range(stages_text, StoreError),
        fields=fields,
        warmup=warmup,
        jit_stale_after_s=jit_stale_after_s,
        progress=progress,
    )
    summary = run_shard(run_dir, opts)
    click.echo(_summary_line(summary, run_dir))

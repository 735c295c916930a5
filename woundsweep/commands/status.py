"""``woundsweep status RUN_DIR [--json]``: what the store holds, and what is left."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import click

from ..config.manifest import load_run
from ..config.solver import element_name
from ..core.schema import FailureClass
from ..execution.summary import summarize
from ..store.reader import rows_element_degree, scan_results, scan_store

__all__ = ["cmd", "format_status"]


def _duration(seconds: float | None) -> str:
    if seconds is None:
        return "n/a"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def format_status(s: dict[str, Any]) -> str:
    """The human-readable table of a `summarize` record."""
    lines = [
        f"jobs: {s['jobs_done']} of {s['jobs_total']} stored, {s['jobs_pending']} pending"
        f" ({s['rows']} rows, {s['attempts']} attempts)"
    ]
    if s["orphan_jobs"]:
        lines.append(f"  {s['orphan_jobs']} stored jobs are not in the manifest (ignored)")
    if s.get("jobs_stale"):
        lines.append(
            f"  {s['jobs_stale']} stored results are stale (other settings, stages or result"
            " format): pending, `woundsweep run` recomputes them"
        )
    if s.get("jobs_damaged"):
        lines.append(
            f"  {s['jobs_damaged']} stored results are damaged (e.g. {s['damaged_example']}):"
            " pending, `woundsweep run` moves them to corrupt/ and redoes them"
        )
    if s.get("stray_files"):
        lines.append(f"  {s['stray_files']} files in results/ are not the store's (ignored)")
    lines.append("by failure class:")
    for cls, n in s["by_failure_class"].items():
        extra = ""
        if cls == FailureClass.NOT_CONVERGED and s["not_converged_at_stage"]:
            extra = (
                "  (at stage "
                + ", ".join(f"{k}: {v}" for k, v in s["not_converged_at_stage"].items())
                + ")"
            )
        lines.append(f"  {cls:<14} {n:>7}{extra}")
    if s["by_stage"]:
        statuses = [st for st in next(iter(s["by_stage"].values()))]
        lines.append("by stage:  " + "".join(f"{st:>22}" for st in statuses))
        for stage, counts in s["by_stage"].items():
            lines.append(f"  stage {stage:<3}" + "".join(f"{counts[st]:>22}" for st in statuses))
    reopened = s.get("reopened_by_stage") or {}
    if reopened:
        lines.append(
            "reopened (converged, the sutured zone open at the surface): stage "
            + ", ".join(f"{k}: {v}" for k, v in reopened.items())
        )
    if s.get("closure_rows"):
        lines.append(
            f"closure: sutured zone closed at the surface in {s['closed_rows']} of"
            f" {s['closure_rows']} converged stage 2-6 rows"
        )
    rate = s["throughput_jobs_per_hour"]
    lines.append(
        f"throughput: {'n/a' if rate is None else f'{rate:.1f} jobs/h'}"
        f" over {_duration(s['wall_busy_s'])} while jobs ran"
        f" ({_duration(s['wall_span_s'])} from the first job's start to the last one's end)"
    )
    lines.append(
        f"CPU time: {_duration(s['cpu_time_used_s'])} used,"
        f" about {_duration(s['cpu_time_left_estimate_s'])} left (cost-weighted estimate)"
    )
    return "\n".join(lines)


@click.command("status")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the counts as JSON.")
@click.option(
    "--verify",
    is_flag=True,
    help="Read and check every result file, trusting none of the read cache.",
)
def cmd(run_dir: Path, as_json: bool, verify: bool) -> None:
    """Counts by failure class and by stage, throughput, CPU time used and left.

    Every result file is validated, with the checksums of its fields and mesh files; stale
    results (computed with other settings) and damaged ones count as pending (rerun
    `woundsweep run`: it recomputes them, moving damaged files to RUN_DIR/corrupt/). Result
    files unchanged (size, times, inode) since a reader checked them come from the read
    cache RUN_DIR/.read-cache.wsc; --verify reads them all. The time it took ends the table
    as a line on stderr (with --json: the key read_time_s).
    """
    t0 = time.perf_counter()
    run = load_run(run_dir)
    scan = scan_store(run.run_dir, run=run, use_cache=not verify)
    rows = scan_results(scan)
    s = summarize(run.manifest, rows, scan)
    degree = rows_element_degree(rows)  # the stored results' element (None: none stored)
    name = element_name(degree) if degree is not None else None
    seconds = time.perf_counter() - t0
    if as_json:
        # In the document, not on stderr: a script reading --json gets stdout alone and a
        # silent stderr means success.
        element = {"element_degree": degree, "element": name}
        doc = {"run_dir": str(run.run_dir), **element, **s, "read_time_s": round(seconds, 3)}
        click.echo(json.dumps(doc, indent=2))
    else:
        click.echo(f"sweep {run.sweep.name}: element {name or 'n/a (no stored results)'}")
        click.echo(format_status(s))
        click.echo(
            f"status: {len(run.manifest):,} jobs ({s['jobs_done']:,} stored) read in"
            f" {seconds:.1f} s",
            err=True,
        )

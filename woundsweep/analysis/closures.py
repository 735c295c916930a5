"""The closing loads side by side (the paper's Figure 2 per closure): the analysed run and the
runs given with ``analyze --beside``, each closed by its sweep's ``stages.closure_load``.

Every converged row with a position counts, reopened or not: where the along-wound maximum
sits under a closure is the question, whether or not the closure holds the wound. The runs are
compared on the jobs they all have (a run of a slice of the grid beside the whole grid is
compared on the slice). Per run and stage group: the rows, the closed ones (stages 2-6) and the
share of rows whose along-wound maximum lies within `ENDS_TOL` of the line's length of its
closure zone's ends.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..core.errors import AnalysisError
from ..core.schema import StageStatus
from .data import drop_orphans, load_results, run_or_none
from .paper import along_half_length
from .settings import STAGE_GROUPS

if TYPE_CHECKING:
    from ..config.manifest import Run

__all__ = [
    "ENDS_TOL", "closure_entry", "closure_rows", "closure_summary", "common_jobs", "report_lines",
]  # fmt: skip

ENDS_TOL = 0.05


def closure_entry(results: pd.DataFrame, run: Run) -> tuple[pd.DataFrame, str, float]:
    """A run's converged rows (of its ``results``, orphans dropped) with ``closure_load``
    set, its closing load and its zone's y fraction."""
    rows = results[results["status"] == StageStatus.CONVERGED.value]
    load = run.sweep.stages.closure_load
    return rows.assign(closure_load=load), load, run.sweep.stages.closure_zone.y_fraction


def closure_rows(run_dir: str | Path) -> tuple[pd.DataFrame, str, float]:
    """`closure_entry` of the run directory ``run_dir``."""
    rd = Path(run_dir)
    run = run_or_none(rd)
    if run is None:
        raise AnalysisError(f"--beside {rd}: not a run directory")
    return closure_entry(drop_orphans(load_results(rd, run), run)[0], run)


def common_jobs(
    runs: list[tuple[pd.DataFrame, str, float]],
) -> list[tuple[pd.DataFrame, str, float]]:
    """Each run's rows of the jobs every run has (runs without a ``job_id`` column whole)."""
    if len(runs) < 2 or any("job_id" not in r[0] for r in runs):
        return runs
    shared = set.intersection(*(set(r[0]["job_id"]) for r in runs))
    return [(r[r["job_id"].isin(shared)], load, y) for r, load, y in runs]


def closure_summary(runs: list[tuple[pd.DataFrame, str, float]]) -> dict[str, Any]:
    """metrics.json's ``closures``: per closing load, on the jobs every run has (their number),
    and per stage group the rows, the closed rows and the share of along-wound maxima at the
    zone's ends."""
    out: dict[str, Any] = {}
    for rows, load, y_fraction in common_jobs(runs):
        ends = (0.5 - y_fraction / 2, 0.5 + y_fraction / 2)
        groups: dict[str, Any] = {}
        for name, stages in STAGE_GROUPS:
            sel = rows[rows["stage"].isin(stages)]
            at = sel["profile_along_wound_max_at_mm"].to_numpy(dtype=float)
            half = along_half_length(sel)
            t = (at + half) / (2 * half)
            ok = np.isfinite(t)
            near = np.minimum(np.abs(t - ends[0]), np.abs(t - ends[1])) <= ENDS_TOL
            closed = sel["closed"].to_numpy(dtype=float) if "closed" in sel else np.array([])
            groups[name] = {
                "rows": int(len(sel)),
                "closed": int(np.nansum(closed == 1)) if min(stages) >= 2 else None,
                "at_zone_ends": float(near[ok].mean()) if ok.any() else None,
            }
        jobs = int(rows["job_id"].nunique()) if "job_id" in rows else None
        out[load] = {"zone_ends": list(ends), "jobs": jobs, "groups": groups}
    return out


def report_lines(metrics: dict[str, Any]) -> list[str]:
    """The report's section comparing the closing loads (when ``--beside`` gave others)."""
    closures = metrics.get("closures")
    if not closures or len(closures) < 2:
        return []
    lines = [
        "",
        "## The closing loads side by side (Figure 2 per closure)",
        "",
        "On the jobs every run has"
        + (f" ({jobs:,})" if (jobs := next(iter(closures.values())).get("jobs")) else "")
        + "; every converged row counts, reopened or not; `max_location_profiles` shows the "
        "positions per closure side by side. At the zone's ends: the along-wound maximum within "
        f"{ENDS_TOL} of the line's length of the closure zone's ends.",
        "",
        "| closing load | stage group | rows | closed | maximum at the zone's ends |",
        "|---|---|---|---|---|",
    ]
    for load, c in closures.items():
        for group, g in c["groups"].items():
            closed = "-" if g["closed"] is None else f"{g['closed']:,}"
            ends = "-" if g["at_zone_ends"] is None else f"{100 * g['at_zone_ends']:.0f} %"
            lines.append(f"| {load} | {group} | {g['rows']:,} | {closed} | {ends} |")
    return lines

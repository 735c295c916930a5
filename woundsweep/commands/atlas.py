"""``woundsweep atlas RUN_DIR --out DIR``: the static site of a run (opens from disk)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
from tqdm import tqdm

if TYPE_CHECKING:
    import pandas as pd

    from ..config.manifest import Run

__all__ = ["cmd"]


def _mb(n: float) -> str:
    return f"{n / 1e6:.1f} MB"


def _check_out(run_dir: Path, out: Path) -> None:
    """--out must not be the run directory, hold it, or be one of its own directories (a site
    written there would mix with, or replace, the store)."""
    from ..core.errors import StoreError
    from ..core.layout import RunLayout

    rd, target = run_dir.resolve(), out.resolve()
    if target == rd or target in rd.parents or target in RunLayout(rd).own_dirs:
        raise StoreError(
            f"--out {out}: would write into the run directory {run_dir} (use a new directory)"
        )


def _stale_pages(out: Path, jobs: set[int]) -> list[Path]:
    """The site's job pages (``jobs/job-<N>.html``, regular files) of jobs not in ``jobs``."""
    import re

    pages = out / "jobs"
    if not pages.is_dir() or pages.is_symlink():
        return []
    name = re.compile(r"job-(\d+)\.html")
    return sorted(
        p
        for p in pages.iterdir()
        if (m := name.fullmatch(p.name)) and int(m.group(1)) not in jobs and not p.is_symlink()
    )


def _warn_if_stale(run: Run, results: pd.DataFrame) -> None:
    """A line on stderr when RUN_DIR/analysis was trained on other settings or results."""
    import json

    from ..analysis.trained_on import stale_note
    from ..core.errors import one_line

    path = run.layout.analysis_metrics
    try:
        record = json.loads(path.read_text()).get("trained_on")
    except (OSError, ValueError, AttributeError):
        return  # no analysis (or none readable): the site has no analysis section to doubt
    note = stale_note(run.run_dir, record, results, run)
    if note:
        click.echo(one_line(f"woundsweep: warning: {note}"), err=True)


@click.command("atlas")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Directory of the site (default RUN_DIR/atlas; created if missing).",
)
@click.option(
    "--views",
    default="all",
    show_default=True,
    help="Jobs with a 3D view: all, none, or job indices and ranges such as 0-9,15.",
)
def cmd(run_dir: Path, out: Path | None, views: str) -> None:
    """Write a static site: an index of every job (sortable, filterable), a page per job
    (stage table, log, 3D view) and the analysis' report and figures when they exist.

    One copy of plotly.js (about 4.8 MB) serves every 3D view; a view costs about
    24 + 13 x (stored stages) bytes per exterior triangle of the job's mesh (about 130 kB for
    a demo job). The projected size of the chosen views is shown while it builds and the
    sizes are printed at the end, and the time it took on stderr.
    """
    t0 = time.perf_counter()
    from ..config.manifest import load_run
    from ..core.errors import WoundsweepError
    from ..core.fsutil import check_output_dir
    from ..store.reader import read_results, result_files
    from ..viz.atlas import build_atlas, parse_views

    run = load_run(run_dir)
    out = out or run.layout.atlas_dir
    _check_out(run.run_dir, out)
    try:
        check_output_dir(out)
    except ValueError as err:
        raise WoundsweepError(f"--out {err}") from None
    chosen = parse_views(views, [int(j) for j in run.manifest["job_index"]])
    n_files = len(result_files(run.run_dir)[0])
    click.echo(f"reading and validating {n_files} result files ...", err=True)
    results = read_results(run.run_dir, run=run)
    read_s = time.perf_counter() - t0
    _warn_if_stale(run, results[results["job_id"].isin(set(run.manifest["job_id"]))])
    stored = set(int(j) for j in results["job_index"].unique())
    has_fields = results["fields_file"].fillna("").astype(str) != ""
    with_fields = set(int(j) for j in results.loc[has_fields, "job_index"].unique())
    chosen &= stored
    no_fields = len(chosen - with_fields)
    chosen &= with_fields
    click.echo(
        f"atlas of {len(run.manifest)} jobs ({len(stored)} stored), 3D views for {len(chosen)}"
        + (f" ({no_fields} chosen jobs have no stored fields)" if no_fields else "")
    )
    bar = tqdm(total=len(run.manifest), desc="atlas", unit="job")

    def progress(n: int, info: dict) -> None:
        bar.update(1)
        if info["views"] and info["cells_done"]:
            est = info["view_bytes"] / info["cells_done"] * info["cells_total"]
            bar.set_postfix_str(f"views {_mb(info['view_bytes'])} of ~{_mb(est)}", refresh=False)

    try:
        s = build_atlas(run, results, out, chosen, progress)
    finally:
        bar.close()
    stale = _stale_pages(out, {int(j) for j in run.manifest["job_index"]})
    for page in stale:  # pages of jobs the manifest no longer holds (`generate --force`)
        page.unlink(missing_ok=True)
    if stale:
        click.echo(f"removed {len(stale)} pages of jobs the manifest no longer holds")
    per = f", {s.view_bytes / s.views / 1e3:.0f} kB each" if s.views else ""
    click.echo(
        f"wrote {s.jobs} job pages in {s.seconds:.1f} s; site {_mb(s.total_bytes)}: "
        f"pages with a 3D view: {s.views} jobs, {_mb(s.view_bytes)}{per}; "
        f"plotly.js {_mb(s.plotly_bytes)} once"
    )
    click.echo(f"index: {s.index}")
    click.echo(
        f"atlas: {s.jobs:,} jobs in {time.perf_counter() - t0:.1f} s (reading the store"
        f" {read_s:.1f} s, pages {s.seconds:.1f} s; index {_mb(s.index.stat().st_size)})",
        err=True,
    )

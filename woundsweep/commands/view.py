"""``woundsweep view RUN_DIR (--job N | --result FILE.h5) --out FILE.html``: one job's 3D
view, self-contained."""

from __future__ import annotations

from pathlib import Path

import click

__all__ = ["cmd"]


@click.command("view")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--job", "job", type=int, help="The job index.")
@click.option(
    "--result",
    type=click.Path(dir_okay=False, path_type=Path),
    help="View the HDF5 file `woundsweep solve --out` wrote (a job of RUN_DIR).",
)
@click.option(
    "--out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="The HTML file to write (opens from disk, no network needed; its directory is "
    "created if missing).",
)
def cmd(run_dir: Path, job: int | None, result: Path | None, out: Path) -> None:
    """Write one HTML file with the job's deformed surface coloured by von Mises (kPa).

    The colour scale ends at the stage's p99 (cells above it are marked), a deformation
    scale, a clipping plane through the wound's mid-section, the profile lines' von Mises
    beside the 3D view, a stage selector (stages without a stored field are listed with the
    reason), the closure zone outlined, the largest von Mises marked, and the job's
    parameters and per-stage table. plotly.js is inlined (about 4.8 MB), so the file works
    offline. A job without a stored result is read from RUN_DIR/solve/job_<N>.h5 when
    `woundsweep solve` wrote it.
    """
    from ..core.errors import WoundsweepError
    from ..core.fsutil import atomic_write, check_output_file
    from ..viz.jobdata import open_job
    from ..viz.view import view_page

    if job is None and result is None:
        raise click.UsageError("give --job N or --result FILE.h5")
    if out.suffix.lower() not in (".html", ".htm"):
        raise click.BadParameter(f"{out}: expected an .html file", param_hint="--out")
    try:
        check_output_file(out)
    except ValueError as err:
        raise WoundsweepError(f"--out {err}") from None
    from ..store.paths import refuse_store_target

    refuse_store_target(run_dir, out, "--out")  # never onto or among the store's files
    jf = open_job(run_dir, job, result=result)
    job = int(jf.job["job_index"])
    data = view_page(jf).encode("utf-8")
    atomic_write(out, lambda tmp: Path(tmp).write_bytes(data))
    stored = [n.stage for n in jf.notes if n.stored]
    src = "" if jf.source.startswith("fields/") else f" (from {jf.source})"
    click.echo(f"job {job}: stages {stored or 'none'}{src}; wrote {out} ({len(data) / 1e6:.1f} MB)")
    for n in jf.notes:
        if not n.stored:
            click.echo(f"job {job}: stage {n.stage} has no view: {n.reason}")

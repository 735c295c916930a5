"""``woundsweep view RUN_DIR --job N --out FILE.html``: one job's 3D view, self-contained."""

from __future__ import annotations

from pathlib import Path

import click

__all__ = ["cmd"]


@click.command("view")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--job", "job", type=int, required=True, help="The job index.")
@click.option(
    "--out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="The HTML file to write (opens from disk, no network needed).",
)
def cmd(run_dir: Path, job: int, out: Path) -> None:
    """Write one HTML file with the job's deformed surface coloured by von Mises (kPa).

    A stage selector (stages without a stored field are listed with the reason), the
    closure zone outlined, the largest von Mises marked, and the job's parameters and
    per-stage table. plotly.js is inlined (about 4.8 MB), so the file works offline.
    """
    from ..core.fsutil import atomic_write
    from ..viz.jobdata import open_job
    from ..viz.view import view_page

    if out.suffix.lower() not in (".html", ".htm"):
        raise click.BadParameter(f"{out}: expected an .html file", param_hint="--out")
    jf = open_job(run_dir, job)
    data = view_page(jf).encode("utf-8")
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, lambda tmp: Path(tmp).write_bytes(data))
    stored = [n.stage for n in jf.notes if n.stored]
    click.echo(f"job {job}: stages {stored or 'none'}; wrote {out} ({len(data) / 1e6:.1f} MB)")
    for n in jf.notes:
        if not n.stored:
            click.echo(f"job {job}: stage {n.stage} has no view: {n.reason}")

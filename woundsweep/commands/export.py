"""``woundsweep export RUN_DIR (--job N | --all) --out DIR``: ParaView series per job."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import click
from tqdm import tqdm

__all__ = ["cmd"]


def _notes_line(info: dict) -> str:
    missing = [s for s in info["stages"] if s["not_exported"]]
    return "; ".join(f"stage {s['stage']} {s['not_exported']}" for s in missing)


@click.command("export")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--job", "job", type=int, help="Export this job index.")
@click.option("--all", "all_", is_flag=True, help="Export every stored job.")
@click.option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Directory for the series (one job-<N>/ folder per job).",
)
def cmd(run_dir: Path, job: int | None, all_: bool, out: Path) -> None:
    """Write ParaView files: per job a PVD series with one VTU per stored stage.

    Each VTU holds the reference mesh (tetrahedra and exterior triangles), the point data
    displacement_mm and the cell data von_mises_kPa, cell_tag, facet_tag and closure_zone
    (Warp By Vector on displacement_mm shows the deformed state). Which stages exist is
    decided by `run --fields`; a stage without a field is named with the reason.
    """
    from ..config.manifest import load_run
    from ..store.reader import read_results
    from ..viz.export import export_job
    from ..viz.jobdata import load_job

    if (job is not None) == all_:
        raise click.UsageError("give exactly one of --job N or --all")
    run = load_run(run_dir)
    if job is not None:
        row = run.job(job)
        rows = read_results(run.run_dir, [str(row["job_id"])])
        info = export_job(load_job(run, row, rows), out)
        stages = [s["stage"] for s in info["stages"] if s["file"]]
        where = out / f"job-{job}" / info["series"]
        click.echo(f"job {job}: stages {stages or 'none'} -> {where}")
        if _notes_line(info):
            click.echo(f"job {job}: not exported: {_notes_line(info)}")
        return
    results = read_results(run.run_dir)
    man = run.manifest[run.manifest["job_id"].isin(set(results["job_id"]))]
    man = man.sort_values(["geometry_id", "job_index"])
    reasons: Counter[str] = Counter()
    n_stages, cache = 0, {}
    by_job = dict(tuple(results.groupby("job_id")))
    for row in tqdm(man.to_dict("records"), desc="export", unit="job", leave=False):
        info = export_job(load_job(run, row, by_job[row["job_id"]], cache), out)
        n_stages += sum(1 for s in info["stages"] if s["file"])
        reasons.update(s["not_exported"] for s in info["stages"] if s["not_exported"])
    pending = len(run.manifest) - len(man)
    click.echo(f"exported {len(man)} jobs ({n_stages} stages) to {out}/job-<N>/job-<N>.pvd")
    if pending:
        click.echo(f"{pending} jobs of the manifest have no stored result yet")
    for reason, count in sorted(reasons.items()):
        click.echo(f"  {count} stages not exported: {reason}")

"""``woundsweep export RUN_DIR (--job N | --all | --result FILE.h5) --out DIR``: ParaView
files per job (`woundsweep.viz.export`)."""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path
from typing import Any

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
    "--result",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Export the HDF5 file `woundsweep solve --out` wrote (a job of RUN_DIR).",
)
@click.option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Directory for the files (one job-<N>/ folder per job; created if missing).",
)
@click.option("--xdmf", is_flag=True, help="Also write the volume series as XDMF + HDF5.")
def cmd(
    run_dir: Path, job: int | None, all_: bool, result: Path | None, out: Path, xdmf: bool
) -> None:
    """Write ParaView files: per job a PVD series over the stored stages, each stage a
    multiblock of the volume (tetrahedra) and the exterior surface (triangles).

    Point data displacement_mm (Warp By Vector shows the deformed state); cell data with
    units: von_mises_kPa (the cell mean of the solver's samples), inverted (1 where the
    solver's state has no stress; its stresses written as 0), cell_tag, and as the solver
    computes them cauchy_stress_kPa, principal_stress_kPa, green_lagrange_strain and det_F
    (P1 runs; P2 runs only where the fields file holds the solver's cell means); on the
    surface facet_tag, closure_zone, normal_traction_kPa and contact_pressure_kPa.
    job-<N>.json says how each array was computed. With --xdmf the .h5 lies beside the
    .xdmf in DIR/job-<N>/. Which stages exist is decided by `run --fields`; a stage without a
    field is named with the reason. A job without a stored result is read from
    RUN_DIR/solve/job_<N>.h5 when `woundsweep solve` wrote it. The time it took is the last
    line, on stderr.
    """
    t0 = time.perf_counter()
    from ..config.manifest import load_run
    from ..core.errors import WoundsweepError
    from ..core.fsutil import check_output_dir
    from ..store.reader import read_results
    from ..viz.export import export_job
    from ..viz.jobdata import load_job, open_job

    if all_ == (job is not None or result is not None):
        raise click.UsageError("give exactly one of --job N (or --result FILE.h5) or --all")
    try:
        check_output_dir(out)
    except ValueError as err:
        raise WoundsweepError(f"--out {err}") from None
    from ..store.paths import refuse_store_target

    refuse_store_target(run_dir, out, "--out")  # never onto or among the store's files
    run = load_run(run_dir)
    if not all_:
        info = export_job(open_job(run_dir, job, result=result), out, xdmf)
        job = info["job_index"]
        stages = [s["stage"] for s in info["stages"] if s["file"]]
        where = out / f"job-{job}" / info["series"]
        click.echo(f"job {job}: stages {stages or 'none'} -> {where}")
        if _notes_line(info):
            click.echo(f"job {job}: not exported: {_notes_line(info)}")
        click.echo(f"export: job {job} in {time.perf_counter() - t0:.1f} s", err=True)
        return
    results = read_results(run.run_dir, run=run)
    man = run.manifest[run.manifest["job_id"].isin(set(results["job_id"]))]
    man = man.sort_values(["geometry_id", "job_index"])
    reasons: Counter[str] = Counter()
    n_stages = 0
    cache: dict[Any, Any] = {}
    by_job = dict(tuple(results.groupby("job_id")))
    for row in tqdm(man.to_dict("records"), desc="export", unit="job", leave=False):
        info = export_job(load_job(run, row, by_job[row["job_id"]], cache), out, xdmf)
        n_stages += sum(1 for s in info["stages"] if s["file"])
        reasons.update(s["not_exported"] for s in info["stages"] if s["not_exported"])
    pending = len(run.manifest) - len(man)
    click.echo(f"exported {len(man)} jobs ({n_stages} stages) to {out}/job-<N>/job-<N>.pvd")
    if pending:
        click.echo(f"{pending} jobs of the manifest have no stored result yet")
    for reason, count in sorted(reasons.items()):
        click.echo(f"  {count} stages not exported: {reason}")
    click.echo(
        f"export: {len(man):,} jobs ({n_stages:,} stages) in {time.perf_counter() - t0:.1f} s",
        err=True,
    )

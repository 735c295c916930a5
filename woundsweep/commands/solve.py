"""``woundsweep solve RUN_DIR --job N [--stages 1-6] [--out FILE.h5]``: one job, in-process.

Exit status (docs/design.md): 0 every requested stage converged; 3 a stage did not converge
(the file is still written; later stages are ``not-run``); 2 invalid input; 4 mesh failed.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import click

from ..errors import SolverError
from ..fsutil import check_output_file
from ..schema import ExitCode, StageResult, StageStatus, parse_stage_range
from ..sweep.grid import load_run

__all__ = ["cmd"]

_HEADER = (
    f"{'stage':>5} {'status':<21}{'newton':>7}{'time s':>8}{'p99 vM kPa':>12}"
    f"{'max vM kPa':>12}{'gap mm':>9}{'min J':>8}"
)


def _fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _row(r: StageResult) -> str:
    return (
        f"{r.stage:>5} {r.status:<21}{_fmt(r.newton_iterations, 'd'):>7}"
        f"{_fmt(r.time_s, '.2f'):>8}{_fmt(r.p99_von_mises_kPa, '.3f'):>12}"
        f"{_fmt(r.max_von_mises_kPa, '.3f'):>12}{_fmt(r.closure_gap_mm, '.4f'):>9}"
        f"{_fmt(r.min_J, '.3f'):>8}"
    )


@click.command("solve")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--job", "job_index", type=int, required=True, help="Manifest job_index.")
@click.option("--stages", "stages_text", default="1-6", show_default=True, help="Stages A-B.")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Output HDF5 file [RUN_DIR/solve/job_<N>.h5].",
)
def cmd(run_dir: Path, job_index: int, stages_text: str, out: Path | None) -> None:
    """Solve one job through the stages and write its HDF5 result."""
    try:  # test-only fault switch (WOUNDSWEEP_FAULT); absent in builds without it
        from ..faults import maybe_inject
    except ImportError:
        maybe_inject = None
    if maybe_inject is not None:
        maybe_inject(job_index)
    # Each job is one serial process; threaded BLAS would only fight the sibling workers.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    stages = parse_stage_range(stages_text, SolverError)
    if out is not None:
        try:
            check_output_file(out)
        except ValueError as err:
            raise SolverError(f"--out {err}") from None
    load_run(run_dir)  # a bad run directory fails here, before DOLFINx is imported
    from ..model.job import NotConvergedError, StageRecord, solve_job

    logging.getLogger().setLevel(logging.WARNING)  # FFCx/cffi log every compile at INFO

    click.echo(f"job {job_index}: stages {stages[0]}-{stages[1]}")
    click.echo(_HEADER)

    def echo(rec: StageRecord) -> None:
        if rec.result.stage >= stages[0]:
            click.echo(_row(rec.result))

    outcome = solve_job(run_dir, job_index, stages, out, echo=echo)
    for rec in outcome.records:
        if rec.result.status == StageStatus.NOT_RUN:
            click.echo(_row(rec.result))
    click.echo(f"wrote {outcome.out}")
    if outcome.exit_code != ExitCode.OK:
        bad = next(r.result for r in outcome.records if r.result.status != StageStatus.CONVERGED)
        raise NotConvergedError(f"job {job_index}: stage {bad.stage} {bad.status}")

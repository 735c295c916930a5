"""The job function: one job through its stages into a solver file, as ``woundsweep solve``
and each job process of ``woundsweep run`` execute it.

`solve` raises `WoundsweepError` for bad input; `run_job` is the process entry of the fork
server's children: it reports such an error on one line and returns the exit status
(`ExitCode`: 0 every requested stage converged, 3 a stage did not, 2 invalid input, 4 a
geometry that cannot be meshed).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from ..config.manifest import load_run
from ..core.errors import SolverError, WoundsweepError, report
from ..core.faults import maybe_inject
from ..core.fsutil import check_output_file
from ..core.schema import ExitCode, StageResult, StageStatus

__all__ = ["SweepChanged", "run_job", "solve"]

_HEADER = (
    f"{'stage':>5} {'status':<21}{'newton':>7}{'time s':>8}{'p99 vM kPa':>12}"
    f"{'max vM kPa':>12}{'gap mm':>9}{'closed':>7}{'min J':>8}"
)


def _fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _closed(flag: int | None) -> str:
    return "-" if flag is None else ("yes" if flag else "OPEN")


def _row(r: StageResult) -> str:
    return (
        f"{r.stage:>5} {r.status:<21}{_fmt(r.newton_iterations, 'd'):>7}"
        f"{_fmt(r.time_s, '.2f'):>8}{_fmt(r.p99_von_mises_kPa, '.3f'):>12}"
        f"{_fmt(r.max_von_mises_kPa, '.3f'):>12}{_fmt(r.closure_gap_max_mm, '.4f'):>9}"
        f"{_closed(r.closed):>7}{_fmt(r.min_J, '.3f'):>8}"
    )


class SweepChanged(WoundsweepError):
    """The run's sweep gives the job another fingerprint than the runner stamps its result
    with (the sweep was rewritten while the run was in progress)."""

    exit_code = ExitCode.SWEEP_CHANGED


def solve(
    run_dir: str | Path,
    job_index: int,
    stages: tuple[int, int],
    out: str | Path | None,
    fingerprint: str = "",
) -> None:
    """Solve manifest job ``job_index`` of ``run_dir`` through stages 1..B, report A..B on
    stdout and write them to ``out`` (default ``RUN_DIR/solve/job_<N>.h5``); raise
    `NotConvergedError` (exit 3, the file written) when a stage did not converge.

    With ``fingerprint`` (a runner's job) the run's sweep, loaded once here and solved with,
    must give the job that result fingerprint (`SweepChanged` otherwise, before any work)."""
    maybe_inject(job_index)  # test-only fault switch (WOUNDSWEEP_FAULT)
    if out is not None:
        try:
            check_output_file(out)
        except ValueError as err:
            raise SolverError(f"--out {err}") from None
    run = load_run(run_dir, job_index)  # a bad run directory fails here, before DOLFINx loads
    if fingerprint:
        from ..store.identity import result_fingerprint

        if result_fingerprint(run.sweep, run.job(job_index)) != fingerprint:
            raise SweepChanged(f"job {job_index}: {run.layout.sweep} changed since the run started")
    from .job import NotConvergedError, StageRecord, solve_job

    logging.getLogger().setLevel(logging.WARNING)  # FFCx/cffi log every compile at INFO
    print(f"job {job_index}: stages {stages[0]}-{stages[1]}", flush=True)
    print(_HEADER, flush=True)

    def echo(rec: StageRecord) -> None:
        if rec.result.stage >= stages[0]:
            print(_row(rec.result), flush=True)

    outcome = solve_job(run_dir, job_index, stages, out, echo=echo, run=run)
    for rec in outcome.records:
        if rec.result.status == StageStatus.NOT_RUN:
            print(_row(rec.result))
    print(f"wrote {outcome.out}", flush=True)
    if outcome.exit_code != ExitCode.OK:
        bad = next(r.result for r in outcome.records if r.result.status != StageStatus.CONVERGED)
        raise NotConvergedError(f"job {job_index}: stage {bad.stage} {bad.status}")


def run_job(
    run_dir: str, job_index: int, stages: tuple[int, int], out: str, fingerprint: str = ""
) -> int:
    """`solve` in a job process: an error becomes one line on stderr and its exit status."""
    try:
        solve(run_dir, job_index, stages, out, fingerprint)
    except (WoundsweepError, OSError) as err:
        sys.stdout.flush()
        return report(err)
    return int(ExitCode.OK)

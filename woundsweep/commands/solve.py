"""``woundsweep solve RUN_DIR --job N [--stages 1-6] [--out FILE.h5]``: one job, in-process.

Exit status (docs/design.md): 0 every requested stage converged; 3 a stage did not converge
(the file is still written; later stages are ``not-run``); 2 invalid input; 4 mesh failed.
"""

from __future__ import annotations

import os
from pathlib import Path

import click

from ..core.errors import SolverError
from ..core.schema import parse_stage_range

__all__ = ["cmd"]


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
    from ..config.manifest import load_run
    from ..store.identity import result_fingerprint
    from ..store.paths import refuse_store_target
    from ..store.solverfile import stamp_fingerprint

    stages = parse_stage_range(stages_text, SolverError)
    run = load_run(run_dir, job_index)
    if out is not None:
        refuse_store_target(run.run_dir, out, "--out")
    from ..physics.entry import solve

    path = out if out is not None else run.layout.solve_file(job_index)
    fingerprint = result_fingerprint(run.sweep, run.job(job_index))
    before = _identity(path)
    try:
        solve(run_dir, job_index, stages, out)
    except BaseException:
        if _identity(path) not in (None, before):  # written (a stage not converged: exit 3)
            stamp_fingerprint(path, fingerprint)
        raise
    stamp_fingerprint(path, fingerprint)  # the file records the settings it was solved with


def _identity(path: Path) -> tuple[int, int] | None:
    """The file's inode and modification time (None if missing): did the solve write it?"""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns

"""``woundsweep solve RUN_DIR --job N [--stages 1-6] [--out FILE.h5]``: one job, in-process.

Exit status (docs/design.md): 0 every requested stage converged; 3 a stage did not converge
(the file is still written; later stages are ``not-run``); 2 invalid input; 4 mesh failed.
"""

from __future__ import annotations

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
    from ..physics.entry import solve

    solve(run_dir, job_index, parse_stage_range(stages_text, SolverError), out)

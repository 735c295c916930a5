"""``woundsweep unpack TABLE RUN_DIR``: a packed table's jobs into a run's store."""

from __future__ import annotations

import time
from pathlib import Path

import click

__all__ = ["cmd"]


@click.command("unpack")
@click.argument("table", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
def cmd(table: Path, run_dir: Path) -> None:
    """Write the jobs of TABLE (from `woundsweep pack`) into RUN_DIR's store, without fields.

    RUN_DIR must exist (`woundsweep generate SWEEP.yaml --out RUN_DIR`). Only jobs of its
    manifest computed with its settings (the same fingerprint) are written, and a job RUN_DIR
    already holds is kept; `woundsweep run` then skips every written job. Refused while a
    `woundsweep run` holds RUN_DIR.
    """
    from tqdm import tqdm

    from ..config.manifest import load_run
    from ..core.runlock import hold_run, release
    from ..store.packed import read_packed, unpack

    t0 = time.perf_counter()
    jobs = read_packed(table)[1].get("jobs", 0)
    load_run(run_dir)  # a run directory, before its lock is taken (and its lock file made)
    lock = hold_run(run_dir, exclusive=True)
    try:
        with tqdm(total=jobs, desc="unpack", unit="job", disable=None) as bar:
            c = unpack(table, run_dir, progress=bar.update)
    finally:
        release(lock)
    click.echo(
        f"{run_dir}: {c.written} of {c.jobs} jobs written, {c.present} already stored,"
        f" {c.other_settings} computed with other settings and {c.not_in_manifest} not in its"
        f" manifest left out ({time.perf_counter() - t0:.1f} s)"
    )

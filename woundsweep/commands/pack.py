"""``woundsweep pack RUN_DIR TABLE``: merge a run's finished results into a packed table."""

from __future__ import annotations

import time
from pathlib import Path

import click

__all__ = ["cmd"]


@click.command("pack")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("table", type=click.Path(dir_okay=False, path_type=Path))
def cmd(run_dir: Path, table: Path) -> None:
    """Merge RUN_DIR's finished results into TABLE, one compact Parquet file (made if missing).

    TABLE holds result rows only (no fields), a few hundred bytes per job: small enough to
    keep in a repository, so that a sweep longer than a sitting continues on another machine
    (`woundsweep unpack TABLE RUN_DIR`, then `woundsweep run`). A job the run computed anew
    replaces its rows in TABLE; packing the same run again changes nothing.
    """
    from ..store.packed import pack

    t0 = time.perf_counter()
    c = pack(run_dir, table)
    click.echo(
        f"{table}: {c.jobs} jobs ({c.rows} rows, {c.bytes / 1e6:.2f} MB); from {run_dir}:"
        f" {c.added} added, {c.replaced} replaced, {c.unchanged} unchanged"
        f" ({time.perf_counter() - t0:.1f} s)"
    )

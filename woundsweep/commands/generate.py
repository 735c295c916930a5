"""``woundsweep generate SWEEP.yaml --out RUN_DIR``."""

from __future__ import annotations

import json
from pathlib import Path

import click
import pandas as pd

from ..config.geometry import GeometrySpec
from ..config.manifest import expand
from ..config.sweep import MANIFEST_COLUMNS, MAX_JOBS, Sweep, parse_sweep_text, read_sweep_text
from ..core.errors import GeometryError, StoreError, SweepError
from ..core.fsutil import atomic_write, atomic_write_bytes
from ..core.layout import RunLayout
from ..core.provenance import provenance
from ..core.runlock import hold_run, release

__all__ = ["cmd", "generate", "stale_results"]


def _to_parquet(manifest: pd.DataFrame, tmp: str) -> None:
    import io

    buf = io.BytesIO()  # bytes written by Python: pyarrow takes a path (or a file's name) as
    manifest.to_parquet(buf, index=False)  # UTF-8 only, so a non-UTF-8 path would not open
    with open(tmp, "wb") as fh:
        fh.write(buf.getbuffer())


def _existing_sweep(run_dir: Path) -> dict | None:
    path = RunLayout(run_dir).sweep
    if not path.exists():
        return None
    try:
        return parse_sweep_text(read_sweep_text(path), path).resolved()
    except SweepError:
        return {"unreadable": True}


def _manifest_matches(path: Path, manifest: pd.DataFrame) -> bool:
    """Does the stored manifest read back whole and equal the expansion of its sweep?"""
    try:
        with open(path, "rb") as fh:  # by Python: pyarrow takes paths as UTF-8 only
            old = pd.read_parquet(fh)
        return bool(old[list(MANIFEST_COLUMNS)].equals(manifest))
    except Exception:  # noqa: BLE001 - any failure to read it back means it must be rewritten
        return False


def stale_results(run_dir: Path, sweep, manifest: pd.DataFrame) -> tuple[int, int]:  # noqa: ANN001
    """(stored results of the manifest's jobs that are stale, results of jobs not in it).

    Reads only the footer records (cheap), so damaged files count as neither.
    """
    from ..store.identity import fingerprints
    from ..store.reader import read_footer, result_files, stale_reason

    files, _ = result_files(run_dir)
    if not files:
        return 0, 0
    expected = fingerprints(sweep, manifest)
    stale = orphans = 0
    for jid, p in files.items():
        if jid not in expected:
            orphans += 1
            continue
        meta = read_footer(p)  # None: damaged, `run` moves it aside
        if meta is not None and stale_reason(meta, expected[jid]):
            stale += 1
    return stale, orphans


def _check_cell_cap(sweep: Sweep, manifest: pd.DataFrame) -> None:
    """Every geometry's mesh within `mesh.sizing.MAX_CELLS` by the size law (no gmsh)."""
    from ..mesh.sizing import check_cell_cap

    for row in manifest.drop_duplicates("geometry_id").to_dict("records"):
        spec = GeometrySpec.from_row(row, sweep.stages.closure_zone, sweep.solver.element_degree)
        try:
            check_cell_cap(spec)
        except GeometryError as err:
            raise SweepError(sweep.path, "grid", str(err)) from None


def generate(
    sweep_path: str | Path,
    run_dir: str | Path,
    *,
    force: bool = False,
    max_jobs: int = MAX_JOBS,
) -> tuple[int, bool]:
    """Write the manifest, the sweep copy and provenance; return (jobs, written).

    Re-generating from an equivalent sweep (same grid and settings, whatever the formatting)
    over a whole manifest is a no-op. A different sweep, or a manifest that is damaged or does
    not match the run's sweep copy, is refused unless ``force``; results are never deleted.
    """
    text = read_sweep_text(sweep_path)
    sweep = parse_sweep_text(text, sweep_path)
    manifest = expand(sweep, max_jobs)
    _check_cell_cap(sweep, manifest)
    rd = Path(run_dir)
    layout = RunLayout(rd)
    if rd.exists() and not rd.is_dir():
        raise StoreError(f"{rd}: exists and is not a directory")
    old = _existing_sweep(rd)
    new = json.loads(json.dumps(sweep.resolved() | {"path": None}))
    if old is not None:
        same = json.loads(json.dumps(old | {"path": None})) == new
        if same and _manifest_matches(layout.manifest, manifest):
            return len(manifest), False
        if not force and not same:
            raise StoreError(
                f"{rd}: already holds a run made from a different sweep (use --force to replace "
                "its manifest; results are kept)"
            )
        if not force:
            raise StoreError(
                f"{layout.manifest}: missing, damaged or not the expansion of "
                f"{layout.sweep} (use --force to rewrite it; results are kept)"
            )
    # Over an existing run, only while no `woundsweep run` holds it: a runner stamps its
    # results with the sweep it loaded when it started.
    lock = hold_run(rd, exclusive=True) if old is not None else None
    try:
        _write_run(rd, sweep_path, text, sweep, manifest, new)
    finally:
        if lock is not None:
            release(lock)
    return len(manifest), True


def _write_run(
    rd: Path, sweep_path: str | Path, text: str, sweep: Sweep, manifest: pd.DataFrame, new: dict
) -> None:
    """Write the manifest, the provenance record and (last) the sweep copy."""
    layout = RunLayout(rd)
    try:
        rd.mkdir(parents=True, exist_ok=True)
        atomic_write(layout.manifest, lambda tmp: _to_parquet(manifest, tmp))
        prov = provenance() | {
            "sweep_file": str(Path(sweep_path).resolve()),
            "sweep_name": sweep.name,
            "jobs": len(manifest),
            "geometries": int(manifest["geometry_id"].nunique()),
            "units": {"length": "mm", "stress": "kPa", "force": "mN", "time": "s"},
            "resolved_sweep": new,
        }
        atomic_write_bytes(layout.provenance, (json.dumps(prov, indent=2) + "\n").encode())
        # The sweep copy goes last: its presence marks a complete generate.
        atomic_write_bytes(layout.sweep, text.encode())
    except OSError as err:
        where = err.filename or rd
        raise StoreError(f"{where}: cannot write the run directory ({err.strerror})") from None


@click.command("generate")
@click.argument("sweep_file", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--out", "run_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
    help="Run directory to create (manifest.parquet, sweep.yaml, provenance.json).",
)  # fmt: skip
@click.option(
    "--force", is_flag=True,
    help="Replace the manifest of a run made from another sweep (or a damaged one).",
)  # fmt: skip
@click.option(
    "--max-jobs", type=click.IntRange(min=1), default=MAX_JOBS, show_default=True,
    help="Refuse grids with more jobs than this (counted before exclusions).",
)  # fmt: skip
def cmd(sweep_file: Path, run_dir: Path, force: bool, max_jobs: int) -> None:
    """Expand SWEEP_FILE into one job per parameter combination.

    Writes RUN_DIR/manifest.parquet (one row per job: job_index, job_id, geometry_id, the
    parameters and the derived lengths in mm), a copy of the sweep and provenance.json.
    Over an existing run (--force) it says how many stored results the new sweep makes stale.
    """
    n, written = generate(sweep_file, run_dir, force=force, max_jobs=max_jobs)
    if not written:
        click.echo(f"{run_dir} is up to date ({n} jobs, same sweep): nothing to do")
        return
    click.echo(f"{n} jobs written to {RunLayout(run_dir).manifest}")
    from ..config.manifest import load_run

    run = load_run(run_dir)
    stale, orphans = stale_results(run.run_dir, run.sweep, run.manifest)
    if stale or orphans:
        click.echo(
            f"stored results: {stale} stale (computed with other settings; `woundsweep run` "
            f"recomputes them), {orphans} of jobs not in the manifest (kept, ignored)"
        )

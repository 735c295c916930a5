"""``woundsweep generate SWEEP.yaml --out RUN_DIR``."""

from __future__ import annotations

import json
from pathlib import Path

import click
import yaml

from ..errors import StoreError, SweepError
from ..fsutil import atomic_write, atomic_write_bytes
from ..provenance import provenance
from ..sweep.grid import expand, load_sweep, parse_sweep

__all__ = ["cmd", "generate"]


def _existing_sweep(run_dir: Path) -> dict | None:
    path = run_dir / "sweep.yaml"
    if not path.is_file():
        return None
    try:
        return parse_sweep(yaml.safe_load(path.read_text()), str(path)).resolved()
    except (SweepError, yaml.YAMLError):
        return {"unreadable": True}


def generate(
    sweep_path: str | Path, run_dir: str | Path, *, force: bool = False
) -> tuple[int, bool]:
    """Write the manifest, the sweep copy and provenance; return (jobs, written).

    Re-generating from an equivalent sweep (same grid and settings, whatever the formatting)
    is a no-op. A different sweep is refused unless ``force``; results are never deleted.
    """
    sweep = load_sweep(sweep_path)
    manifest = expand(sweep)
    rd = Path(run_dir)
    if rd.exists() and not rd.is_dir():
        raise StoreError(f"{rd}: exists and is not a directory")
    old = _existing_sweep(rd)
    new = json.loads(json.dumps(sweep.resolved() | {"path": None}))
    if old is not None:
        old = json.loads(json.dumps(old | {"path": None}))
        if old == new and (rd / "manifest.parquet").is_file():
            return len(manifest), False
        if not force:
            raise StoreError(
                f"{rd}: already holds a run made from a different sweep (use --force to replace "
                "its manifest; results are kept)"
            )
    rd.mkdir(parents=True, exist_ok=True)
    text = Path(sweep_path).read_text()
    atomic_write(rd / "manifest.parquet", lambda tmp: manifest.to_parquet(tmp, index=False))
    prov = provenance() | {
        "sweep_file": str(Path(sweep_path).resolve()),
        "sweep_name": sweep.name,
        "jobs": len(manifest),
        "geometries": int(manifest["geometry_id"].nunique()),
        "units": {"length": "mm", "stress": "kPa", "force": "mN", "time": "s"},
        "resolved_sweep": new,
    }
    atomic_write_bytes(rd / "provenance.json", (json.dumps(prov, indent=2) + "\n").encode())
    # The sweep copy goes last: its presence marks a complete generate.
    atomic_write_bytes(rd / "sweep.yaml", text.encode())
    return len(manifest), True


@click.command("generate")
@click.argument("sweep_file", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--out", "run_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
    help="Run directory to create (manifest.parquet, sweep.yaml, provenance.json).",
)  # fmt: skip
@click.option(
    "--force", is_flag=True, help="Replace the manifest of a run made from another sweep."
)
def cmd(sweep_file: Path, run_dir: Path, force: bool) -> None:
    """Expand SWEEP_FILE into one job per parameter combination.

    Writes RUN_DIR/manifest.parquet (one row per job: job_index, job_id, geometry_id, the
    parameters and the derived lengths in mm), a copy of the sweep and provenance.json.
    """
    n, written = generate(sweep_file, run_dir, force=force)
    if written:
        man = run_dir / "manifest.parquet"
        click.echo(f"{n} jobs written to {man}")
    else:
        click.echo(f"{run_dir} is up to date ({n} jobs, same sweep): nothing to do")

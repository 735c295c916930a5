"""``woundsweep converge RUN_DIR --job N [--levels L] [--ratio r | --factors LIST] [--refine K]
[--stages A-B]``.

Solves one job on L meshes whose mesh size factor grows by r per level, on the listed
factors, or on one mesh and its K uniform refinements (`woundsweep.studies.convergence`), and prints, per
stage and quantity, the value at each level, the observed order p, Roache's grid convergence
index of the finest grid, the Richardson-extrapolated value and the largest deviation of a
level from it, and with four or more levels the least-squares fit over all of them
(`woundsweep.studies.gci.fit_study`). Writes RUN_DIR/convergence/job_<N>.json and job_<N>.png
(job_<N>_refined.* with --refine).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import click

from ..core.errors import SolverError
from ..core.schema import parse_stage_range

__all__ = ["cmd", "study_lines"]

_SHORT = {
    "p99_von_mises_kPa": "p99 vM kPa",
    "max_von_mises_kPa": "max vM kPa",
    "closure_gap_max_mm": "gap mm",
    "contact_force_mN": "contact mN",
    "closure_force_left_mN": "closure mN",
    "closure_traction_kPa": "closing kPa",
    "closing_line_load_max_mN_per_mm": "line mN/mm",
}


def _label(level: dict[str, Any], prefix: str = "") -> str:
    """A level's column head: m=<factor>, and /2^k for its k-th uniform refinement."""
    k = level.get("refinements", 0)
    return prefix + f"m={level['mesh_size_factor']:.3g}" + (f"/{2**k}" if k else "")


def _num(v: Any, spec: str = ".4g") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def study_lines(study: dict[str, Any]) -> list[str]:
    """The printed table: per stage one line per quantity (levels coarse to fine, then p,
    GCI in %, the extrapolated value of the finest triple and the largest |deviation| of a
    level from it in %)."""
    levels = study["levels"]
    head = f"{'stage':>5} {'quantity':<11}" + "".join(f"{_label(lv):>11}" for lv in levels)
    lines = [
        f"job {study['job_index']}: {study['geometry']}",
        "cells: " + ", ".join(str(lv["cells"]) for lv in levels)
        + "; element-size ratios "
        + ", ".join(format(r, ".4f") for r in study["size_ratios"])
        + f"; Fs = {study['safety_factor']}",
        head + f"{'p':>7}{'GCI %':>8}{'f_ext':>11}{'dev %':>8}  kind",
    ]  # fmt: skip
    for stage, per_q in study["studies"].items():
        for q, triples in per_q.items():
            vals = "".join(f"{_num(lv['stages'][stage][q]):>11}" for lv in levels)
            fin = triples[-1]
            gci = None if fin["gci_fine"] is None else 100 * fin["gci_fine"]
            devs = [abs(d) for d in study["deviations"][stage][q] if d is not None]
            dev = 100 * max(devs) if devs else None
            lines.append(
                f"{stage:>5} {_SHORT[q]:<11}{vals}{_num(fin['order'], '.2f'):>7}"
                f"{_num(gci, '.2f'):>8}{_num(fin['extrapolated']):>11}{_num(dev, '.2f'):>8}"
                f"  {fin['kind']}"
            )
        bad = {lv["stages"][stage]["status"] for lv in levels} - {"converged"}
        if bad:
            lines.append(f"{stage:>5} not converged on every level: {', '.join(sorted(bad))}")
    if study.get("fits"):
        lines += _fit_lines(study)
    return lines


def _fit_lines(study: dict[str, Any]) -> list[str]:
    """The least-squares fits over all levels: order p, limit f0, sigma (* when the data
    scatter more than their range), each level's uncertainty U as a % of f0, the largest
    |deviation| from f0 in %, and the fit's form."""
    levels = study["levels"]
    lines = [
        "least-squares fits over all levels (U: each level's uncertainty, % of f0)",
        f"{'stage':>5} {'quantity':<11}{'p':>6}{'f0':>10}{'sigma':>10}"
        + "".join(f"{_label(lv, 'U '):>10}" for lv in levels)
        + f"{'dev %':>8}  form",
    ]
    for stage, per_q in study["fits"].items():
        for q, fit in per_q.items():
            f0 = fit["extrapolated"]
            scale = 100 / abs(f0) if f0 not in (None, 0) and math.isfinite(f0) else None
            us = "".join(
                f"{_num(None if scale is None or u is None else u * scale, '.2f'):>10}"
                for u in fit["uncertainty"]
            )
            devs = [abs(d) for d in study["fit_deviations"][stage][q] if d is not None]
            dev = 100 * max(devs) if devs else None
            mark = "*" if fit["scattered"] else " "
            lines.append(
                f"{stage:>5} {_SHORT[q]:<11}{_num(fit['order'], '.2f'):>6}{_num(f0):>10}"
                f"{_num(fit['sigma'], '.3g'):>9}{mark}{us}{_num(dev, '.2f'):>8}"
                f"  {fit['kind']}{' ' + fit['fit'] if fit['fit'] else ''}"
            )
    return lines


def _check_cells(
    run_dir: Path,
    job_index: int,
    levels: int,
    ratio: float,
    factors: list[float] | None,
    refinements: int | None,
) -> None:
    """Every level within the cell cap (`mesh.sizing.MAX_CELLS`, the size law's estimate),
    before anything is meshed: a level of gmsh, or the base mesh times 8 per refinement."""
    import dataclasses

    from ..config.manifest import load_run
    from ..mesh.sizing import MAX_CELLS, estimate_cells
    from ..studies.convergence import level_factors

    run = load_run(run_dir, job_index)
    base = run.geometry(run.job(job_index))
    if refinements is not None:
        m0 = factors[0] if factors else base.mesh_size_factor
        cells = estimate_cells(dataclasses.replace(base, mesh_size_factor=m0)) * 8**refinements
        if not cells <= MAX_CELLS:
            raise SolverError(
                f"--refine {refinements}: its finest level would have about {cells:.3g} cells, "
                f"above the cap of {MAX_CELLS:,} (refine fewer times or start coarser)"
            )
        return
    for m in factors or level_factors(base.mesh_size_factor, levels, ratio):
        cells = estimate_cells(dataclasses.replace(base, mesh_size_factor=m))
        if not cells <= MAX_CELLS:
            raise SolverError(
                f"the level at mesh size factor {m:g} would have about {cells:.3g} cells, "
                f"above the cap of {MAX_CELLS:,} (fewer or coarser levels)"
            )


@click.command("converge")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--job", "job_index", type=int, required=True, help="Manifest job_index.")
@click.option("--levels", type=int, default=3, show_default=True, help="Number of meshes (>= 3).")
@click.option(
    "--ratio", type=float, default=1.5, show_default=True,
    help="Mesh size factor ratio between levels (element sizes shrink by ratio^(1/3)).",
)  # fmt: skip
@click.option(
    "--factors", "factors_text", default=None, metavar="LIST",
    help="The levels' mesh size factors instead, increasing, up to 8, e.g. 0.3,0.5,0.7,1,1.4 "
    "(the paper's factors and two finer levels).",
)  # fmt: skip
@click.option(
    "--refine", "refinements", type=int, default=None, metavar="K",
    help="The levels are instead one mesh (the job's factor, or the one --factors value) and "
    "its uniform refinements 1..K (K >= 2): nested meshes, element sizes halved and cells "
    "times 8 per level. Writes job_<N>_refined.json and .png.",
)  # fmt: skip
@click.option("--stages", "stages_text", default="1-6", show_default=True, help="Stages A-B.")
def cmd(
    run_dir: Path,
    job_index: int,
    levels: int,
    ratio: float,
    factors_text: str | None,
    refinements: int | None,
    stages_text: str,
) -> None:
    """Solve one job on systematically refined meshes and estimate the discretisation error.

    Level k uses the job's mesh size factor times ratio^k, or the k-th of --factors (every
    other mesh input is the job's). Prints p99, maximum, closure gap, contact force, (stage
    2) closure force and (stage 3) closure traction per level, with the observed order p,
    the grid convergence index of the finest mesh (GCI, Fs = 1.25), the
    Richardson-extrapolated value of the three finest levels and the largest deviation of a
    level from it; with four or more levels also the least-squares fit of each quantity over
    all of them (order, limit, scatter, each level's uncertainty). Writes
    RUN_DIR/convergence/job_<N>.json and job_<N>.png.
    """
    stages = parse_stage_range(stages_text, SolverError)
    from ..studies.convergence import check_refinements, convergence_study, parse_factors

    minimum = 1 if refinements is not None else 3
    factors = None if factors_text is None else parse_factors(factors_text, minimum)
    if refinements is not None:
        check_refinements(refinements, factors)
    _check_cells(run_dir, job_index, levels, ratio, factors, refinements)
    logging.getLogger().setLevel(logging.WARNING)  # FFCx/cffi log every compile at INFO
    study = convergence_study(
        run_dir,
        job_index,
        levels,
        ratio,
        stages,
        echo=click.echo,
        factors=factors,
        refinements=refinements,
    )
    for line in study_lines(study):
        click.echo(line)
    click.echo(f"wrote {study['json']} and {study['figure']}")

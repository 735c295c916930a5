"""Mesh convergence of one job: the stages on systematically refined meshes, with `gci`.

The levels are mesh size factors: m r^k (k < levels, m the job's) or an explicit increasing
list (e.g. the paper's 0.3, 0.5, 0.7 and finer ones, up to `FINEST_FACTOR`), each meshing
the job's geometry (closure zone included); or one such mesh and its uniform refinements
(`woundsweep.mesh.refine`: nested, element sizes halved per level, eight times the cells).
Every other mesh input is the job's. The size law scales every element size with
s = (0.5 / m)^(1/3) (`woundsweep.mesh.sizing`): s is each level's relative element size
(halved per refinement), and the ratios of consecutive sizes are those the observed order
and the GCI use (r^(1/3) for a constant factor ratio r). Each quantity's deviation at
a level is (f - f_ext) / f_ext, f_ext the finest triple's extrapolation. With four or more
levels each quantity is also fitted over all of them by least squares (`gci.fit_study`: order,
limit f0, scatter and each level's uncertainty U), with deviations (f - f0) / f0: meshes that
are not nested scatter about the error's law, which a triple cannot tell from oscillation.
The gmsh meshes are cached under ``RUN_DIR/convergence/meshes/`` (named by their
`GeometrySpec.mesh_id`); the study is written to ``RUN_DIR/convergence/job_<N>.json`` and drawn in
``job_<N>.png`` (``job_<N>_refined.*`` for refinements).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config.geometry import FINEST_FACTOR
from ..core.errors import WoundsweepError
from ..core.fsutil import atomic_write_bytes
from ..core.schema import StageStatus
from .figure import draw_study
from .gci import SAFETY_FACTOR, fit_study, grid_studies

if TYPE_CHECKING:
    from ..physics.job import StageRecord

__all__ = [
    "QUANTITIES",
    "analyse_levels",
    "convergence_study",
    "check_refinements",
    "level_factors",
    "parse_factors",
]

# Per-stage quantities of the study: result fields, and from the diagnostics the stage-2
# closure reaction of the left flank, the mean closing load of stage 3 per deformed zone area
# and the largest closing force per length along the wound.
QUANTITIES = (
    "p99_von_mises_kPa",
    "max_von_mises_kPa",
    "closure_gap_max_mm",
    "contact_force_mN",
    "closure_force_left_mN",
    "closure_traction_kPa",
    "closing_line_load_max_mN_per_mm",
)


# Bounds of a study: levels closer than MIN_RATIO mesh (nearly) alike, and every level and
# refinement multiplies the cost.
MAX_LEVELS = 10
MIN_RATIO = 1.05
MAX_REFINEMENTS = 3


def level_factors(mesh_size_factor: float, levels: int, ratio: float) -> list[float]:
    """The mesh size factors m r^k, k = 0..levels-1 (WoundsweepError, exit 2, if invalid)."""
    if not 3 <= levels <= MAX_LEVELS:
        raise WoundsweepError(f"--levels {levels}: expected 3 (for an order) to {MAX_LEVELS}")
    if not ratio >= MIN_RATIO:
        raise WoundsweepError(
            f"--ratio {ratio:g}: must be at least {MIN_RATIO:g} (closer levels mesh alike)"
        )
    if levels * math.log(ratio) > math.log(FINEST_FACTOR / mesh_size_factor) + 1:
        raise WoundsweepError(  # ratio**k would overflow long before the check below
            f"--levels {levels} --ratio {ratio:g}: the finest level passes {FINEST_FACTOR:g}"
        )
    factors = [mesh_size_factor * ratio**k for k in range(levels)]
    if factors[-1] > FINEST_FACTOR * (1 + 1e-12):
        raise WoundsweepError(
            f"--levels {levels} --ratio {ratio:g} from the job's mesh size factor "
            f"{mesh_size_factor:g} reach {factors[-1]:.3g} > {FINEST_FACTOR:g} "
            "(the finest factor allowed)"
        )
    return [min(f, FINEST_FACTOR) for f in factors]


def check_refinements(refinements: int, factors: list[float] | None) -> None:
    """``--refine K``: K >= 2 (three levels), with at most one listed factor (the base mesh);
    WoundsweepError, exit 2, otherwise."""
    if not 2 <= refinements <= MAX_REFINEMENTS:
        raise WoundsweepError(
            f"--refine {refinements}: expected 2 (3 levels) to {MAX_REFINEMENTS} refinements "
            "(cells times 8 each)"
        )
    if factors is not None and len(factors) != 1:
        raise WoundsweepError("--refine takes one --factors value (the base mesh's), or none")


def parse_factors(text: str, minimum: int = 3) -> list[float]:
    """``--factors`` "0.3,0.5,0.7,1,1.4": at least ``minimum`` increasing factors in
    (0, FINEST_FACTOR] (WoundsweepError, exit 2, otherwise)."""
    try:
        factors = [float(t) for t in text.split(",")]
    except ValueError:
        raise WoundsweepError(f"--factors {text!r}: expected numbers separated by commas") from None
    if len(factors) < minimum:
        raise WoundsweepError(f"--factors {text!r}: at least 3 levels are needed for an order")
    if len(factors) > MAX_LEVELS:
        raise WoundsweepError(f"--factors {text!r}: at most {MAX_LEVELS} levels")
    if not all(0 < f <= FINEST_FACTOR for f in factors):
        raise WoundsweepError(f"--factors {text!r}: each must be in (0, {FINEST_FACTOR:g}]")
    if any(b < a * MIN_RATIO for a, b in zip(factors, factors[1:])):
        raise WoundsweepError(
            f"--factors {text!r}: must increase (coarse to fine) by at least {MIN_RATIO:g} times"
        )
    return factors


def _stage_values(rec: StageRecord) -> dict[str, Any]:
    r = rec.result
    ok = r.status == StageStatus.CONVERGED
    row = {"status": str(r.status), "cells": r.cells, "dofs": r.dofs, "time_s": r.time_s}
    for q in QUANTITIES:
        v: Any = getattr(r, q, None) if q in r._fields else rec.diagnostics.get(q)
        row[q] = float(v) if ok and v is not None and math.isfinite(v) else None
    return row


def convergence_study(
    run_dir: str | Path,
    job_index: int,
    levels: int = 3,
    ratio: float = 1.5,
    stages: tuple[int, int] = (1, 6),
    echo: Callable[[str], None] | None = None,
    jit: dict[str, Any] | None = None,
    factors: list[float] | None = None,
    refinements: int | None = None,
) -> dict[str, Any]:
    """Solve job ``job_index`` at each level, write and return the study (JSON-ready dict).

    The levels are ``factors`` if given, else ``levels`` factors from the job's by ``ratio``;
    with ``refinements`` K they are instead the mesh at the job's factor (or the single one
    of ``factors``) and its uniform refinements 1..K (`woundsweep.mesh.refine`).
    """
    from ..config.manifest import load_run
    from ..mesh.cache import get_mesh
    from ..mesh.refine import refine_uniform
    from ..mesh.sizing import size_scale
    from ..physics.job import job_model, run_stages

    say = echo or (lambda _line: None)
    run = load_run(run_dir)
    row = run.job(job_index)
    base = run.geometry(row)
    if refinements is not None:
        m0 = factors[0] if factors else base.mesh_size_factor
        plan = [(m0, k) for k in range(refinements + 1)]
    else:
        factors = factors or level_factors(base.mesh_size_factor, levels, ratio)
        plan = [(m, 0) for m in factors]
    out_dir = run.layout.convergence_dir
    level_rows = []
    mesh = None
    for k, (m, times) in enumerate(plan):
        spec = dataclasses.replace(base, mesh_size_factor=m)
        if times == 0:
            mesh = get_mesh(out_dir, spec).mesh
        else:
            assert mesh is not None  # the plan starts at an unrefined level (times 0)
            mesh = refine_uniform(mesh)
        how = f", refinement {times}" if times else ""
        say(f"level {k}: mesh size factor {m:.4g}{how}, {mesh.info['cells']} cells")
        model, materials = job_model(run, row, mesh, jit)
        records = run_stages(model, materials, stages[1])
        level_rows.append(
            {
                "mesh_size_factor": m,
                "refinements": times,
                "relative_size": size_scale(m, spec.element_degree) / 2**times,
                "cells": int(mesh.info["cells"]),
                "stages": {
                    str(rec.result.stage): _stage_values(rec)
                    for rec in records
                    if rec.result.stage >= stages[0]
                },
            }
        )
        del model
    study = {
        "job_index": int(job_index),
        "job_id": str(row["job_id"]),
        "geometry": base.describe(),
        "safety_factor": SAFETY_FACTOR,
        "levels": level_rows,
        **analyse_levels(level_rows),
        "units": (
            "mm, kPa, mN, s; gci_fine and deviations are fractions, a fit's sigma and "
            "uncertainty are in the quantity's unit"
        ),
    }
    name = f"job_{int(job_index)}" + ("_refined" if refinements is not None else "")
    path = out_dir / f"{name}.json"
    atomic_write_bytes(path, (json.dumps(_jsonable(study), indent=1) + "\n").encode())
    study["json"] = str(path)
    study["figure"] = str(draw_study(study, out_dir / f"{name}.png"))
    return study


def analyse_levels(level_rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The studies of the levels' values (the module docstring): ``size_ratios``, per stage
    and quantity the triples' ``studies`` and ``deviations``, and with four or more levels
    the least-squares ``fits`` and ``fit_deviations``."""
    sizes = [lv["relative_size"] for lv in level_rows]
    ratios = [a / b for a, b in zip(sizes, sizes[1:])]
    studies: dict[str, dict[str, list[dict[str, Any]]]] = {}
    deviations: dict[str, dict[str, list[float | None]]] = {}
    fits: dict[str, dict[str, dict[str, Any]]] = {}
    fit_deviations: dict[str, dict[str, list[float | None]]] = {}
    for stage in level_rows[0]["stages"]:
        per_q: dict[str, list[dict[str, Any]]] = {}
        dev_q: dict[str, list[float | None]] = {}
        fit_q: dict[str, dict[str, Any]] = {}
        fit_dev_q: dict[str, list[float | None]] = {}
        for q in QUANTITIES:
            values = [lv["stages"][stage][q] for lv in level_rows]
            if all(v is None for v in values):
                continue
            vals = [math.nan if v is None else v for v in values]
            per_q[q] = [s._asdict() for s in grid_studies(vals, sizes)]
            f_ext = per_q[q][-1]["extrapolated"]
            dev_q[q] = _deviations(vals, f_ext)
            # The fit uses the levels where the stage converged (a failed finest level
            # leaves the others' trend).
            ok = [i for i, v in enumerate(vals) if math.isfinite(v)]
            if len(vals) >= 4:
                fit = fit_study([vals[i] for i in ok], [sizes[i] for i in ok])._asdict()
                u = dict(zip(ok, fit["uncertainty"]))
                fit["uncertainty"] = [u.get(i, math.nan) for i in range(len(vals))]
                fit_q[q] = fit
                constant = fit["kind"] == "constant"  # equal up to roundoff: no deviation
                fit_dev_q[q] = (
                    [0.0] * len(vals) if constant else _deviations(vals, fit["extrapolated"])
                )
        studies[stage] = per_q
        deviations[stage] = dev_q
        if fit_q:
            fits[stage], fit_deviations[stage] = fit_q, fit_dev_q
    return {
        "size_ratios": ratios,
        "studies": studies,
        "deviations": deviations,
        "fits": fits,
        "fit_deviations": fit_deviations,
    }


def _deviations(values: list[float], limit: float) -> list[float | None]:
    """(f - limit) / limit per level (None where either is not a number or limit is 0)."""
    ok = math.isfinite(limit) and limit != 0
    return [(v - limit) / limit if ok and math.isfinite(v) else None for v in values]


def _jsonable(x: Any) -> Any:
    """NaN and inf as null (strict JSON)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x

"""Sweep files: loading, validation, and expansion into the job manifest.

A sweep YAML has the sections ``grid`` (axes shared by both wound shapes), ``shapes``
(the shape-specific axis of each wound shape), ``exclude`` (rules, as expressions over the
manifest's columns, that drop combinations), and the settings ``materials``, ``stages``,
``solver`` and ``analysis`` (defaults: the paper's values, see ``DEFAULTS``).

Lengths are in mm, moduli in kPa, penalties in GPa (converted where used).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import itertools
import json
import math
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import yaml

from ..analysis.settings import ModelSettings
from ..errors import GeometryError, StoreError, SweepError
from ..fsutil import read_small_text
from ..mesh.spec import GeometrySpec
from ..model.element import DEGREES
from ..model.parameters import STAGE_SETTINGS, TABLE2
from ..solver.settings import NewtonSettings
from .rules import compile_rule, evaluate_rule

__all__ = [
    "DEFAULTS",
    "GEOMETRY_KEYS",
    "MANIFEST_COLUMNS",
    "MAX_JOBS",
    "MAX_SWEEP_BYTES",
    "Run",
    "Sweep",
    "canonical_hash",
    "count_jobs",
    "expand",
    "load_run",
    "load_sweep",
    "parse_sweep",
    "read_sweep_text",
]

# A sweep file is a small text file; anything larger is refused before it is read whole.
MAX_SWEEP_BYTES = 1_000_000
# Grids above this many jobs (before exclusions) are refused before they are expanded.
MAX_JOBS = 1_000_000

# Grid axes in canonical order: job_index follows this order whatever the YAML key order is.
GRID_AXES = (
    "dermal_thickness_mm",
    "subcutis_thickness_factor",
    "patch_size_factor",
    "wound_width_factor",
    "mesh_size_factor",
    "skin_type",
    "orientation_deg",
)
SHAPE_AXES = {"cylindrical": "wound_aspect_factor", "wedge": "wound_depth_factor"}
# Parameters that define the mesh; the 9 jobs (skin type x orientation) of a geometry share it.
GEOMETRY_KEYS = (
    "wound_shape",
    "dermal_thickness_mm",
    "subcutis_thickness_factor",
    "patch_size_factor",
    "wound_width_factor",
    "mesh_size_factor",
    "wound_depth_factor",
    "wound_aspect_factor",
)
DERIVED = (
    "subcutis_thickness_mm",
    "total_thickness_mm",
    "patch_half_length_mm",
    "wound_width_mm",
    "wound_depth_mm",
)
MANIFEST_COLUMNS = (
    "job_index",
    "job_id",
    "geometry_id",
    *GEOMETRY_KEYS,
    "orientation_deg",
    "skin_type",
    *DERIVED,
)
# The manifest columns an exclusion rule may name.
_RULE_NAMES = frozenset(MANIFEST_COLUMNS) - {"job_index", "job_id", "geometry_id"}

# The paper's settings: Table 2 (`woundsweep.model.parameters`), the stage settings of its
# Methods, the Newton defaults (`woundsweep.solver.settings.NewtonSettings`) and the stress
# model's (`woundsweep.analysis.settings.ModelSettings`).
DEFAULTS: dict[str, Any] = {
    "materials": copy.deepcopy(TABLE2),
    "stages": copy.deepcopy(STAGE_SETTINGS),
    # Numerics: the displacement element's degree (1: P1, 2: P2), the quadrature degree (at
    # least 2 (degree - 1)) and `NewtonSettings` (which documents each key).
    "solver": {
        "element_degree": 1,
        "quadrature_degree": 1,
        **dataclasses.asdict(NewtonSettings()),
    },
    # The stress model (`woundsweep.analysis.settings.ModelSettings` documents each key).
    "analysis": dataclasses.asdict(ModelSettings()),
}
SETTINGS = tuple(DEFAULTS)
CHOICES = {"stages.contact_model": ("smooth",)}  # the string-valued settings
# String-setting values refused with a message of their own.
_GONE = "was removed; the only contact model is 'smooth' (docs/model.md, 'Contact')"
REMOVED_CHOICES = {
    "stages.contact_model": {"depth": f"'depth' {_GONE}", "surface": f"'surface' {_GONE}"},
}
TOP_KEYS = ("name", "description", "grid", "shapes", "exclude", *SETTINGS)


class Sweep(NamedTuple):
    """A validated sweep: grid axes and settings with defaults filled in."""

    path: str
    name: str
    grid: dict[str, list[Any]]
    shapes: dict[str, dict[str, list[float]]]
    exclude: list[str]
    materials: dict[str, Any]
    stages: dict[str, Any]
    solver: dict[str, Any]
    analysis: dict[str, Any]

    def resolved(self) -> dict[str, Any]:
        """Everything that determines the jobs and their results (not the file's formatting)."""
        d = self._asdict()
        d.pop("path")
        return d


class Run(NamedTuple):
    """A run directory made by ``woundsweep generate``."""

    run_dir: Path
    sweep: Sweep
    manifest: pd.DataFrame


def _is_number(v: Any) -> bool:
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:  # an integer too large for a float
        return False


def _axis(path: str, key: str, values: Any, *, kind: str = "positive") -> list[Any]:
    if not isinstance(values, list) or not values:
        raise SweepError(path, key, f"expected a non-empty list, got {values!r}")
    for v in values:
        if kind == "name":
            if not isinstance(v, str) or not v:
                raise SweepError(path, key, f"expected names (strings), got {v!r}")
            continue
        if not _is_number(v):
            raise SweepError(path, key, f"expected numbers, got {v!r}")
        if kind == "positive" and v <= 0:
            raise SweepError(path, key, f"expected positive numbers, got {v!r}")
        if kind == "nonnegative" and v < 0:
            raise SweepError(path, key, f"expected non-negative numbers, got {v!r}")
    if len(set(values)) != len(values):
        raise SweepError(path, key, f"duplicate values in {values!r}")
    return [v if kind == "name" else float(v) for v in values]


def _merge(path: str, key: str, default: Any, given: Any) -> Any:
    """Overlay ``given`` on ``default``, checking keys and types against the default."""
    if given is None:
        return copy.deepcopy(default)
    if isinstance(default, dict):
        if not isinstance(given, dict):
            raise SweepError(path, key, f"expected a mapping, got {type(given).__name__}")
        # skin_types is open: new names may be added, each with the full Fung parameter set.
        if key.endswith("skin_types"):
            out = {}
            template = default["normal"]
            for name, params in given.items():
                if not isinstance(name, str) or not isinstance(params, dict):
                    raise SweepError(
                        path, f"{key}.{name}", "expected a skin type name with a mapping of values"
                    )
                base = default.get(name)
                if base is None:
                    missing = set(template) - set(params or {})
                    if missing:
                        raise SweepError(path, f"{key}.{name}", f"missing keys {sorted(missing)}")
                    base = template
                out[name] = _merge(path, f"{key}.{name}", base, params)
            return out
        unknown = set(given) - set(default)
        if unknown:
            raise SweepError(
                path,
                f"{key}.{sorted(unknown)[0]}",
                f"unknown key (expected one of {sorted(default)})",
            )
        return {k: _merge(path, f"{key}.{k}", default[k], given.get(k)) for k in default}
    if isinstance(default, str):
        if not isinstance(given, str):
            raise SweepError(path, key, f"expected one of {list(CHOICES[key])}, got {given!r}")
        if key in REMOVED_CHOICES and given in REMOVED_CHOICES[key]:
            raise SweepError(path, key, REMOVED_CHOICES[key][given])
        if given not in CHOICES[key]:
            raise SweepError(path, key, f"expected one of {list(CHOICES[key])}, got {given!r}")
        return str(given)
    if isinstance(default, list):
        if not isinstance(given, list) or len(given) != len(default):
            raise SweepError(path, key, f"expected a list of {len(default)} numbers, got {given!r}")
        return [_merge(path, f"{key}[{i}]", d, g) for i, (d, g) in enumerate(zip(default, given))]
    if isinstance(default, bool) or not _is_number(given):
        raise SweepError(path, key, f"expected a number, got {given!r}")
    if isinstance(default, int) and not float(given).is_integer():
        raise SweepError(path, key, f"expected an integer, got {given!r}")
    if isinstance(default, int):
        if given < 0:
            raise SweepError(path, key, f"expected a non-negative integer, got {given!r}")
        return int(given)
    if given <= 0:
        raise SweepError(path, key, f"expected a positive number, got {given!r}")
    return float(given)


def parse_sweep(data: Any, path: str = "<sweep>") -> Sweep:
    """Validate a parsed sweep document; raise `SweepError` naming the key path."""
    if not isinstance(data, dict):
        raise SweepError(path, "", "expected a mapping at the top level")
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        raise SweepError(path, str(unknown[0]), f"unknown key (expected one of {list(TOP_KEYS)})")
    for key in ("grid", "shapes"):
        if key not in data:
            raise SweepError(path, key, "missing section")
    grid_in = data["grid"]
    if not isinstance(grid_in, dict):
        raise SweepError(path, "grid", "expected a mapping of axis name -> list of values")
    for k in grid_in:
        if k not in GRID_AXES:
            raise SweepError(path, f"grid.{k}", f"unknown axis (expected one of {list(GRID_AXES)})")
    grid: dict[str, list[Any]] = {}
    for k in GRID_AXES:
        if k not in grid_in:
            raise SweepError(path, f"grid.{k}", "missing axis")
        kind = {"skin_type": "name", "orientation_deg": "number"}.get(k, "positive")
        grid[k] = _axis(path, f"grid.{k}", grid_in[k], kind=kind)

    shapes_in = data["shapes"]
    if not isinstance(shapes_in, dict) or not shapes_in:
        raise SweepError(path, "shapes", "expected a non-empty mapping of wound shape -> axis")
    shapes: dict[str, dict[str, list[float]]] = {}
    for shape in sorted(shapes_in):
        if shape not in SHAPE_AXES:
            raise SweepError(
                path, f"shapes.{shape}", f"unknown wound shape (expected one of {list(SHAPE_AXES)})"
            )
        spec = shapes_in[shape]
        axis = SHAPE_AXES[shape]
        if not isinstance(spec, dict) or set(spec) != {axis}:
            raise SweepError(path, f"shapes.{shape}", f"expected exactly the key {axis!r}")
        kind = "nonnegative" if shape == "cylindrical" else "positive"
        shapes[shape] = {axis: _axis(path, f"shapes.{shape}.{axis}", spec[axis], kind=kind)}
    if max(grid["mesh_size_factor"]) > 1:
        raise SweepError(
            path,
            "grid.mesh_size_factor",
            f"expected factors in (0, 1] (larger is finer), got {max(grid['mesh_size_factor'])!r}",
        )
    if max(grid["wound_width_factor"]) > 2:
        raise SweepError(
            path,
            "grid.wound_width_factor",
            "expected factors up to 2 (the width is a fraction of the patch half-length and "
            f"must fit the patch), got {max(grid['wound_width_factor'])!r}",
        )
    if "wedge" in shapes and max(shapes["wedge"]["wound_depth_factor"]) >= 1:
        raise SweepError(
            path,
            "shapes.wedge.wound_depth_factor",
            "expected factors below 1 (the depth is a fraction of the total thickness)",
        )

    exclude = data.get("exclude") or []
    if not isinstance(exclude, list) or not all(isinstance(r, str) for r in exclude):
        raise SweepError(path, "exclude", "expected a list of rule expressions (strings)")
    for i, rule in enumerate(exclude):
        compile_rule(path, f"exclude[{i}]", rule, _RULE_NAMES)

    settings = {k: _merge(path, k, DEFAULTS[k], data.get(k)) for k in SETTINGS}
    known = set(settings["materials"]["skin_types"])
    for name in grid["skin_type"]:
        if name not in known:
            raise SweepError(
                path,
                "grid.skin_type",
                f"unknown skin type {name!r} (expected one of {sorted(known)})",
            )
    degree = settings["solver"]["element_degree"]
    if degree not in DEGREES:
        raise SweepError(
            path, "solver.element_degree", f"expected one of {DEGREES}, got {degree!r}"
        )
    zone = settings["stages"]["closure_zone"]
    for k, v in zone.items():
        if v > 1:
            raise SweepError(
                path, f"stages.closure_zone.{k}", f"expected a fraction in (0, 1], got {v!r}"
            )
    return Sweep(
        path=str(path),
        name=str(data.get("name") or Path(str(path)).stem),
        grid=grid,
        shapes=shapes,
        exclude=list(exclude),
        **settings,
    )


def read_sweep_text(path: str | Path) -> str:
    """The text of a sweep file: a regular UTF-8 text file of at most `MAX_SWEEP_BYTES`.

    Anything else (a directory, a named pipe, a device, a binary or UTF-16 file) is refused
    at once (`fsutil.read_small_text`: no blocking open, no read beyond the limit).
    """
    try:
        return read_small_text(path, MAX_SWEEP_BYTES, "a YAML text file")
    except ValueError as err:
        raise SweepError(path, "", str(err)) from None


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep YAML file."""
    p = Path(path)
    return parse_sweep_text(read_sweep_text(p), p)


def parse_sweep_text(text: str, path: str | Path) -> Sweep:
    """Parse and validate the YAML text of a sweep file (``path`` names it in errors)."""
    p = Path(path)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "YAML"
        problem = getattr(err, "problem", None) or "invalid YAML"
        raise SweepError(p, where, f"YAML syntax error: {problem}") from None
    except RecursionError:
        raise SweepError(p, "YAML", "nested too deeply") from None
    return parse_sweep(data, str(p))


# -- expansion ---------------------------------------------------------------------------


def canonical_hash(params: dict[str, Any]) -> str:
    """16 hex chars of sha256 over the sorted, type-normalised parameters (floats as repr)."""
    norm = {
        k: (float(v) if _is_number(v) else v)
        for k, v in params.items()
        if not (isinstance(v, float) and math.isnan(v))
    }
    blob = json.dumps(norm, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _derive(df: pd.DataFrame) -> pd.DataFrame:
    td = df["dermal_thickness_mm"]
    df["subcutis_thickness_mm"] = df["subcutis_thickness_factor"] * td
    df["total_thickness_mm"] = td + df["subcutis_thickness_mm"]
    df["patch_half_length_mm"] = df["patch_size_factor"] * df["total_thickness_mm"]
    w = df["wound_width_factor"] * df["patch_half_length_mm"]
    df["wound_width_mm"] = w
    a = df["wound_aspect_factor"]
    # Cylinder axis a*w above the surface, radius through the surface edges at x = 0 and w.
    cyl_depth = np.sqrt((w / 2) ** 2 + (a * w) ** 2) - a * w
    wedge_depth = df["wound_depth_factor"] * df["total_thickness_mm"]
    df["wound_depth_mm"] = np.where(df["wound_shape"] == "cylindrical", cyl_depth, wedge_depth)
    return df


def count_jobs(sweep: Sweep) -> int:
    """The jobs of the grid before exclusions (computed without expanding it)."""
    common = math.prod(len(sweep.grid[k]) for k in GRID_AXES)
    return sum(common * len(sweep.shapes[s][SHAPE_AXES[s]]) for s in sweep.shapes)


def _check_geometries(sweep: Sweep, df: pd.DataFrame) -> None:
    """Every geometry must be buildable (`GeometrySpec`), so no job fails on its ranges later."""
    for row in df.drop_duplicates(list(GEOMETRY_KEYS)).to_dict("records"):
        try:
            GeometrySpec.from_row(row)
        except GeometryError as err:
            where = ", ".join(
                f"{k}={row[k]:g}" if isinstance(row[k], float) else f"{k}={row[k]}"
                for k in GEOMETRY_KEYS
                if not (isinstance(row[k], float) and math.isnan(row[k]))
            )
            raise SweepError(sweep.path, "grid", f"geometry {where}: {err}") from None


def expand(sweep: Sweep, max_jobs: int = MAX_JOBS) -> pd.DataFrame:
    """Expand a sweep into the manifest (one row per job, geometry-major stable order).

    A grid of more than ``max_jobs`` jobs (before exclusions) is refused before expansion.
    """
    total = count_jobs(sweep)
    if total > max_jobs:
        raise SweepError(
            sweep.path,
            "grid",
            f"the grid has {total} jobs before exclusions, above the limit of {max_jobs} "
            "(generate --max-jobs raises it)",
        )
    rows = []
    for shape in sorted(sweep.shapes):
        axis = SHAPE_AXES[shape]
        axes = [sweep.grid[k] for k in GRID_AXES[:5]] + [sweep.shapes[shape][axis]]
        axes += [sweep.grid["skin_type"], sweep.grid["orientation_deg"]]
        names = [*GRID_AXES[:5], axis, "skin_type", "orientation_deg"]
        for values in itertools.product(*axes):
            row = dict(zip(names, values))
            row["wound_shape"] = shape
            rows.append(row)
    df = pd.DataFrame(rows)
    for axis in SHAPE_AXES.values():
        if axis not in df:
            df[axis] = np.nan
    df = _derive(df)
    keep = np.ones(len(df), dtype=bool)
    for i, rule in enumerate(sweep.exclude):
        tree = compile_rule(sweep.path, f"exclude[{i}]", rule, _RULE_NAMES)
        with np.errstate(all="ignore"):  # x / 0 is inf, as in NumPy; no warning on stderr
            hit = evaluate_rule(tree, df)
        keep &= ~np.broadcast_to(np.asarray(hit, dtype=bool), keep.shape)
    df = df[keep].reset_index(drop=True)
    if df.empty:
        raise SweepError(sweep.path, "exclude", "the grid expands to zero jobs")
    _check_geometries(sweep, df)
    job_keys = [*GEOMETRY_KEYS, "skin_type", "orientation_deg"]
    records = df[job_keys].to_dict("records")
    df["job_id"] = [canonical_hash(r) for r in records]
    # One hash per geometry, not per job (the skin type x orientation jobs share it).
    codes = df.groupby(list(GEOMETRY_KEYS), dropna=False, sort=False).ngroup().to_numpy()
    first = pd.Series(np.arange(len(df))).groupby(codes).first().to_numpy()
    gids = np.array([canonical_hash({k: records[i][k] for k in GEOMETRY_KEYS}) for i in first])
    df["geometry_id"] = gids[codes]
    df["job_index"] = np.arange(len(df), dtype=np.int64)
    if df["job_id"].duplicated().any():
        raise SweepError(sweep.path, "grid", "duplicate jobs (two axis values give the same job)")
    return df[list(MANIFEST_COLUMNS)]


def load_run(run_dir: str | Path) -> Run:
    """Open a run directory: its sweep copy and its manifest."""
    rd = Path(run_dir)
    manifest_path, sweep_path = rd / "manifest.parquet", rd / "sweep.yaml"
    if not manifest_path.is_file() or not sweep_path.is_file():
        raise StoreError(
            f"{rd}: not a run directory (run `woundsweep generate SWEEP.yaml --out {rd}`)"
        )
    try:
        manifest = pd.read_parquet(manifest_path)
    except Exception as err:  # pyarrow raises several types for damaged files
        raise StoreError(f"{manifest_path}: unreadable manifest ({type(err).__name__})") from None
    missing = [c for c in MANIFEST_COLUMNS if c not in manifest.columns]
    if missing:
        raise StoreError(f"{manifest_path}: missing columns {missing}")
    return Run(rd, load_sweep(sweep_path), manifest)

"""The manifest (a sweep expanded into one row per job) and the run directory that holds it.

`expand` turns a `Sweep` into the manifest's rows in a stable geometry-major order (the
grid's product, or the random draws of its ``sample`` design); job and geometry ids are
content hashes of the parameters. `load_run` opens a run directory made by
``woundsweep generate``; `Run.job` and `Run.geometry` give one job's manifest row and mesh
parameters (`job_geometry`; their `GeometrySpec.mesh_id` names the job's mesh files).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple, TypedDict

import numpy as np
import pandas as pd

from ..core.errors import GeometryError, StoreError, SweepError
from ..core.layout import RunLayout
from .design import draw_sample, sampled_jobs
from .geometry import GeometrySpec
from .rules import compile_rule, evaluate_rule
from .sweep import (
    DERIVED,
    GEOMETRY_KEYS,
    GRID_AXES,
    MANIFEST_COLUMNS,
    MAX_JOBS,
    RULE_NAMES,
    SHAPE_AXES,
    Sweep,
    is_number,
    load_sweep,
)

__all__ = [
    "ID_RE",
    "JobRow",
    "Run",
    "canonical_hash",
    "count_jobs",
    "expand",
    "job_geometry",
    "load_run",
    "manifest_problem",
]

# job_id and geometry_id: 16 hex digits (they name the store's files).
ID_RE = re.compile(r"[0-9a-f]{16}")


class JobRow(TypedDict):
    """One manifest row (`MANIFEST_COLUMNS`; lengths in mm). A shape's own factors are NaN for
    the other shapes: ``wound_depth_factor`` for a cylinder, ``wound_aspect_factor`` for a
    wedge or an excision, ``wound_length_factor`` and ``wound_length_mm`` for the trenches."""

    job_index: int
    job_id: str
    geometry_id: str
    wound_shape: str
    dermal_thickness_mm: float
    subcutis_thickness_factor: float
    patch_size_factor: float
    wound_width_factor: float
    mesh_size_factor: float
    wound_depth_factor: float
    wound_aspect_factor: float
    wound_length_factor: float
    orientation_deg: float
    skin_type: str
    subcutis_thickness_mm: float
    total_thickness_mm: float
    patch_half_length_mm: float
    wound_width_mm: float
    wound_depth_mm: float
    wound_length_mm: float


def canonical_hash(params: dict[str, Any]) -> str:
    """16 hex chars of sha256 over the sorted, type-normalised parameters (floats as repr)."""
    norm = {
        k: (float(v) if is_number(v) else v)
        for k, v in params.items()
        if not (isinstance(v, float) and math.isnan(v))
    }
    blob = json.dumps(norm, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _encoded(column: pd.Series, nan: str | None) -> list[str | None] | None:
    """A column's values as canonical JSON texts (numbers as float reprs, strings quoted; a
    NaN as ``nan``, None meaning the key is left out); None for any other value."""
    if column.dtype.kind in "fiu":
        a = column.to_numpy(dtype=float)
        if np.isinf(a).any():
            return None
        out: list[str | None] = [repr(x) for x in a.tolist()]
        for i in np.flatnonzero(np.isnan(a)).tolist():
            out[i] = nan
        return out
    texts: dict[Any, str | None] = {}
    out = []
    for v in column.tolist():
        key = (type(v), v)
        if key not in texts:
            if isinstance(v, str):
                texts[key] = json.dumps(v)
            elif isinstance(v, float) and math.isnan(v):
                texts[key] = nan
            elif is_number(v):
                texts[key] = repr(float(v))
            else:
                return None
        out.append(texts[key])
    return out


def json_rows(frame: pd.DataFrame, keys: Sequence[str], nan: str | None) -> list[str] | None:
    """Each row of ``frame``'s ``keys`` as the text ``json.dumps(row, sort_keys=True,
    separators=(",", ":"))`` gives for it after `canonical_hash`'s normalisation (numbers as
    floats; a NaN left out when ``nan`` is None, else written as ``nan``), built column by
    column (a million rows in seconds); None when a value is neither a string nor a finite
    number (the caller then takes the row-by-row path)."""
    columns = []
    for k in sorted(keys):
        enc = _encoded(frame[k], nan)
        if enc is None:
            return None
        columns.append((json.dumps(k) + ":", enc))
    rows = []
    for i in range(len(frame)):
        parts = [name + col[i] for name, col in columns if col[i] is not None]  # type: ignore[operator]
        rows.append("{" + ",".join(parts) + "}")
    return rows


def canonical_hashes(frame: pd.DataFrame, keys: Sequence[str]) -> list[str]:
    """`canonical_hash` of each row's ``keys``, in order."""
    rows = json_rows(frame, keys, None)
    if rows is None:
        return [canonical_hash(r) for r in frame[list(keys)].to_dict("records")]
    return [hashlib.sha256(r.encode()).hexdigest()[:16] for r in rows]


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
    df["wound_length_mm"] = df["wound_length_factor"] * w  # the excision's l; NaN otherwise
    return df


def _frame(df: pd.DataFrame) -> pd.DataFrame:
    """Job parameters completed into the manifest's parameter and derived columns (a shape's
    own factors NaN for the other shapes)."""
    for axis in sorted({a for own in SHAPE_AXES.values() for a in own}):
        if axis not in df:
            df[axis] = np.nan
    return _derive(df)


def count_jobs(sweep: Sweep) -> int:
    """The jobs of the grid before exclusions (computed without expanding it); of a sampled
    sweep, shapes x geometries x skin types."""
    if sweep.sample is not None:
        return sampled_jobs(sweep)
    common = math.prod(len(sweep.grid[k]) for k in GRID_AXES)
    return sum(
        common * math.prod(len(sweep.shapes[s][a]) for a in SHAPE_AXES[s]) for s in sweep.shapes
    )


def job_geometry(sweep: Sweep, row: JobRow | Mapping[str, Any]) -> GeometrySpec:
    """The `GeometrySpec` of a manifest row with the sweep's closure zone and element degree
    (both part of the mesh); GeometryError names the job."""
    return GeometrySpec.from_row(row, sweep.stages.closure_zone, sweep.solver.element_degree)


def _check_geometries(sweep: Sweep, df: pd.DataFrame) -> None:
    """Every geometry must be buildable (`GeometrySpec`), so no job fails on its ranges later."""
    for row in df.drop_duplicates(list(GEOMETRY_KEYS)).to_dict("records"):
        try:
            job_geometry(sweep, row)
        except GeometryError as err:
            where = ", ".join(
                f"{k}={row[k]:g}" if isinstance(row[k], float) else f"{k}={row[k]}"
                for k in GEOMETRY_KEYS
                if not (isinstance(row[k], float) and math.isnan(row[k]))
            )
            raise SweepError(sweep.path, "grid", f"geometry {where}: {err}") from None


def expand(sweep: Sweep, max_jobs: int = MAX_JOBS) -> pd.DataFrame:
    """Expand a sweep into the manifest (one row per job, geometry-major stable order): the
    grid's product less the excluded jobs, or a sampled sweep's draws (`design.draw_sample`).

    A grid of more than ``max_jobs`` jobs (before exclusions) is refused before expansion.
    """
    total = count_jobs(sweep)
    if total > max_jobs:
        key = "grid" if sweep.sample is None else "sample"
        when = " before exclusions" if sweep.sample is None else ""
        raise SweepError(
            sweep.path,
            key,
            f"the {key} has {total} jobs{when}, above the limit of {max_jobs} "
            "(generate --max-jobs raises it)",
        )
    trees = [
        compile_rule(sweep.path, f"exclude[{i}]", rule, RULE_NAMES)
        for i, rule in enumerate(sweep.exclude)
    ]

    def excluded(df: pd.DataFrame) -> np.ndarray:
        hit = np.zeros(len(df), dtype=bool)
        for tree in trees:
            with np.errstate(all="ignore"):  # x / 0 is inf, as in NumPy; no warning on stderr
                out = evaluate_rule(tree, df)
            hit |= np.broadcast_to(np.asarray(out, dtype=bool), hit.shape)
        return hit

    if sweep.sample is not None:
        df = draw_sample(sweep, _frame, excluded)
    else:
        rows = []
        for shape in sorted(sweep.shapes):
            own = SHAPE_AXES[shape]
            axes = [sweep.grid[k] for k in GRID_AXES[:5]] + [sweep.shapes[shape][a] for a in own]
            axes += [sweep.grid["skin_type"], sweep.grid["orientation_deg"]]
            names = [*GRID_AXES[:5], *own, "skin_type", "orientation_deg"]
            for values in itertools.product(*axes):
                row = dict(zip(names, values))
                row["wound_shape"] = shape
                rows.append(row)
        df = _frame(pd.DataFrame(rows))
        df = df[~excluded(df)].reset_index(drop=True)
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


class Run(NamedTuple):
    """A run directory made by ``woundsweep generate``: its sweep and its manifest."""

    run_dir: Path
    sweep: Sweep
    manifest: pd.DataFrame

    @property
    def layout(self) -> RunLayout:
        """The run directory's paths."""
        return RunLayout(self.run_dir)

    def job(self, job_index: int) -> JobRow:
        """The manifest row of ``job_index`` as a dict of plain values (StoreError if none)."""
        hit = self.manifest[self.manifest["job_index"] == int(job_index)]
        if hit.empty:
            raise StoreError(f"no job {job_index} (the run has jobs 0-{len(self.manifest) - 1})")
        row = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in hit.iloc[0].items()}
        return row  # type: ignore[return-value]

    def geometry(self, row: JobRow | Mapping[str, Any]) -> GeometrySpec:
        """`job_geometry` of a manifest row with the run's sweep."""
        return job_geometry(self.sweep, row)


# Manifest columns of the fusiform excision (NaN for the trenches).
_LATER_COLUMNS = ("wound_length_factor", "wound_length_mm")


def load_run(run_dir: str | Path, job: int | None = None) -> Run:
    """Open a run directory: its sweep copy and its manifest.

    With ``job`` only that job's row has its ids recomputed from its parameters (a job's
    process: its runner checked every row; hashing all 11,664 rows of the paper grid costs a
    short job a tenth of its CPU time); every other check covers the whole manifest."""
    rd = Path(run_dir)
    layout = RunLayout(rd)
    manifest_path, sweep_path = layout.manifest, layout.sweep
    if not manifest_path.is_file() or not sweep_path.is_file():
        raise StoreError(
            f"{rd}: not a run directory (run `woundsweep generate SWEEP.yaml --out {rd}`)"
        )
    try:
        with open(manifest_path, "rb") as fh:  # by Python: pyarrow takes paths as UTF-8 only
            manifest = pd.read_parquet(fh)
    except Exception as err:  # pyarrow raises several types for damaged files
        raise StoreError(f"{manifest_path}: unreadable manifest ({type(err).__name__})") from None
    for name in _LATER_COLUMNS:  # absent from manifests made before the excision existed
        if name not in manifest.columns:
            manifest[name] = np.nan
    missing = [c for c in MANIFEST_COLUMNS if c not in manifest.columns]
    if missing:
        raise StoreError(f"{manifest_path}: missing columns {missing}")
    sweep = load_sweep(sweep_path)
    problem = manifest_problem(manifest, sweep, None if job is None else (int(job),))
    if problem:
        raise StoreError(
            f"{manifest_path}: damaged manifest: {problem} (rewrite it with `woundsweep "
            f"generate SWEEP.yaml --out {rd} --force`; results are kept)"
        )
    return Run(rd, sweep, manifest)


def _ids_ok(values: pd.Series) -> bool:
    return bool(values.map(lambda v: isinstance(v, str) and ID_RE.fullmatch(v) is not None).all())


def manifest_problem(
    manifest: pd.DataFrame, sweep: Sweep, hashed: Sequence[int] | None = None
) -> str:
    """What makes ``manifest`` not a manifest `expand` could have written ("" if nothing):
    indices not 0..N-1, duplicate jobs, ids that are not 16 hex digits or not the hash of the
    row's parameters (ids name files; only the rows ``hashed``, default all), derived lengths
    that differ from the parameters' (they size the mesh), a shape or skin type the sweep does
    not know."""
    n = len(manifest)
    if n == 0:
        return "no jobs"
    idx = manifest["job_index"]
    if idx.dtype.kind not in "iu" or not (idx.to_numpy() == np.arange(n)).all():
        return f"job_index is not 0..{n - 1} in order"
    for col in ("job_id", "geometry_id"):
        if not _ids_ok(manifest[col]):
            return f"a {col} is not 16 hex digits"
    dup = manifest["job_id"].duplicated()
    if dup.any():
        return f"job {int(idx[dup].iloc[0])} duplicates job_id {manifest['job_id'][dup].iloc[0]}"
    shapes, skins = manifest["wound_shape"], manifest["skin_type"]
    if not shapes.isin(list(SHAPE_AXES)).all():
        return f"unknown wound_shape {shapes[~shapes.isin(list(SHAPE_AXES))].iloc[0]!r}"
    known = list(sweep.materials.skin_types)
    if not skins.isin(known).all():
        return f"skin_type {skins[~skins.isin(known)].iloc[0]!r} is not in the sweep"
    params = manifest[[*GEOMETRY_KEYS, "skin_type", "orientation_deg"]].copy()
    try:
        derived = _derive(params.copy())
        numeric = manifest[[*GEOMETRY_KEYS[1:], "orientation_deg", *DERIVED]].astype(float)
    except (TypeError, ValueError):
        return "a parameter is not a number"
    for col in DERIVED:
        a, b = numeric[col].to_numpy(), derived[col].to_numpy(dtype=float)
        bad = ~np.isclose(a, b, rtol=1e-12, atol=0.0, equal_nan=True)
        if bad.any():
            return f"job {int(idx[bad].iloc[0])}: {col} is not derived from its parameters"
    rows = list(range(n)) if hashed is None else [i for i in hashed if 0 <= i < n]
    picked = params.iloc[rows]
    job_ids, geometry_ids = manifest["job_id"].tolist(), manifest["geometry_id"].tolist()
    for i, h in zip(rows, canonical_hashes(picked, list(params.columns))):
        if h != job_ids[i]:
            return f"job {i}: job_id is not the hash of its parameters"
    gids = pd.Series([geometry_ids[i] for i in rows])
    first = ~gids.duplicated().to_numpy()  # each geometry's hash computed once
    firsts = [i for i, f in zip(rows, first) if f]
    for i, h in zip(firsts, canonical_hashes(params.iloc[firsts], list(GEOMETRY_KEYS))):
        if h != geometry_ids[i]:
            return f"job {i}: geometry_id is not the hash of its geometry"
    return ""

"""Sweep files: their schema, loading and validation into a typed `Sweep`.

A sweep YAML has the sections ``grid`` (axes shared by the wound shapes), ``shapes``
(the shape-specific axes of each wound shape), ``sample`` (optional: a random design between
the axes' bounds instead of their product, `design.SampleDesign`), ``exclude`` (rules, as
expressions over the manifest's columns, that drop combinations), and the settings
``materials``, ``stages``, ``solver`` and ``analysis`` (typed records whose defaults are the
paper's values: `Materials`, `StageSettings`, `SolverSettings`, `ModelSettings`).

Lengths are in mm, moduli in kPa, penalties in GPa (converted where used).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any, NamedTuple

import yaml

from ..core.errors import SweepError
from ..core.fsutil import read_small_text
from . import strictyaml
from .analysis import ModelSettings
from .design import SampleDesign, check_sampled_axes, parse_sample
from .limits import check_settings
from .paper import CLOSURE_LOADS, Materials, StageSettings
from .rules import compile_rule
from .solver import DEGREES, SolverSettings

__all__ = [
    "DEFAULTS",
    "DERIVED",
    "GEOMETRY_KEYS",
    "GRID_AXES",
    "MANIFEST_COLUMNS",
    "MAX_JOBS",
    "MAX_RULES",
    "MAX_TEXT",
    "MAX_SWEEP_BYTES",
    "RULE_NAMES",
    "SHAPE_AXES",
    "Sweep",
    "is_number",
    "load_sweep",
    "parse_sweep",
    "parse_sweep_text",
    "read_sweep_text",
]

# A sweep file is a small text file; anything larger is refused before it is read whole.
MAX_SWEEP_BYTES = 1_000_000
# Grids above this many jobs (before exclusions) are refused before they are expanded.
MAX_JOBS = 1_000_000
# Exclusion rules and text fields are bounded, so that loading a sweep stays cheap.
MAX_RULES = 1000
MAX_TEXT = {"name": 200, "description": 10_000, "rule": 1000}

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
# Each wound shape's own axes: the cylinder's axis offset (a multiple of w), the depth as a
# fraction of T, the excision's length as a multiple of w.
SHAPE_AXES = {
    "cylindrical": ("wound_aspect_factor",),
    "wedge": ("wound_depth_factor",),
    "fusiform": ("wound_length_factor", "wound_depth_factor"),
}
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
    "wound_length_factor",
)
DERIVED = (
    "subcutis_thickness_mm",
    "total_thickness_mm",
    "patch_half_length_mm",
    "wound_width_mm",
    "wound_depth_mm",
    "wound_length_mm",
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
RULE_NAMES = frozenset(MANIFEST_COLUMNS) - {"job_index", "job_id", "geometry_id"}

# The settings sections in plain form with the defaults, against which a sweep file's
# sections are checked key by key.
DEFAULTS: dict[str, Any] = {
    "materials": Materials.table2().to_dict(),
    "stages": StageSettings().to_dict(),
    "solver": SolverSettings().to_dict(),
    "analysis": dataclasses.asdict(ModelSettings()),
}
SETTINGS = tuple(DEFAULTS)
TOP_KEYS = ("name", "description", "grid", "shapes", "sample", "exclude", *SETTINGS)


class Sweep(NamedTuple):
    """A validated sweep: grid axes and settings with defaults filled in; ``sample`` the
    random design (None: the grid's product)."""

    path: str
    name: str
    grid: dict[str, list[Any]]
    shapes: dict[str, dict[str, list[float]]]
    exclude: list[str]
    materials: Materials
    stages: StageSettings
    solver: SolverSettings
    analysis: ModelSettings
    sample: SampleDesign | None = None

    def settings_dict(self) -> dict[str, Any]:
        """The settings sections in plain form (as a sweep file writes them)."""
        return {
            "materials": self.materials.to_dict(),
            "stages": self.stages.to_dict(),
            "solver": self.solver.to_dict(),
            "analysis": dataclasses.asdict(self.analysis),
        }

    def resolved(self) -> dict[str, Any]:
        """Everything that determines the jobs and their results (not the file's formatting)."""
        d = self._asdict()
        d.pop("path")
        sample = d.pop("sample")
        if sample is not None:  # a grid sweep's record has no sample key
            d["sample"] = sample.to_dict()
        return {**d, **self.settings_dict()}


def is_number(v: Any) -> bool:
    """A finite int or float (not a bool; an integer too large for a float is not)."""
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
        if not is_number(v):
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
            out = copy.deepcopy(default)  # the built-in types stay; given ones add or override
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
        if key.endswith("closure_zone") and "depth_per_w" in given:
            # An optional key: the zone's depth as a multiple of the wound width.
            default = {**default, "depth_per_w": 1.0}
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
            raise SweepError(path, key, f"expected a name, got {given!r}")
        return given
    if isinstance(default, list):
        if not isinstance(given, list) or len(given) != len(default):
            raise SweepError(path, key, f"expected a list of {len(default)} numbers, got {given!r}")
        return [_merge(path, f"{key}[{i}]", d, g) for i, (d, g) in enumerate(zip(default, given))]
    if isinstance(default, bool):
        if not isinstance(given, bool):
            raise SweepError(path, key, f"expected true or false, got {given!r}")
        return given
    if not is_number(given):
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
    sample = parse_sample(path, data.get("sample"), MAX_JOBS)
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
        axes = SHAPE_AXES[shape]
        if not isinstance(spec, dict) or set(spec) != set(axes):
            keys = " and ".join(repr(a) for a in axes)
            raise SweepError(path, f"shapes.{shape}", f"expected exactly the key(s) {keys}")
        kind = "nonnegative" if shape == "cylindrical" else "positive"
        shapes[shape] = {a: _axis(path, f"shapes.{shape}.{a}", spec[a], kind=kind) for a in axes}
    if sample is not None:
        check_sampled_axes(path, grid, shapes, sample)
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
    for shape in ("wedge", "fusiform"):
        if shape in shapes and max(shapes[shape]["wound_depth_factor"]) >= 1:
            raise SweepError(
                path,
                f"shapes.{shape}.wound_depth_factor",
                "expected factors below 1 (the depth is a fraction of the total thickness)",
            )
    if "fusiform" in shapes and min(shapes["fusiform"]["wound_length_factor"]) <= 1:
        raise SweepError(
            path,
            "shapes.fusiform.wound_length_factor",
            "expected factors above 1 (the length is a multiple of the width), got "
            f"{min(shapes['fusiform']['wound_length_factor'])!r}",
        )

    exclude = data.get("exclude") or []
    if not isinstance(exclude, list) or not all(isinstance(r, str) for r in exclude):
        raise SweepError(path, "exclude", "expected a list of rule expressions (strings)")
    if len(exclude) > MAX_RULES:
        raise SweepError(path, "exclude", f"expected at most {MAX_RULES} rules, got {len(exclude)}")
    for i, rule in enumerate(exclude):
        if len(rule) > MAX_TEXT["rule"]:
            raise SweepError(path, f"exclude[{i}]", f"longer than {MAX_TEXT['rule']} characters")
        compile_rule(path, f"exclude[{i}]", rule, RULE_NAMES)
    for key in ("name", "description"):
        _text(path, key, data.get(key))

    settings = {k: _merge(path, k, DEFAULTS[k], data.get(k)) for k in SETTINGS}
    analysis = check_settings(path, settings)
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
    closure = settings["stages"]["closure_load"]
    if closure not in CLOSURE_LOADS:
        raise SweepError(
            path,
            "stages.closure_load",
            f"unknown closing load {closure!r} (expected one of {', '.join(CLOSURE_LOADS)})",
        )
    zone = settings["stages"]["closure_zone"]
    for k, v in zone.items():
        if k != "depth_per_w" and v > 1:
            raise SweepError(
                path, f"stages.closure_zone.{k}", f"expected a fraction in (0, 1], got {v!r}"
            )
    return Sweep(
        path=str(path),
        name=str(data.get("name") or Path(str(path)).stem),
        grid=grid,
        shapes=shapes,
        exclude=list(exclude),
        materials=Materials.from_dict(settings["materials"]),
        stages=StageSettings.from_dict(settings["stages"]),
        solver=SolverSettings.from_dict(settings["solver"]),
        analysis=analysis,
        sample=sample,
    )


def _text(path: str, key: str, value: Any) -> None:
    """``name`` and ``description``: absent, or a string of printable text within its bound
    (a name is one line: it labels reports and pages)."""
    if value is None:
        return
    if not isinstance(value, str):
        raise SweepError(path, key, f"expected a string, got {type(value).__name__}")
    if len(value) > MAX_TEXT[key]:
        raise SweepError(path, key, f"longer than {MAX_TEXT[key]} characters")
    allowed = "\t\n" if key == "description" else ""
    if any(not c.isprintable() and c not in allowed for c in value):
        raise SweepError(path, key, "expected printable text (a control character was found)")


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
        data = strictyaml.load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "YAML"
        problem = getattr(err, "problem", None) or "invalid YAML"
        if not isinstance(err, strictyaml.Refused):
            problem = f"YAML syntax error: {problem}"
        raise SweepError(p, where, problem) from None
    except RecursionError:
        raise SweepError(p, "YAML", "nested too deeply") from None
    return parse_sweep(data, str(p))

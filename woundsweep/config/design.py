"""Random designs: a sweep's optional ``sample`` section.

With ``sample``, each numeric axis of ``grid`` and ``shapes`` is one value (fixed) or a
``[low, high]`` range, and the manifest holds ``geometries`` wounds per shape drawn between
the bounds (log-uniformly for the ``log_axes``) instead of the axes' Cartesian product. The
draws come from ``np.random.default_rng(seed)`` (PCG64) and are rounded to 4 significant
digits, so a seed gives one manifest. `parse_sample` reads the section, `check_sampled_axes`
the axes it constrains, `draw_sample` the jobs (lengths in mm, angles in degrees).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..core.errors import SweepError

if TYPE_CHECKING:
    from .sweep import Sweep

__all__ = [
    "MAX_CANDIDATES",
    "MAX_SEED",
    "SAMPLE_KEYS",
    "SampleDesign",
    "check_sampled_axes",
    "draw_sample",
    "parse_sample",
    "round_sig",
    "sampled_jobs",
]

SAMPLE_KEYS = ("geometries", "seed", "log_axes")
# The seed's range (that of the analysis seed).
MAX_SEED = 2**32 - 1
# Candidates drawn per kept geometry before the exclusion rules are said to reject every draw.
MAX_CANDIDATES = 100
# Significant digits of every drawn value.
DIGITS = 4
# The axis drawn per job (every other numeric axis is drawn per geometry), and the axes of
# names (a list of jobs per geometry, never drawn).
_PER_JOB = "orientation_deg"
_NAMES = ("skin_type",)


@dataclasses.dataclass(frozen=True)
class SampleDesign:
    """``geometries`` random geometries per wound shape from ``seed``; ``log_axes`` drawn
    log-uniformly."""

    geometries: int
    seed: int
    log_axes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The section as a sweep file writes it."""
        return {"geometries": self.geometries, "seed": self.seed, "log_axes": list(self.log_axes)}


def _integer(path: str, key: str, value: Any, low: int, high: int) -> int:
    integral = isinstance(value, int) or (
        isinstance(value, float) and math.isfinite(value) and value.is_integer()
    )
    if isinstance(value, bool) or not integral:
        raise SweepError(path, key, f"expected an integer, got {value!r}")
    if not low <= value <= high:
        raise SweepError(path, key, f"expected an integer from {low} to {high}, got {value!r}")
    return int(value)


def parse_sample(path: str, data: Any, max_geometries: int) -> SampleDesign | None:
    """The ``sample`` section (None when absent); SweepError names the key."""
    if data is None:
        return None
    if not isinstance(data, dict):
        raise SweepError(path, "sample", f"expected a mapping, got {type(data).__name__}")
    for k in data:
        if k not in SAMPLE_KEYS:
            raise SweepError(
                path, f"sample.{k}", f"unknown key (expected one of {list(SAMPLE_KEYS)})"
            )
    for k in ("geometries", "seed"):
        if k not in data:
            raise SweepError(path, f"sample.{k}", "missing key")
    geometries = _integer(path, "sample.geometries", data["geometries"], 1, max_geometries)
    seed = _integer(path, "sample.seed", data["seed"], 0, MAX_SEED)
    log_axes = data.get("log_axes") or []
    if not isinstance(log_axes, list) or not all(isinstance(a, str) for a in log_axes):
        raise SweepError(
            path, "sample.log_axes", f"expected a list of axis names, got {log_axes!r}"
        )
    if len(set(log_axes)) != len(log_axes):
        raise SweepError(path, "sample.log_axes", f"duplicate names in {log_axes!r}")
    return SampleDesign(geometries, seed, tuple(log_axes))


def _numeric_axes(
    grid: Mapping[str, list[Any]], shapes: Mapping[str, Mapping[str, list[float]]]
) -> dict[str, list[float]]:
    """Every numeric axis by its key path (``grid.X``, ``shapes.S.X``)."""
    out = {f"grid.{k}": v for k, v in grid.items() if k not in _NAMES}
    for shape, axes in shapes.items():
        out.update({f"shapes.{shape}.{k}": v for k, v in axes.items()})
    return out


def check_sampled_axes(
    path: str,
    grid: Mapping[str, list[Any]],
    shapes: Mapping[str, Mapping[str, list[float]]],
    design: SampleDesign,
) -> None:
    """Each numeric axis one value or a ``[low, high]`` range with low < high; each log axis
    a range with positive bounds wherever it occurs."""
    axes = _numeric_axes(grid, shapes)
    for key, values in axes.items():
        if len(values) > 2:
            raise SweepError(
                path,
                key,
                "a sampled sweep's axis is one value or a [low, high] range, got "
                f"{len(values)} values",
            )
        if len(values) == 2 and not values[0] < values[1]:
            raise SweepError(
                path, key, f"expected a [low, high] range with low < high, got {values!r}"
            )
    for name in design.log_axes:
        found = {k: v for k, v in axes.items() if k.rsplit(".", 1)[1] == name}
        if not found:
            raise SweepError(
                path,
                "sample.log_axes",
                f"unknown axis {name!r} (expected a numeric axis of grid or shapes)",
            )
        for key, values in found.items():
            if len(values) != 2:
                raise SweepError(
                    path, key, "a log axis (sample.log_axes) must be a [low, high] range"
                )
            if values[0] <= 0:
                raise SweepError(
                    path,
                    key,
                    f"a log axis (sample.log_axes) needs positive bounds, got {values!r}",
                )


def sampled_jobs(sweep: Sweep) -> int:
    """The jobs of a sampled sweep: shapes x geometries x skin types."""
    assert sweep.sample is not None
    return len(sweep.shapes) * sweep.sample.geometries * len(sweep.grid["skin_type"])


def round_sig(values: np.ndarray) -> np.ndarray:
    """Each value rounded to `DIGITS` significant digits (as ``float(f"{v:.4g}")``)."""
    return np.array([float(f"{v:.{DIGITS}g}") for v in values.tolist()], dtype=float)


def _draw(u: np.ndarray, bounds: Sequence[float], log: bool) -> np.ndarray:
    """Uniform (or log-uniform) values in ``bounds`` from uniform ``u`` in [0, 1), rounded
    and kept within the bounds."""
    low, high = bounds
    if log:
        v = np.exp(math.log(low) + u * (math.log(high) - math.log(low)))
    else:
        v = low + u * (high - low)
    return np.clip(round_sig(v), low, high)


def _candidates(
    rng: np.random.Generator,
    block: int,
    axes: Mapping[str, list[float]],
    skins: list[str],
    per_job: list[float],
    log_axes: tuple[str, ...],
) -> pd.DataFrame:
    """The jobs of ``block`` candidate geometries: each candidate's draws consecutive in the
    stream (its geometry's range axes in order, then its jobs' orientations)."""
    n = len(skins)
    ranged = [k for k, v in axes.items() if len(v) == 2]
    u = rng.random((block, len(ranged) + (n if len(per_job) == 2 else 0)))
    cols: dict[str, Any] = {}
    for k, v in axes.items():
        if k in ranged:
            cols[k] = np.repeat(_draw(u[:, ranged.index(k)], v, k in log_axes), n)
        else:
            cols[k] = np.full(block * n, v[0])
    cols["skin_type"] = np.tile(np.array(skins, dtype=object), block)
    if len(per_job) == 2:
        cols[_PER_JOB] = _draw(u[:, len(ranged) :].ravel(), per_job, _PER_JOB in log_axes)
    else:
        cols[_PER_JOB] = np.full(block * n, per_job[0])
    return pd.DataFrame(cols)


def draw_sample(
    sweep: Sweep,
    frame: Callable[[pd.DataFrame], pd.DataFrame],
    excluded: Callable[[pd.DataFrame], np.ndarray],
) -> pd.DataFrame:
    """The jobs of a sampled sweep, geometry-major: shapes sorted, geometries in draw order,
    a geometry's jobs consecutive in the sweep's skin-type order.

    ``frame`` completes the parameter columns into manifest columns (derived lengths);
    ``excluded`` marks the jobs the exclusion rules drop. A candidate geometry is kept when
    none of its jobs is excluded or already drawn; candidates are drawn in blocks of
    ``geometries`` until ``geometries`` are kept, and the sweep is refused after
    `MAX_CANDIDATES` x ``geometries`` candidates.
    """
    design = sweep.sample
    assert design is not None
    rng = np.random.default_rng(design.seed)
    skins = list(sweep.grid["skin_type"])
    n = len(skins)
    parts = []
    for shape in sorted(sweep.shapes):
        axes = {k: v for k, v in sweep.grid.items() if k not in (*_NAMES, _PER_JOB)}
        axes.update(sweep.shapes[shape])
        names = [*axes, "skin_type", _PER_JOB]
        need, drawn = design.geometries, 0
        seen: set[tuple[Any, ...]] = set()
        while need > 0:
            if drawn >= MAX_CANDIDATES * design.geometries:
                raise SweepError(
                    sweep.path,
                    "sample",
                    f"the exclusion rules reject nearly every draw: {design.geometries - need} "
                    f"of {design.geometries} {shape} geometries kept after {drawn} candidates",
                )
            block = design.geometries
            drawn += block
            params = _candidates(rng, block, axes, skins, sweep.grid[_PER_JOB], design.log_axes)
            df = frame(params.assign(wound_shape=shape))
            bad = np.asarray(excluded(df), dtype=bool).reshape(block, n).any(axis=1)
            jobs = list(zip(*(df[k].tolist() for k in names)))
            take = []
            for i in np.flatnonzero(~bad).tolist():
                mine = jobs[i * n : (i + 1) * n]
                if seen.intersection(mine):  # a draw that repeats a kept job
                    continue
                seen.update(mine)
                take.append(i)
                if len(take) == need:
                    break
            need -= len(take)
            rows = np.repeat(np.array(take, dtype=int) * n, n) + np.tile(np.arange(n), len(take))
            parts.append(df.iloc[rows])
    return pd.concat(parts, ignore_index=True)

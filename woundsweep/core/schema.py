"""The definitions the layers share: mesh tags and `MeshData`, stages, statuses, exit codes,
result fields.

Every other module imports these from here (docs/design.md, "Contracts"). Pure Python: no
DOLFINx, no Arrow (numpy only in annotations), so the command line, the store and the solver
can all use it.
"""

from __future__ import annotations

import enum
import re
import typing
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple

from .errors import WoundsweepError

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "PROFILE_LINES",
    "PROFILE_POINTS",
    "BOTTOM",
    "CELL_TAGS",
    "DERMIS",
    "FACET_TAGS",
    "STAGES",
    "STAGE_NAMES",
    "SUBCUTIS",
    "TAGS",
    "TOP",
    "UNITS",
    "WOUND",
    "WOUND_TAGS",
    "WOUND_ZONE",
    "X_MAX",
    "X_MIN",
    "Y_MAX",
    "Y_MIN",
    "ExitCode",
    "FailureClass",
    "MeshData",
    "ResultState",
    "StageResult",
    "StageStatus",
    "parse_stage_range",
    "stage_field_kinds",
    "start_stage",
]


UNITS = "mm, kPa, mN, s"

# The profile lines of the solver file (`woundsweep.physics.profiles`), each of
# `PROFILE_POINTS` points.
PROFILE_LINES = ("along_wound", "through_thickness", "across_patch")
PROFILE_POINTS = 100

# Cell and facet tags of the mesh contract (integers are part of it).
DERMIS, SUBCUTIS = 1, 2
X_MIN, X_MAX, Y_MIN, Y_MAX, BOTTOM, TOP, WOUND = 11, 12, 13, 14, 15, 16, 17
# The wound surface is WOUND (outside the closure zone) plus WOUND_ZONE (the closure zone).
WOUND_ZONE = 18
WOUND_TAGS = (WOUND, WOUND_ZONE)
CELL_TAGS = MappingProxyType({"dermis": DERMIS, "subcutis": SUBCUTIS})
FACET_TAGS = MappingProxyType(
    {
        "x_min": X_MIN,
        "x_max": X_MAX,
        "y_min": Y_MIN,
        "y_max": Y_MAX,
        "bottom": BOTTOM,
        "top": TOP,
        "wound": WOUND,
        "wound_zone": WOUND_ZONE,
    }
)
TAGS = MappingProxyType({**CELL_TAGS, **FACET_TAGS})


class MeshData(NamedTuple):
    """A first-order tetrahedral mesh: arrays in mm, tags as in ``CELL_TAGS``/``FACET_TAGS``.

    ``info`` of a built mesh records, among others, the ``element_degree`` its edges were
    sized for and its ``closure_zone`` (`woundsweep.mesh.build`)."""

    points: np.ndarray  # (n, 3) float64, every node used by a cell, no duplicates
    cells: np.ndarray  # (m, 4) int64, positively oriented
    cell_tags: np.ndarray  # (m,) int32
    facets: np.ndarray  # (k, 3) int64, each exterior triangle once
    facet_tags: np.ndarray  # (k,) int32
    info: dict[str, Any]


STAGES = (1, 2, 3, 4, 5, 6)
# Where stage 4 starts, per closing load (`woundsweep.config.paper.CLOSURE_LOADS`;
# docs/model.md, "The six stages"): the reactions' from stage 2's Dirichlet-closed state and
# the published code's from stage 1, so a stage 3 that does not converge does not stop
# stages 4-6; the solved closure's from stage 3, whose amplitude it holds.
_RESTARTS = MappingProxyType({"reactions": {4: 2}, "paper-code": {4: 1}, "solved": {}})


def start_stage(stage: int, closure_load: str = "reactions") -> int:
    """The stage whose converged state ``stage`` starts from (0 for stage 1)."""
    return _RESTARTS[closure_load].get(stage, stage - 1)


STAGE_NAMES = MappingProxyType(
    {
        1: "pre-tension (Dirichlet lateral)",
        2: "lateral traction + Dirichlet closure",
        3: "lateral traction + closure traction",
        4: "contact k_V = 1 GPa",
        5: "contact k_V = 5 GPa",
        6: "contact k_V = 100 GPa",
    }
)


class _Text(str, enum.Enum):
    """A string enum that prints, formats and serialises as its value."""

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)


class StageStatus(_Text):
    """How a stage ended (the ``status`` column)."""

    CONVERGED = "converged"
    MAX_ITERATIONS = "max-iterations"
    DIVERGED = "diverged"
    INVERTED = "inverted"
    LINEAR_SOLVER_FAILED = "linear-solver-failed"
    NOT_RUN = "not-run"


class ResultState(_Text):
    """What a job's stored result is for the current sweep (`woundsweep.store.reader`)."""

    MISSING = "missing"  # no result file
    DONE = "done"  # valid, of the current fingerprint, with its files intact
    STALE = "stale"  # another result format, fingerprint or stage range
    CORRUPT = "corrupt"  # the result file fails validation
    DAMAGED = "damaged"  # its fields or mesh file is missing or altered


class FailureClass(_Text):
    """How a job ended (the ``failure_class`` column)."""

    CONVERGED = "converged"
    NOT_CONVERGED = "not-converged"
    TIMEOUT = "timeout"
    OUT_OF_MEMORY = "out-of-memory"
    CRASHED = "crashed"
    MESH_FAILED = "mesh-failed"
    INVALID = "invalid"


class ExitCode(enum.IntEnum):
    """Exit status of ``woundsweep solve`` (and of the CLI for invalid input)."""

    OK = 0
    INVALID = 2
    NOT_CONVERGED = 3
    MESH_FAILED = 4
    SWEEP_CHANGED = 5  # a runner's job: the run's sweep differs from the one the runner stamps


class StageResult(NamedTuple):
    """Per-stage scalars (docs/design.md); None where a quantity does not apply."""

    stage: int
    status: str
    newton_iterations: int | None = None
    time_s: float | None = None
    p99_von_mises_kPa: float | None = None
    p99_von_mises_nodal_kPa: float | None = None
    p99_von_mises_wound_kPa: float | None = None
    max_von_mises_kPa: float | None = None
    max_location_x_mm: float | None = None
    max_location_y_mm: float | None = None
    max_location_z_mm: float | None = None
    # The closure along the wound (docs/model.md, "Closure measures"): the gap between mirror
    # pairs of zone points at the skin surface, and the largest overlap over the zone.
    closure_gap_min_mm: float | None = None
    closure_gap_median_mm: float | None = None
    closure_gap_max_mm: float | None = None
    closure_gap_median_per_w: float | None = None  # fraction of the wound width
    closure_gap_max_per_w: float | None = None
    closure_overlap_mm: float | None = None
    # Stages 2-6: 1 if the sutured zone is closed at the surface, 0 if it has reopened.
    closed: int | None = None
    # Stages 2-6: 1 if the flanks pass through each other: mirrored zone points overlap, or the
    # audit (`contact.audit`) finds flank nodes inside the other side's deformed tissue.
    interpenetrating: int | None = None
    min_J: float | None = None
    n_penetrating: int | None = None  # contact stages (4-6) only
    max_penetration_mm: float | None = None  # contact stages only
    contact_force_mN: float | None = None  # contact stages only
    residual_norm: float | None = None
    dofs: int | None = None
    cells: int | None = None
    # The job's displacement element (1: P1, 2: P2), from its solver settings.
    element_degree: int | None = None


def stage_field_kinds() -> dict[str, type]:
    """`StageResult` fields after ``stage`` and ``status`` and their kind (int or float)."""
    hints = typing.get_type_hints(StageResult)
    return {
        name: int if int in typing.get_args(hints[name]) else float
        for name in StageResult._fields[2:]
    }


def parse_stage_range(text: str, error: type[WoundsweepError] = WoundsweepError) -> tuple[int, int]:
    """``"A-B"`` or ``"A"`` with 1 <= A <= B <= 6 -> (A, B); raise ``error`` with one line."""
    m = re.fullmatch(r"\s*([1-6])\s*(?:-\s*([1-6])\s*)?", str(text))
    if not m or int(m.group(2) or m.group(1)) < int(m.group(1)):
        raise error(f"--stages {text!r}: expected A-B with 1 <= A <= B <= 6, e.g. 1-3")
    return int(m.group(1)), int(m.group(2) or m.group(1))

"""A stage's report: its `StageResult` and its diagnostics, carried from the solver (the
solver file's ``stage_results``) to the store (one typed column per known diagnostic) and the
analysis.

Diagnostics are what a stage measures beside its result (docs/design.md, "Solver output");
a key is present where the stage measures it, with null where the value is not a finite
number. `StageDiagnostics` is the list of known diagnostics, each name carrying its unit; the
store has one column per name (`DIAGNOSTIC_KINDS`: int for counts, float for the rest), null
where a stage has none, and refuses a diagnostic it has no column for.
"""

from __future__ import annotations

import math
import typing
from collections.abc import Mapping
from typing import Any, NamedTuple, TypedDict

from .schema import StageResult, StageStatus

__all__ = [
    "DIAGNOSTIC_KEYS",
    "DIAGNOSTIC_KINDS",
    "StageDiagnostics",
    "StageReport",
    "diagnostic_columns",
]


class StageDiagnostics(TypedDict, total=False):
    """The diagnostics a stage may report (units in the names; counts are ints)."""

    load_increments: int
    load_cuts: int
    load_reached: float
    assembly_time_s: float
    factor_time_s: float
    pin_reaction_max_mN: float | None  # stages 2-6
    closure_force_left_mN: float | None  # stage 2
    closure_force_right_mN: float | None
    lateral_force_mN: float | None
    closure_traction_kPa: float | None  # stage 3: mean closing load per deformed zone area
    closing_traction_kPa: float | None  # stages 3-6 of the traction closures: the amplitude
    closing_amplitude_solves: int | None  # stages 3-6 of the solved closure
    max_penetration_rel: float | None  # stages 4-6
    contact_penalty_kPa: float | None
    contact_detect_time_s: float | None
    contact_assembly_time_s: float | None
    contact_searches: int | None
    contact_fade_points: int | None  # engaged points in the support's fade (0 < weight < 1)
    contact_fade_force_share: float | None  # their share of the contact force
    audit_inside_nodes: int | None  # stages 2-6: flank nodes inside the other side's tissue
    audit_max_depth_mm: float | None  # the deepest such node's depth below the other flank
    tie_force_mN: float | None
    tie_max_slip_mm: float | None
    stability_min_eig_mN_per_mm: float | None  # a contact stage that did not converge
    stability_penalty_kPa: float | None
    profile_along_wound_max_kPa: float | None  # converged stages: the profile lines' maxima
    profile_along_wound_max_at_mm: float | None
    profile_through_thickness_max_kPa: float | None
    profile_through_thickness_max_at_mm: float | None
    profile_across_patch_max_kPa: float | None
    profile_across_patch_max_at_mm: float | None
    closing_line_load_max_mN_per_mm: float | None  # converged wounded stages: line loads
    closing_line_load_max_at_mm: float | None  # y of the maximum along the wound
    contact_line_load_max_mN_per_mm: float | None
    contact_line_load_max_at_mm: float | None


def _kind(hint: Any) -> type:
    return int if hint is int or int in typing.get_args(hint) else float


# The known diagnostics in declaration order and their kind (int or float): the store's
# diagnostic columns.
DIAGNOSTIC_KINDS: dict[str, type] = {
    name: _kind(hint) for name, hint in typing.get_type_hints(StageDiagnostics).items()
}
DIAGNOSTIC_KEYS = frozenset(DIAGNOSTIC_KINDS)


def _number(v: Any) -> Any:
    """None for a value that is not a finite number (NaN read from a file), else the value."""
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v


class StageReport(NamedTuple):
    """One stage's result and diagnostics."""

    result: StageResult
    diagnostics: StageDiagnostics

    @property
    def status(self) -> str:
        return self.result.status

    def to_row(self) -> dict[str, Any]:
        """The flat record of the solver file: the result's fields, then the diagnostics."""
        return {**self.result._asdict(), **self.diagnostics}

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> StageReport:
        """Split a flat record; ValueError for a missing stage or an unknown status."""
        if row.get("status") not in {s.value for s in StageStatus}:
            raise ValueError(f"unknown status {row.get('status')!r}")
        fields = StageResult._fields
        result = StageResult(
            int(row["stage"]),
            str(row["status"]),
            *(_number(row.get(name)) for name in fields[2:]),
        )
        extra = {k: v for k, v in row.items() if k not in fields}
        return cls(result, extra)  # type: ignore[arg-type]

    def diagnostic_columns(self) -> dict[str, int | float | None]:
        """The store's diagnostic columns of this stage (`diagnostic_columns`)."""
        return diagnostic_columns(self.diagnostics)


def diagnostic_columns(diagnostics: Mapping[str, Any]) -> dict[str, int | float | None]:
    """Every known diagnostic (`DIAGNOSTIC_KINDS` order) with its value as its kind, None
    where ``diagnostics`` has none; ValueError for a name the store has no column for."""
    unknown = sorted(set(diagnostics) - DIAGNOSTIC_KEYS)
    if unknown:
        raise ValueError(
            f"diagnostics {unknown} have no store column (add them to core.diagnostics)"
        )
    out: dict[str, int | float | None] = {}
    for name, kind in DIAGNOSTIC_KINDS.items():
        v = diagnostics.get(name)
        x = None if v is None else float(v)
        if x is None or not math.isfinite(x):
            out[name] = None
        elif kind is float:
            out[name] = x
        elif x != int(x):
            raise ValueError(f"diagnostic {name} = {v!r} is not a count")
        else:
            out[name] = int(v) if isinstance(v, int) else int(x)
    return out

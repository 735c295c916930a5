"""A stage's report: its `StageResult` and its diagnostics, with the one encoding that carries
them from the solver (the solver file's ``stage_results``) to the store (the result rows'
fields and ``stage_extra_json``) and the analysis.

Diagnostics are what a stage measures beside its result (docs/design.md, "Solver output");
a key is present where the stage measures it, with null where the value is not a finite
number. Keys a reader does not know are kept as they are.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, NamedTuple, TypedDict

from .schema import StageResult, StageStatus

__all__ = ["DIAGNOSTIC_KEYS", "StageDiagnostics", "StageReport", "parse_diagnostics"]


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
    max_penetration_rel: float | None  # stages 4-6
    contact_penalty_kPa: float | None
    contact_detect_time_s: float | None
    contact_assembly_time_s: float | None
    contact_searches: int | None
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


DIAGNOSTIC_KEYS = frozenset(StageDiagnostics.__annotations__)


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

    def diagnostics_json(self) -> str | None:
        """The store's ``stage_extra_json``: sorted keys, or None without diagnostics."""
        return json.dumps(self.diagnostics, sort_keys=True) if self.diagnostics else None


def parse_diagnostics(text: str | None) -> StageDiagnostics:
    """The diagnostics of a stored ``stage_extra_json`` (empty for None or '')."""
    return json.loads(text) if isinstance(text, str) and text else StageDiagnostics()

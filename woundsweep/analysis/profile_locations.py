"""Where each profile line's maximum sits (the paper's Figure 2 as it was computed).

The solver stores per converged stage, in the row's ``profile_<line>_max_at_mm`` column, the
running coordinate (mm) of each line's maximum (`woundsweep.physics.profiles`).
Positions are normalised as the global maximum's (`paper.normalised_locations`): along the
wound (y + L) / 2L, through the thickness -z / T, across the patch (x - w/2) / (L + w/2).
Each line holds `PROFILE_POINTS` samples; a bin holds `POINTS_PER_BIN` neighbouring samples,
its edges halfway between samples, so that every bin counts the same number of positions.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..core.schema import PROFILE_LINES, PROFILE_POINTS
from .paper import along_half_length
from .settings import STAGE_GROUPS

__all__ = [
    "POINTS_PER_BIN",
    "PROFILE_NORMALISATION",
    "bin_edges",
    "profile_counts",
    "profile_positions",
    "profile_summary",
    "report_lines",
]

POINTS_PER_BIN = 4
N_BINS = PROFILE_POINTS // POINTS_PER_BIN
PROFILE_NORMALISATION = {
    "along_wound": "(y + L) / 2L (L + l/2 in place of L for the excision), x = 0, z = 0; "
    "closure zone ends at 1/3 and 2/3",
    "through_thickness": "-z / T, x = 0, y = 0; 0 = skin surface, 1 = bottom face",
    "across_patch": "(x - w/2) / (L + w/2), y = 0, z = 0; 0 = wound mid-plane",
}
# A sample's fraction t in [0, 1] along its line -> the figure's coordinate: u = a + b t.
_AFFINE = {"along_wound": (0.0, 1.0), "through_thickness": (1.0, -1.0), "across_patch": (-1.0, 2.0)}


def _fraction(line: str, at_mm: np.ndarray, rows: pd.DataFrame) -> np.ndarray:
    """The fraction t of each position along its line (`woundsweep.physics.profiles.profile_lines`)."""
    L = rows["patch_half_length_mm"].to_numpy(dtype=float)
    w = rows["wound_width_mm"].to_numpy(dtype=float)
    T = rows["total_thickness_mm"].to_numpy(dtype=float)
    if line == "along_wound":
        Ly = along_half_length(rows)
        return (at_mm + Ly) / (2 * Ly)
    if line == "through_thickness":
        return (at_mm + T) / T
    return (at_mm + L) / (2 * L + w)


def profile_positions(rows: pd.DataFrame) -> pd.DataFrame:
    """Per row its stage group and, per line, the sample index (0..99) of the line's maximum.

    Columns ``stage_group``, ``closure_load`` (``reactions`` where the store has no such
    column) and ``<line>_index`` (float, NaN where the row stores no position for that line:
    a stage that did not converge, or a line that missed the mesh).
    """
    stage = rows["stage"].to_numpy()
    group = np.full(len(rows), "", dtype=object)
    for name, stages in STAGE_GROUPS:
        group[np.isin(stage, stages)] = name
    out = pd.DataFrame({"stage_group": group})
    # How the stages 3-6 closed the wound (a store without the column: the reactions).
    load = rows["closure_load"] if "closure_load" in rows else pd.Series("reactions", rows.index)
    out["closure_load"] = load.fillna("reactions").astype(str).to_numpy()
    for line in PROFILE_LINES:
        at = rows[f"profile_{line}_max_at_mm"].to_numpy(dtype=float)
        out[f"{line}_index"] = _fraction(line, at, rows) * (PROFILE_POINTS - 1)
    return out


def bin_edges(line: str) -> np.ndarray:
    """The ``N_BINS + 1`` bin edges of ``line`` in the figure's coordinate, ascending."""
    idx = np.arange(N_BINS + 1) * POINTS_PER_BIN - 0.5
    a, b = _AFFINE[line]
    return np.sort(a + b * idx / (PROFILE_POINTS - 1))


def profile_counts(index: np.ndarray, line: str) -> tuple[np.ndarray, int]:
    """Counts per bin (in `bin_edges` order) of the finite sample indices; and how many lay
    more than half a sample outside the line (clipped into the end bins)."""
    i = np.asarray(index, dtype=float)
    i = i[np.isfinite(i)]
    outside = int(np.sum((i < -0.5) | (i > PROFILE_POINTS - 0.5)))
    k = np.clip(np.rint(i), 0, PROFILE_POINTS - 1).astype(np.int64) // POINTS_PER_BIN
    counts = np.bincount(k, minlength=N_BINS)
    # Through the thickness the coordinate runs opposite to the samples: ascending edges.
    return (counts[::-1] if _AFFINE[line][1] < 0 else counts), outside


def profile_summary(pos: pd.DataFrame) -> dict[str, Any]:
    """The ``max_location_profiles`` entry of metrics.json: per stage group and line the rows
    with a position, those without, the counts per bin and the positions outside the line."""
    groups: dict[str, Any] = {}
    for name, _ in STAGE_GROUPS:
        sel = pos[pos["stage_group"] == name]
        lines = {}
        for line in PROFILE_LINES:
            col = sel[f"{line}_index"].to_numpy(dtype=float)
            counts, outside = profile_counts(col, line)
            lines[line] = {
                "rows": int(np.isfinite(col).sum()),
                "rows_without_position": int((~np.isfinite(col)).sum()),
                "outside_line": outside,
                "counts": counts.tolist(),
            }
        groups[name] = {"rows": int(len(sel)), "lines": lines}
    return {
        "source": "profile_<line>_max_at_mm columns",
        "normalisation": dict(PROFILE_NORMALISATION),
        "points_per_line": PROFILE_POINTS,
        "points_per_bin": POINTS_PER_BIN,
        "bin_edges": {line: bin_edges(line).tolist() for line in PROFILE_LINES},
        "groups": groups,
    }


def report_lines(metrics: dict[str, Any]) -> list[str]:
    """The report's section on the two Figure 2 variants, with n per stage group."""
    glob = metrics.get("max_location", {}).get("rows", {})
    prof = metrics["max_location_profiles"]["groups"]

    def per_line(g: dict[str, Any]) -> str:
        return " / ".join(str(g["lines"][line]["rows"]) for line in PROFILE_LINES)

    lines = [
        "",
        "## Where the maximum sits (Figure 2)",
        "",
        "`max_location.png`: the cell of the largest von Mises in the whole patch. "
        "`max_location_profiles.png`: the paper's method, the position of the maximum on each of "
        f"three lines of {PROFILE_POINTS} points (along the wound, through the thickness, across "
        "the patch), read from the stored line maxima.",
        "",
        "| stage group | rows (global maximum) | rows with a line position (along / through / "
        "across) | rows without |",
        "|---|---|---|---|",
    ]
    for name, _ in STAGE_GROUPS:
        g = prof[name]
        without = max(g["lines"][line]["rows_without_position"] for line in PROFILE_LINES)
        lines.append(f"| {name} | {glob.get(name, 'n/a')} | {per_line(g)} | {without} |")
    outside = sum(g["lines"][ln]["outside_line"] for g in prof.values() for ln in PROFILE_LINES)
    if outside:
        lines += ["", f"{outside} line positions lay outside their line (clipped to its ends)."]
    return lines

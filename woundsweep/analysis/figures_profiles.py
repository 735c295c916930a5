"""Figure 2 from the profile lines: where each line's maximum sits, per stage group.

Top row: the three lines drawn in a schematic patch (top view for the lines at the surface,
a section for the one through the thickness). Below, one row per `STAGE_GROUPS` entry: the
histogram of the position of each line's maximum (`profile_locations`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from ..core.schema import PROFILE_LINES  # noqa: E402
from .profile_locations import bin_edges, profile_counts  # noqa: E402
from .settings import STAGE_GROUPS  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["profile_max_locations"]

_TITLES = {
    "along_wound": ("along the wound (x = 0, z = 0)", "(y + L) / 2L"),
    "through_thickness": ("through the thickness (x = 0, y = 0)", "-z / T (0 = surface)"),
    "across_patch": ("across the patch (y = 0, z = 0)", "(x - w/2) / (L + w/2)"),
}
# Proportions of the schematic patch only (L, w, T in arbitrary units).
_L, _W, _T = 1.0, 0.5, 0.6


def _schematic(ax: Axes, line: str) -> None:
    """The patch in top view (x, y) or section (x, z) with the wound and the line in red."""
    section = line == "through_thickness"
    h = (-_T, 0.0) if section else (-_L, _L)
    ax.add_patch(Rectangle((-_L, h[0]), 2 * _L + _W, h[1] - h[0], fc="0.93", ec="0.4", lw=0.8))
    if section:
        # A wedge wound in section: open at the surface, its tip at half the depth.
        ax.fill([0, _W, _W / 2], [0, 0, -_T / 2], color="white", ec="0.4", lw=0.8)
        ax.plot([0, 0], [-_T, 0], color="tab:red", lw=2.5)
    else:
        ax.add_patch(Rectangle((0, -_L), _W, 2 * _L, fc="white", ec="0.4", lw=0.8))
        ax.plot([0, _W], [_L / 3] * 2, color="0.4", ls="--", lw=0.8)
        ax.plot([0, _W], [-_L / 3] * 2, color="0.4", ls="--", lw=0.8)
        if line == "along_wound":
            ax.plot([0, 0], [-_L, _L], color="tab:red", lw=2.5)
        else:
            ax.plot([-_L, 0], [0, 0], color="tab:red", lw=2.5)
            ax.plot([_W, _L + _W], [0, 0], color="tab:red", lw=2.5)
            ax.plot([0, _W], [0, 0], color="tab:red", lw=1, ls=":")
    ax.set_xlim(-_L - 0.1, _L + _W + 0.1)
    ax.set_ylim(h[0] - 0.1, h[1] + 0.1)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(_TITLES[line][0] + ("\nsection y = 0" if section else "\ntop view"), fontsize=9)


def profile_max_locations(
    pos: pd.DataFrame, zone_ends: tuple[float, float] | None = (1 / 3, 2 / 3)
) -> Figure:
    """Figure 2 (profile lines): histograms of the position of each line's maximum, with the
    closure zone's ends dashed along the wound (``None``: no common ends, as for excisions,
    whose zone and patch scale with each one's length). A run with more than one
    ``closure_load`` (how stages 3-6 closed the wound) shows each one's bars side by side."""
    loads = sorted(set(pos["closure_load"])) if "closure_load" in pos else ["reactions"]
    loads = loads or ["reactions"]
    fig = Figure(figsize=(10, 9), layout="constrained")
    axes = fig.subplots(
        len(STAGE_GROUPS) + 1, 3, squeeze=False, height_ratios=[0.8] + [1] * len(STAGE_GROUPS)
    )
    for j, line in enumerate(PROFILE_LINES):
        _schematic(axes[0, j], line)
        edges = bin_edges(line)
        for i, (group, _) in enumerate(STAGE_GROUPS, start=1):
            ax = axes[i, j]
            sel = pos[pos["stage_group"] == group]
            width = np.diff(edges) / len(loads)
            for n, load in enumerate(loads):  # side by side when a run has several
                part = sel[sel["closure_load"] == load] if len(loads) > 1 else sel
                counts, _out = profile_counts(part[f"{line}_index"].to_numpy(dtype=float), line)
                colour = f"C{n}" if len(loads) > 1 else ("tab:red" if i == 2 else "tab:blue")
                ax.bar(edges[:-1] + n * width, counts, width, align="edge", color=colour,
                       label=f"closure load: {load}")  # fmt: skip
            if len(loads) > 1 and i == 1 and j == 0:
                ax.legend(fontsize=7)
            ax.set_xlim(edges[0], edges[-1])
            if line == "along_wound" and zone_ends is not None:
                for v in zone_ends:
                    ax.axvline(v, color="grey", lw=0.8, ls="--")
            if i == len(STAGE_GROUPS):
                ax.set_xlabel(_TITLES[line][1])
            if j == 0:
                ax.set_ylabel(f"{group}\n(n={len(sel)})")
            missing = int(sel[f"{line}_index"].isna().sum())
            if missing:
                ax.text(0.98, 0.95, f"{missing} rows without a position", ha="right", va="top",
                        transform=ax.transAxes, fontsize=7)  # fmt: skip
    dashed = "; dashed: ends of the closure zone" if zone_ends is not None else ""
    fig.suptitle(
        f"Location of the maximal von Mises stress on each profile line (100 points{dashed})"
    )
    return fig

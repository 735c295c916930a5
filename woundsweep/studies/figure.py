"""The figure of a convergence study (`woundsweep.studies.convergence`): each quantity
against the relative element size, with the extrapolated limits at size 0."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..core.fsutil import atomic_write

__all__ = ["draw_study"]


def draw_study(study: dict[str, Any], path: Path) -> Path:
    """Each quantity against the relative element size, one line per stage; at size 0 the
    finest triple's Richardson extrapolation (hollow circle) and the least-squares limit
    (hollow square)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    panels = ("p99_von_mises_kPa", "max_von_mises_kPa", "closure_gap_max_mm", "contact_force_mN")
    fig = Figure(figsize=(10, 7), layout="constrained")
    axes = fig.subplots(2, 2).ravel()
    sizes = [lv["relative_size"] for lv in study["levels"]]
    for ax, q in zip(axes, panels):
        for stage in study["levels"][0]["stages"]:
            ys = [lv["stages"][stage][q] for lv in study["levels"]]
            if all(y is None for y in ys):
                continue
            ys = [math.nan if y is None else y for y in ys]
            color = f"C{int(stage) - 1}"  # one colour per stage in every panel
            ax.plot(sizes, ys, "o-", color=color, label=f"stage {stage}")
            fin = study["studies"].get(stage, {}).get(q)
            if fin and fin[-1]["kind"] == "monotone":
                ax.plot([0.0], [fin[-1]["extrapolated"]], "o", mfc="none", color=color)
            fit = study.get("fits", {}).get(stage, {}).get(q)
            if fit and fit["kind"] in ("monotone", "scattered"):
                ax.plot([0.0], [fit["extrapolated"]], "s", mfc="none", color=color)
        ax.set_xlabel("relative element size s = (0.5 / m)^(1/3)")
        ax.set_ylabel(q)
        ax.set_xlim(left=0.0)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(
        f"job {study['job_index']}: {study['geometry']} (hollow circle: Richardson "
        "extrapolation; square: least-squares limit)",
        fontsize=9,
    )
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))
    return path

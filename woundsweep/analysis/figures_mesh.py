"""The mesh-sensitivity figure: p99 / p99 at the finest mesh size factor, per stage.

One panel per stage with matched geometries (`mesh_sensitivity.matched_ratios`): a thin line
per matched group, the median per factor and its 10-90 % band.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from .mesh_sensitivity import MESH  # noqa: E402

__all__ = ["mesh_ratio_figure"]


def mesh_ratio_figure(ratios: pd.DataFrame) -> Figure:
    """p99 / p99 at the finest factor against the mesh size factor (``ratios`` not empty)."""
    stages = sorted(int(s) for s in ratios["stage"].unique())
    ncol = min(3, len(stages))
    nrow = math.ceil(len(stages) / ncol)
    fig = Figure(figsize=(3.6 * ncol, 3.0 * nrow + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrow, ncol, squeeze=False, sharey=True)).ravel()
    for ax, stage in zip(axes, stages):
        s = ratios[ratios["stage"] == stage]
        segs = [g[[MESH, "ratio"]].to_numpy() for _, g in s.groupby("group", sort=True)]
        ax.add_collection(LineCollection(segs, colors="0.6", linewidths=0.5, alpha=0.4,
                                         rasterized=True))  # fmt: skip
        by = s.groupby(MESH, sort=True)["ratio"]
        f = np.asarray(list(by.groups), dtype=float)
        ax.fill_between(f, by.quantile(0.1).to_numpy(), by.quantile(0.9).to_numpy(),
                        color="tab:blue", alpha=0.25, label="10-90 %")  # fmt: skip
        ax.plot(f, by.median().to_numpy(), "o-", color="tab:blue", label="median")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_title(f"stage {stage} ({len(segs)} groups)", fontsize=9)
        ax.set_xlabel("mesh size factor (larger = finer)")
        ax.autoscale_view()
    for ax in axes[len(stages) :]:
        ax.set_visible(False)
    for ax in axes[::ncol]:
        ax.set_ylabel("p99 / p99 at the finest factor")
    axes[0].legend(fontsize=8)
    fig.suptitle("Mesh sensitivity: matched geometries (equal in every parameter but the mesh)")
    return fig

"""Figures of ``woundsweep analyze`` (matplotlib, Agg backend), each written as PNG and SVG.

Figure objects are built directly (no pyplot), so nothing depends on a display or on global
figure state. Stresses in kPa; locations are normalised as `paper.normalised_locations`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from .settings import STAGE_GROUPS  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from .fitting import SchemeFit
    from .regression import SurrogateFit

__all__ = [
    "FIGURE_STEMS",
    "confusion",
    "importance_bars",
    "max_locations",
    "plain_log",
    "roc_curves",
    "save",
    "stiff_vs_soft",
    "sobol_bars",
    "stress_distribution",
    "surrogate_test",
    "training_curves",
    "write_all",
    "write_surrogate",
]

# Per-scheme figures carry a ``_<scheme>`` suffix.
FIGURE_STEMS = {
    "per_scheme": ("training", "importance", "roc", "confusion"),
    "shared": ("stress_distribution", "stiff_vs_soft", "max_location", "max_location_profiles"),
    "mesh": ("mesh_sensitivity",),  # only with matched geometries (`mesh_sensitivity`)
    "surrogate": ("surrogate_test", "sobol"),
}


def plain_log(ax: Axes, which: str = "xy") -> None:
    """Log-scaled axes labelled with plain numbers (2, 5, 10, 20, not 2x10^0): ticks at 1-2-3-5
    or 1-2-5 per decade over a short range, fewer over a long one, no minor labels. Call it after
    plotting (the ticks follow the data's range)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    for name in which:
        axis = ax.xaxis if name == "x" else ax.yaxis
        (ax.set_xscale if name == "x" else ax.set_yscale)("log")
        lo, hi = sorted(axis.get_view_interval())
        decades = np.log10(hi / lo) if lo > 0 and hi > lo else 1.0
        if decades <= 0.6:
            subs: tuple[float, ...] = tuple(range(1, 10))
        elif decades <= 1.2:
            subs = (1.0, 2.0, 3.0, 5.0)
        elif decades <= 2.0:
            subs = (1.0, 2.0, 5.0)
        elif decades <= 3.2:
            subs = (1.0, 3.0)
        else:
            subs = (1.0,)
        axis.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=12))
        axis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
        axis.set_minor_formatter(NullFormatter())


def save(fig: Figure, out_dir: Path, stem: str) -> list[Path]:
    """Write ``stem.png`` and ``stem.svg``; return both paths."""
    paths = [out_dir / f"{stem}.png", out_dir / f"{stem}.svg"]
    # No timestamps in the files: identical inputs give identical figures.
    fig.savefig(paths[0], dpi=120, metadata={"Software": None})
    fig.savefig(paths[1], metadata={"Date": None})
    return paths


def training_curves(eval_log: dict[str, dict[str, list[float]]], best: int, title: str) -> Figure:
    """Figure 3A/B: classification error and log loss per boosting round."""
    fig = Figure(figsize=(9, 3.6), layout="constrained")
    for ax, metric, label in zip(
        fig.subplots(1, 2), ("merror", "mlogloss"), ("classification error", "log loss")
    ):
        for split, style in (("train", "-"), ("validation", "--")):
            vals = eval_log.get(split, {}).get(metric, [])
            ax.plot(np.arange(1, len(vals) + 1), vals, style, label=split)
        ax.axvline(best + 1, color="grey", lw=0.8, ls=":", label=f"best round {best + 1}")
        ax.set_xlabel("boosting round")
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    return fig


def importance_bars(importance: dict[str, Any], title: str) -> Figure:
    """Figure 3C: split counts ("weight"), average gain and total gain per feature group."""
    grouped = importance["grouped"]
    names = importance["ranking_weight"][::-1]
    fig = Figure(figsize=(11, 4), layout="constrained")
    axes = fig.subplots(1, 3, sharey=True)
    for ax, key, label in zip(
        axes, ("weight", "gain", "total_gain"), ("splits (weight)", "average gain", "total gain")
    ):
        ax.barh(names, [grouped[n][key] for n in names], color="tab:blue")
        ax.set_xlabel(label)
    fig.suptitle(f"{title} (wound_depth = depth factor + aspect factor columns)")
    return fig


def roc_curves(y: np.ndarray, prob: np.ndarray, title: str) -> Figure:
    """Figure 3D: one-vs-rest ROC per quantile, micro- and macro-average curves (test rows)."""
    from sklearn.metrics import auc, roc_curve

    q = prob.shape[1]
    onehot = np.eye(q, dtype=int)[np.asarray(y, dtype=int)]
    fig = Figure(figsize=(5.5, 5), layout="constrained")
    ax = fig.subplots()
    grid = np.linspace(0, 1, 201)
    tprs, aucs = [], []
    for k in range(q):
        if 0 < onehot[:, k].sum() < len(y):
            fpr, tpr, _ = roc_curve(onehot[:, k], prob[:, k])
            aucs.append(auc(fpr, tpr))
            tprs.append(np.interp(grid, fpr, tpr))
            ax.plot(fpr, tpr, lw=0.8, alpha=0.7, label=f"Q{k + 1} (AUC {aucs[-1]:.3f})")
    if len(set(np.asarray(y).tolist())) > 1:
        fpr, tpr, _ = roc_curve(onehot.ravel(), prob.ravel())
        ax.plot(fpr, tpr, "k-", lw=2, label=f"micro-average (AUC {auc(fpr, tpr):.3f})")
    if tprs:
        ax.plot(
            grid,
            np.mean(tprs, axis=0),
            "k--",
            lw=2,
            label=f"macro-average (AUC {np.mean(aucs):.3f})",
        )
    ax.plot([0, 1], [0, 1], color="grey", lw=0.6, ls=":")
    ax.set_xlabel("false positive rate")
    ax.set_ylabel("true positive rate")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title)
    return fig


def confusion(matrix: Sequence[Sequence[int]], title: str) -> Figure:
    """Test confusion matrix, each true quantile's row normalised to 1."""
    m = np.asarray(matrix, dtype=float)
    frac = m / np.maximum(m.sum(axis=1, keepdims=True), 1)
    q = len(m)
    fig = Figure(figsize=(5, 4.4), layout="constrained")
    ax = fig.subplots()
    im = ax.imshow(frac, vmin=0, vmax=1, cmap="viridis")
    ticks = np.arange(q)
    ax.set_xticks(ticks, [f"Q{k + 1}" for k in ticks])
    ax.set_yticks(ticks, [f"Q{k + 1}" for k in ticks])
    ax.set_xlabel("predicted quantile")
    ax.set_ylabel("true quantile")
    fig.colorbar(im, ax=ax, label="fraction of the true quantile")
    ax.set_title(title)
    return fig


def stress_distribution(stress: np.ndarray, stage: np.ndarray, edges: np.ndarray | None) -> Figure:
    """Histogram of the maximal stress (log scale) per stage group, with the quantile edges."""
    s = np.asarray(stress, dtype=float)
    bins = np.geomspace(s.min(), s.max(), 60) if s.max() > s.min() else 10
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    for name, stages in STAGE_GROUPS:
        sel = np.isin(stage, stages)
        if sel.any():
            # matplotlib's stub: bins takes no array (its docs and code take one).
            ax.hist(
                s[sel],
                bins=bins,  # type: ignore[arg-type]
                histtype="step",
                lw=1.5,
                label=f"{name} (n={int(sel.sum())})",
            )
    if edges is not None:
        for e in edges[1:-1]:
            ax.axvline(e, color="grey", lw=0.6, ls="--")
    plain_log(ax, "x")
    ax.set_xlabel("maximal stress: volume-weighted p99 von Mises (kPa)")
    ax.set_ylabel("rows")
    ax.legend(fontsize=8)
    ax.set_title("Distribution of maximal stress (dashed: quantile edges)")
    return fig


def stiff_vs_soft(pairs: pd.DataFrame, summary: dict[str, Any]) -> Figure:
    """Stiff against soft stress of paired jobs (same geometry, orientation, stage), per shape."""
    shapes = sorted(summary) or ["(no pairs)"]
    fig = Figure(figsize=(4.5 * len(shapes), 4.3), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(shapes)))
    for ax, shape in zip(axes, shapes):
        p = pairs[pairs["wound_shape"].astype(str) == shape] if len(pairs) else pairs
        if len(p):
            ax.scatter(p["soft_kPa"], p["stiff_kPa"], s=4, alpha=0.4, rasterized=True)
            lo = float(min(p["soft_kPa"].min(), p["stiff_kPa"].min()))
            hi = float(max(p["soft_kPa"].max(), p["stiff_kPa"].max()))
            ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
            plain_log(ax)
        st = summary.get(shape)
        if st:
            pval = st["sign_test_p"]
            ptxt = "n/a" if pval is None else f"{pval:.2g}"
            ax.set_title(
                f"{shape}: stiff > soft in {100 * st['fraction_stiff_greater']:.1f}%\n"
                f"({st['stiff_greater']}/{st['pairs']} pairs, sign test p = {ptxt})",
                fontsize=9,
            )
        ax.set_xlabel("soft skin: maximal stress (kPa)")
        ax.set_ylabel("stiff skin: maximal stress (kPa)")
    return fig


def max_locations(
    locs: pd.DataFrame, zone_ends: tuple[float, float] | None = (1 / 3, 2 / 3)
) -> Figure:
    """Figure 2: where the maximum sits along (y), across (x) and through (z) the patch, the
    closure zone's ends dashed (``None``: no common ends, as for excisions)."""
    cols = (
        ("y_along", (0, 1), "along the wound: (y + L) / 2L"),
        ("x_across", (-1, 1), "across: (x - w/2) / (L + w/2)"),
        ("z_depth", (0, 1), "depth: -z / T (0 = surface)"),
    )
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    axes = fig.subplots(len(STAGE_GROUPS), 3, squeeze=False)
    for i, (group, _) in enumerate(STAGE_GROUPS):
        sel = locs[locs["stage_group"] == group]
        for j, (col, rng, label) in enumerate(cols):
            ax = axes[i, j]
            # Clip so that a maximum found slightly outside the undeformed patch still counts.
            vals = np.clip(sel[col].to_numpy(dtype=float), *rng)
            ax.hist(vals, bins=40, range=rng, color="tab:red" if i == 1 else "tab:blue")
            if col == "y_along" and zone_ends is not None:
                for v in zone_ends:
                    ax.axvline(v, color="grey", lw=0.8, ls="--")
            if i == len(STAGE_GROUPS) - 1:
                ax.set_xlabel(label)
            if j == 0:
                ax.set_ylabel(f"{group}\n(n={len(sel)})")
    dashed = " (dashed: ends of the closure zone)" if zone_ends is not None else ""
    fig.suptitle(f"Location of the maximal von Mises stress{dashed}")
    return fig


def write_all(
    out_dir: Path,
    fits: Sequence[SchemeFit],
    stress: np.ndarray,
    stage: np.ndarray,
    pairs: pd.DataFrame,
    stiff_soft: dict[str, Any],
    locs: pd.DataFrame,
    zone_ends: tuple[float, float] | None = (1 / 3, 2 / 3),
) -> list[Path]:
    """Write every figure of the analysis; return the paths (PNG and SVG). ``zone_ends``: the
    closure zone's ends along the wound in Figure 2 (``None``: not drawn)."""
    paths: list[Path] = []
    for f in fits:
        label = f"{f.scheme} split"
        test = f.metrics["test"]
        y_test = f.y[f.split.test]
        paths += save(
            training_curves(f.trained.eval_log, f.trained.best_iteration, label),
            out_dir,
            f"training_{f.scheme}",
        )
        paths += save(
            importance_bars(f.metrics["importance"], label), out_dir, f"importance_{f.scheme}"
        )
        paths += save(
            roc_curves(y_test, f.prob_test, f"{label}: test rows (n={len(y_test)})"),
            out_dir,
            f"roc_{f.scheme}",
        )
        paths += save(
            confusion(test["confusion_matrix"], f"{label}: test rows"),
            out_dir,
            f"confusion_{f.scheme}",
        )
    edges = fits[0].edges_kPa if fits else None
    paths += save(stress_distribution(stress, stage, edges), out_dir, "stress_distribution")
    paths += save(stiff_vs_soft(pairs, stiff_soft), out_dir, "stiff_vs_soft")
    paths += save(max_locations(locs, zone_ends), out_dir, "max_location")
    return paths


def surrogate_test(
    observed: np.ndarray, predicted: np.ndarray, half: dict[str, np.ndarray], title: str
) -> Figure:
    """Observed against predicted stress on the test geometries, with the conformal bands."""
    fig = Figure(figsize=(5.5, 5), layout="constrained")
    ax = fig.subplots()
    p = np.exp(predicted)
    # Each row's interval is a vertical bar at its estimate: wider level first, behind.
    for (level, hw), color, lw in zip(
        sorted(half.items(), key=lambda kv: -float(kv[0])), ("0.8", "0.5"), (3, 1.5)
    ):
        w = np.exp(hw)
        ax.vlines(
            p,
            p / w,
            p * w,
            color=color,
            lw=lw,
            rasterized=True,
            label=f"{float(level):.0%} interval",
        )
    ax.scatter(
        p, np.exp(observed), s=6, color="tab:blue", zorder=3, rasterized=True, label="test rows"
    )
    ax.plot([p.min(), p.max()], [p.min(), p.max()], "k-", lw=0.8)
    plain_log(ax)
    ax.set_xlabel("surrogate estimate: p99 von Mises (kPa)")
    ax.set_ylabel("simulated p99 von Mises (kPa)")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=9)
    return fig


def sobol_bars(sobol: dict[str, Any]) -> Figure:
    """First-order and total Sobol indices of the surrogate per input, with 95 % bootstrap bars."""
    idx = sobol["indices"]
    names = sobol["ranking_total"][::-1]
    y = np.arange(len(names))
    fig = Figure(figsize=(6.5, 0.4 * len(names) + 1.5), layout="constrained")
    ax = fig.subplots()
    for off, key, label in ((-0.2, "S1", "first order S1"), (0.2, "ST", "total ST")):
        ax.barh(y + off, [idx[n][key] for n in names], 0.4,
                xerr=[idx[n][f"{key}_conf"] for n in names], label=label)  # fmt: skip
    ax.set_yticks(y, names)
    ax.set_xlabel("Sobol index of log p99 (surrogate, over the grid's values)")
    ax.legend(fontsize=8)
    return fig


def write_surrogate(
    out_dir: Path, fit: SurrogateFit, rows: pd.DataFrame, sobol: dict[str, Any]
) -> list[Path]:
    """Write the surrogate's test figure and the Sobol figure; return the paths."""
    from .conformal import half_widths
    from .settings import COVERAGE_LEVELS, STRESS

    test = fit.split.test
    y = np.log(rows[STRESS].to_numpy(dtype=np.float64)[test])
    stage = rows["stage"].to_numpy()[test]
    scores = fit.meta["calibration_scores_log"]
    half = {str(lv): half_widths(scores, stage, lv) * fit.sd_test for lv in COVERAGE_LEVELS}
    title = f"stress surrogate ({fit.model.kind}): test geometries (n={len(test)})"
    return save(surrogate_test(y, fit.pred_test, half, title), out_dir, "surrogate_test") + save(
        sobol_bars(sobol), out_dir, "sobol"
    )

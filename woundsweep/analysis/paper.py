"""The paper's descriptive statistics: stiff against soft skin, and where the maximum sits."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from .settings import LOCATION_COLUMNS, STAGE_GROUPS, STRESS

__all__ = [
    "LOCATION_NORMALISATION",
    "along_half_length",
    "location_summary",
    "normalised_locations",
    "stiff_vs_soft",
]

# How `normalised_locations` scales each coordinate (recorded in metrics.json).
LOCATION_NORMALISATION = {
    "y_along": "(y + L) / 2L (L + l/2 in place of L for the excision); "
    "closure zone ends at 1/3 and 2/3",
    "x_across": "(x - w/2) / (L + w/2); 0 = wound mid-plane, +-1 = lateral faces",
    "z_depth": "-z / T; 0 = skin surface, 1 = bottom face",
}


def stiff_vs_soft(rows: pd.DataFrame) -> tuple[dict[str, Any], pd.DataFrame]:
    """Pair stiff and soft results of the same geometry, orientation and stage.

    Returns per wound shape the number of pairs, how often stiff > soft, < soft or tied, the
    fraction stiff > soft, and a two-sided sign test (binomial, p = 1/2, ties dropped); and
    the pairs themselves (for the figure).
    """
    from scipy.stats import binomtest

    key = ["geometry_id", "orientation_deg", "stage"]
    cols = [*key, "wound_shape", STRESS]
    skin = rows["skin_type"].astype(str)
    stiff, soft = rows.loc[skin == "stiff", cols], rows.loc[skin == "soft", cols]
    pairs = stiff.merge(soft.drop(columns="wound_shape"), on=key, suffixes=("_stiff", "_soft"))
    pairs = pairs.rename(columns={f"{STRESS}_stiff": "stiff_kPa", f"{STRESS}_soft": "soft_kPa"})
    out: dict[str, Any] = {}
    for shape in sorted(pairs["wound_shape"].astype(str).unique()):
        p = pairs[pairs["wound_shape"].astype(str) == shape]
        greater = int((p["stiff_kPa"] > p["soft_kPa"]).sum())
        less = int((p["stiff_kPa"] < p["soft_kPa"]).sum())
        n = len(p)
        # The pairs of one geometry (its stages, orientations) are not independent: the
        # geometry-level test counts each geometry once, by the sign of its median difference.
        med = (p["stiff_kPa"] - p["soft_kPa"]).groupby(p["geometry_id"]).median()
        g_up, g_down = int((med > 0).sum()), int((med < 0).sum())
        out[shape] = {
            "pairs": n,
            "geometries": int(len(med)),
            "geometries_stiff_greater": g_up,
            "sign_test_p_geometries": float(binomtest(g_up, g_up + g_down, 0.5).pvalue)
            if g_up + g_down
            else None,
            "stiff_greater": greater,
            "soft_greater": less,
            "ties": n - greater - less,
            "fraction_stiff_greater": greater / n,
            "sign_test_p": float(binomtest(greater, greater + less, 0.5).pvalue)
            if greater + less
            else None,
        }
    return out, pairs.reset_index(drop=True)


def along_half_length(rows: pd.DataFrame) -> np.ndarray:
    """Half the patch's extent along the wound (mm): L for the trenches, L + l/2 for the
    excision (its patch reaches L beyond each apex)."""
    L = rows["patch_half_length_mm"].to_numpy(dtype=float)
    if "wound_length_mm" not in rows:
        return L
    half = rows["wound_length_mm"].to_numpy(dtype=float) / 2
    return np.where(np.isfinite(half), L + half, L)


def normalised_locations(rows: pd.DataFrame) -> pd.DataFrame:
    """Where the maximum sits, scaled by the patch (rows with a location only).

    ``y_along`` = (y + L) / 2L: 0 and 1 at the patch ends, the closure zone's ends at 1/3 and
    2/3 (`along_half_length`: the excision's patch reaches L beyond its apices). ``x_across`` = (x - w/2) / (L + w/2): 0 on the wound's mid-plane, -1 and +1 at the
    lateral faces. ``z_depth`` = -z / T: 0 at the skin surface, 1 at the bottom face.
    """
    loc = rows.dropna(subset=list(LOCATION_COLUMNS))
    L, w, T = (
        loc[c].to_numpy(dtype=float)
        for c in ("patch_half_length_mm", "wound_width_mm", "total_thickness_mm")
    )
    Ly = along_half_length(loc)
    stage = loc["stage"].to_numpy()
    group = np.full(len(loc), "", dtype=object)
    for name, stages in STAGE_GROUPS:
        group[np.isin(stage, stages)] = name
    return pd.DataFrame(
        {
            "stage_group": group,
            "y_along": (loc["max_location_y_mm"].to_numpy(dtype=float) + Ly) / (2 * Ly),
            "x_across": (loc["max_location_x_mm"].to_numpy(dtype=float) - w / 2) / (L + w / 2),
            "z_depth": -loc["max_location_z_mm"].to_numpy(dtype=float) / T,
        }
    )


def location_summary(locs: pd.DataFrame) -> dict[str, Any]:
    """The ``max_location`` entry of metrics.json: normalisation, rows per group, outliers."""
    return {
        "normalisation": dict(LOCATION_NORMALISATION),
        "rows": {name: int((locs["stage_group"] == name).sum()) for name, _ in STAGE_GROUPS},
        "outside_unit_range": {
            c: int(((locs[c] < (-1 if c == "x_across" else 0)) | (locs[c] > 1)).sum())
            for c in ("y_along", "x_across", "z_depth")
        },
    }

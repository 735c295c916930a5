"""How much the stress depends on the mesh: the mesh size factor's importance in the stress
models, and p99 by mesh size factor for matched geometries.

A matched group is the rows equal in every model column (`model_features`) but
``mesh_size_factor`` (same wound, skin, orientation and stage). A larger factor is a finer mesh; each group's p99 is
compared with its p99 at the finest factor of the stage's rows, and groups without a row at
that factor, or with no other factor, are left out (and counted).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
import pandas as pd

from .settings import STRESS, model_features

__all__ = ["MESH", "matched_ratios", "mesh_importance", "mesh_sensitivity", "report_lines"]

MESH = "mesh_size_factor"


def _match(rows: pd.DataFrame) -> list[str]:
    """The columns a matched group agrees on: the rows' model columns but the mesh and stage."""
    features = model_features(rows["wound_shape"].astype(str))
    return [f for f in features if f not in (MESH, "stage")]


def matched_ratios(rows: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Per matched group and factor: ``stage``, ``group``, ``mesh_size_factor``, ``ratio`` =
    p99 / p99 at the stage's finest factor; and per stage the groups left out and why."""
    match = _match(rows)
    frame = rows[match].astype(object).where(rows[match].notna(), "n/a").astype(str)
    key = pd.MultiIndex.from_frame(frame).factorize()[0]
    df = pd.DataFrame(
        {
            "stage": rows["stage"].to_numpy(dtype=np.int64),
            "group": key,
            MESH: rows[MESH].to_numpy(dtype=float),
            "p99": rows[STRESS].to_numpy(dtype=float),
        }
    )
    parts, left_out = [], {}
    for stage, s in df.groupby("stage", sort=True):
        finest = float(s[MESH].max())
        ref = s[s[MESH] == finest].set_index("group")["p99"]
        n_factors = s.groupby("group")[MESH].nunique()
        keep = n_factors.index[(n_factors >= 2) & n_factors.index.isin(ref.index)]
        left_out[str(int(stage))] = {
            "finest_factor": finest,
            "groups": int(len(n_factors)),
            "one_factor": int((n_factors < 2).sum()),
            "no_finest_row": int(((n_factors >= 2) & ~n_factors.index.isin(ref.index)).sum()),
        }
        m = s[s["group"].isin(keep)].copy()
        m["ratio"] = m["p99"].to_numpy() / ref.loc[m["group"]].to_numpy()
        parts.append(m)
    cols = ["stage", "group", MESH, "ratio"]
    out = pd.concat(parts, ignore_index=True)[cols] if parts else pd.DataFrame(columns=cols)
    return out.sort_values(["stage", "group", MESH], ignore_index=True), left_out


def _rank_share(values: dict[str, float], name: str = MESH) -> dict[str, Any] | None:
    """The rank (1 = largest; None when unused, 0) and share of the total of ``name`` in
    ``values``; None when ``name`` is not among them (a fixed input)."""
    if name not in values:
        return None
    total = float(sum(values.values()))
    v = float(values[name])
    return {
        "value": v,
        # Ties rank as the best of them: rank = 1 + the number of strictly larger values.
        "rank": 1 + sum(x > v for x in values.values()) if v > 0 else None,
        "of": len(values),
        "share": float(values[name]) / total if total > 0 else None,
    }


def mesh_importance(metrics: dict[str, Any]) -> dict[str, Any]:
    """The mesh size factor's rank and share per importance measure of the stress models."""
    out: dict[str, Any] = {}
    sur = metrics.get("surrogate", {})
    if "importance" in sur:  # the trees' own measures
        imp = sur["importance"]
        out["surrogate_total_gain"] = _rank_share(
            {g: v["total_gain"] for g, v in imp["grouped"].items()}
        )
        out["surrogate_mean_abs_shap"] = _rank_share(dict(imp["shap"]["grouped"]))
    if "sensitivity" in sur:
        idx = sur["sensitivity"].get("indices", {})
        out["surrogate_sobol_total"] = _rank_share({g: v["ST"] for g, v in idx.items()})
    for scheme, m in metrics.get("schemes", {}).items():
        out[f"classifier_{scheme}_total_gain"] = _rank_share(
            {g: v["total_gain"] for g, v in m["importance"]["grouped"].items()}
        )
    return out


def mesh_sensitivity(rows: pd.DataFrame, metrics: dict[str, Any]) -> dict[str, Any]:
    """The ``mesh_sensitivity`` entry of metrics.json (``metrics`` holds the fitted models')."""
    ratios, left_out = matched_ratios(rows)
    stages: dict[str, Any] = {}
    for stage, s in ratios.groupby("stage", sort=True):
        rel = np.abs(s["ratio"].to_numpy() - 1.0)[
            s[MESH].to_numpy() != left_out[str(stage)]["finest_factor"]
        ]
        by_factor = {
            f"{f:g}": {
                "median_ratio": float(np.median(g["ratio"])),
                "q10_ratio": float(np.quantile(g["ratio"], 0.1)),
                "q90_ratio": float(np.quantile(g["ratio"], 0.9)),
                "rows": int(len(g)),
            }
            for f, g in s.groupby(MESH, sort=True)
        }
        stages[str(int(cast(float, stage)))] = {  # a group key: any Scalar to pandas-stubs
            "groups": int(s["group"].nunique()),
            "median_abs_rel_diff": float(np.median(rel)),
            "max_abs_rel_diff": float(np.max(rel)),
            "by_factor": by_factor,
        }
    return {
        "factors": sorted(float(f) for f in rows[MESH].dropna().unique()),
        "matched_on": _match(rows) + ["stage"],
        "relative_difference": "|p99 / p99 at the stage's finest factor - 1|, coarser rows",
        "stages": stages,
        "left_out": left_out,
        "importance": mesh_importance(metrics),
    }


def _imp_cell(e: dict[str, Any] | None) -> str:
    if e is None:
        return "fixed (one value)"
    if e["rank"] is None:
        return f"not used (0; {e['of']} parameters)"
    share = "n/a" if e["share"] is None else f"{100 * e['share']:.1f}%"
    return f"rank {e['rank']} of {e['of']}, {share} ({e['value']:.4g})"


def report_lines(ms: dict[str, Any]) -> list[str]:
    """The report's mesh-sensitivity section."""
    lines = ["", "## Mesh sensitivity", ""]
    factors = ", ".join(f"{f:g}" for f in ms["factors"])
    imp = ms["importance"]
    if imp:
        names = {
            "surrogate_total_gain": "surrogate, total gain",
            "surrogate_mean_abs_shap": "surrogate, mean abs SHAP",
            "surrogate_sobol_total": "surrogate, Sobol total index",
        }
        lines += [
            f"Importance of `{MESH}` (factors in the rows: {factors}); share = its part of the "
            "sum over the parameters.",
            "",
            "| measure | rank, share (value) |",
            "|---|---|",
            *(f"| {names.get(k, k.replace('_', ' '))} | {_imp_cell(e)} |" for k, e in imp.items()),
            "",
        ]
    if not ms["stages"]:
        lines.append(
            f"No matched geometries: no rows equal but for `{MESH}` hold two or more factors "
            f"(factors in the rows: {factors})."
        )
        return lines
    lines += [
        "p99 of matched geometries (rows equal in every parameter but the mesh size factor) "
        "against p99 at the stage's finest factor (larger = finer).",
        "",
        "| stage | finest factor | groups | median abs rel. diff. | max abs rel. diff. "
        "| median ratio per factor |",
        "|---|---|---|---|---|---|",
    ]
    for stage, st in ms["stages"].items():
        per = ", ".join(f"{f}: {v['median_ratio']:.3f}" for f, v in st["by_factor"].items())
        lines.append(
            f"| {stage} | {ms['left_out'][stage]['finest_factor']:g} | {st['groups']} "
            f"| {100 * st['median_abs_rel_diff']:.1f}% | {100 * st['max_abs_rel_diff']:.1f}% "
            f"| {per} |"
        )
    return lines

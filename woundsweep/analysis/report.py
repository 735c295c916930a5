"""``RUN_DIR/analysis/report.md``: one page with our numbers next to the paper's claims."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..core.fsutil import atomic_write_bytes
from .closures import report_lines as closure_report_lines
from .mesh_sensitivity import report_lines as mesh_report_lines
from .offgrid import coverage_text, cross_report_lines
from .offgrid import report_lines as off_grid_report_lines
from .profile_locations import report_lines as profile_report_lines

__all__ = ["PAPER", "auc_text", "p_text", "render_report", "summary", "write_report"]


def p_text(p: float | None, relation: bool = False) -> str:
    """A p-value for the page: "n/a" for none, "< 1e-300" where it underflowed to 0 (a sign
    test over a thousand pairs or more, all one way); ``relation`` prefixes "= " otherwise."""
    if p is None:
        return "n/a"
    if p == 0:
        return "< 1e-300"
    return f"= {p:.2g}" if relation else f"{p:.2g}"


# The paper's statements that the analysis can check (Results, Figure 3).
PAPER: dict[str, Any] = {
    "auc": 0.85,
    "rows": (43_214, 18_519, 6_859),
    "stiff_soft": {"cylindrical": (10_819, 11_566), "wedge": (8_873, 11_105)},
}


def _f(x: float | None, fmt: str = ".3f") -> str:
    return "n/a" if x is None else format(x, fmt)


def _yes(ok: bool | None) -> str:
    return "n/a" if ok is None else ("yes" if ok else "**no**")


def auc_text(m: dict[str, Any]) -> str:
    """The macro AUC (2 decimals) with its 95% interval over the test geometries."""
    auc = m["test"]["auc_macro"]
    if auc is None:
        return "n/a"
    ci = m["test"].get("auc_macro_interval", {})
    n = ci.get("geometries")
    if ci.get("ci95"):
        lo, hi = ci["ci95"]
        return f"{auc:.2f} (95% {lo:.2f}-{hi:.2f} over {n} test geometries)"
    return f"{auc:.2f} (no interval: {n} test geometry)" if n is not None else f"{auc:.2f}"


def summary(metrics: dict[str, Any]) -> list[str]:
    """The report's opening paragraph in plain words: what the model found, how good it is,
    and what it rests on."""
    rows = metrics["rows"]
    out = [
        f"The models learn `{metrics['stress']}`, the stress that 99% of the tissue's volume "
        f"stays below, from {rows['used_rows']:,} distinct stage results of {rows['jobs']:,} jobs"
        + (
            f" on {rows['distinct_geometries']:,} geometries"
            if rows.get("distinct_geometries")
            else ""
        )
        + (
            f" ({rows['duplicate_rows']:,} rows that repeat an earlier stage's state "
            f"{'left out' if rows.get('duplicate_dropped', True) else 'kept'})."
            if "duplicate_rows" in rows
            else "."
        )
    ]
    sur = metrics.get("surrogate", {})
    if "sensitivity" in sur:
        top = sur["sensitivity"]["ranking_total"][:2]
        out.append(f"What drives the stress most: {' and '.join(top)} (Sobol total index).")
    geo = metrics["schemes"].get("geometry") or next(iter(metrics["schemes"].values()), None)
    if geo is not None:
        out.append(
            f"On wounds it never saw, the classifier ranks a wound's stress class with a "
            f"macro AUC of {auc_text(geo)} (0.5 is chance, 1 perfect) and names the exact "
            f"class {100 * geo['test']['accuracy']:.0f}% of the time, within one class "
            f"{100 * geo['test']['within_one_quantile']:.0f}%."
        )
    if "test" in sur:
        cov = sur["test"]["coverage"].get("0.8") or next(iter(sur["test"]["coverage"].values()))
        ci = cov.get("interval")
        out.append(
            f"The stress estimate's {100 * cov['nominal']:g}% interval held for "
            f"{100 * (cov['empirical'] or 0):.0f}% of {cov['rows']} test rows from "
            f"{sur['split_geometries']['test']} geometries"
            + (
                f" ({100 * cov['interval_level']:g}% bootstrap interval over the geometries "
                f"{100 * ci[0]:.0f}-{100 * ci[1]:.0f}%;"
                if ci
                else " ("
            )
            + f" about {cov['median_width_factor'] or float('nan'):.2g}x from its low to its "
            "high end)."
        )
    svs = metrics["stiff_vs_soft"]
    for shape, st in svs.items():
        out.append(
            f"Stiff skin carries more stress than soft in {100 * st['fraction_stiff_greater']:.0f}% "
            f"of {st['pairs']} {shape} pairs from {st.get('geometries', '?')} geometries."
        )
    if rows["used_rows"] < 1000 or (geo is not None and geo["split_geometries"]["test"] < 10):
        out.append(
            "This is a small run: read the numbers as a check that the pipeline works, not "
            "as findings."
        )
    return out


def render_report(metrics: dict[str, Any], figures: Sequence[str]) -> str:
    """The report's Markdown text."""
    schemes = metrics["schemes"]
    names = list(schemes)
    rows = metrics["rows"]
    q = metrics["settings"]["quantiles"]
    head = "| | paper | " + " | ".join(f"{s} split" for s in names) + " |"
    sep = "|---|---|" + "---|" * len(names)

    def row(label: str, paper: str, cell: Any) -> str:
        return f"| {label} | {paper} | " + " | ".join(cell(schemes[s]) for s in names) + " |"

    def min_auc(m: dict[str, Any]) -> float | None:
        vals = [a for a in m["test"]["auc_per_quantile"] if a is not None]
        return min(vals) if vals else None

    def auc_ok(m: dict[str, Any]) -> str:
        lo = min_auc(m)
        return _yes(None if lo is None else lo > PAPER["auc"])

    def top(m: dict[str, Any], key: str) -> str:
        r = m["importance"][key]
        return f"{r[0]}, then {r[1]}" if len(r) > 1 else r[0]

    def depth_first(m: dict[str, Any]) -> str:
        return _yes(m["importance"]["ranking_weight"][0] == "wound_depth")

    lines = [
        "# woundsweep analysis report",
        "",
        "## Summary",
        "",
        " ".join(summary(metrics)),
        "",
        f"Element: {metrics.get('element', 'unknown')}; every number below is of this element.",
        "",
        f"Maximal stress = `{metrics['stress']}` (kPa). Rows: {rows['store_rows']} in the store "
        f"({rows['jobs']} jobs), {rows['converged_rows']} converged, {rows['used_rows']} used "
        f"(converged, stress > 0). {q} quantile classes: chance is accuracy {1 / q:.3f}, AUC 0.5.",
        f"Rows whose sutured zone has reopened (surface gap above the closure tolerance): "
        f"{rows.get('reopened_rows', 0)}"
        f"{', left out' if rows.get('reopened_dropped', True) else ', kept'}; rows whose "
        f"flanks pass through each other (mirrored zone points overlap, or the audit finds flank"
        f" nodes inside the other side): {rows.get('interpenetrating_rows', 0)}"
        f"{', left out' if rows.get('interpenetrating_dropped') else ', kept'}.",
        *(
            [
                f"Rows that repeat an earlier stage's state of their job ({rows['duplicate_rule']}): "
                f"{rows['duplicate_rows']}"
                f"{', left out (`analyze --keep-duplicates` keeps them)' if rows.get('duplicate_dropped', True) else ', kept'}: "
                "one state counted once, so the tests below do not count it as several "
                "independent results."
            ]
            if "duplicate_rows" in rows
            else []
        ),
        "",
        "## Stress-quantile model (test rows; Figure 3)",
        "",
        head,
        sep,
        row(
            "rows train / validation / test",
            " / ".join(f"{n:,}" for n in PAPER["rows"]),
            lambda m: " / ".join(
                f"{m['split_rows'][k]:,}" for k in ("train", "validation", "test")
            ),
        ),
        row("test geometries", "not given", lambda m: str(m["split_geometries"]["test"])),
        row("macro-average AUC (95% over test geometries)", "> 0.85", auc_text),
        row("micro-average AUC", "> 0.85", lambda m: _f(m["test"]["auc_micro"], ".2f")),
        row("lowest per-quantile AUC", "> 0.85", lambda m: _f(min_auc(m), ".2f")),
        row("every AUC > 0.85?", "yes", auc_ok),
        row(
            "accuracy / within one quantile",
            "not given",
            lambda m: (
                f"{_f(m['test']['accuracy'], '.2f')} / {_f(m['test']['within_one_quantile'], '.2f')}"
            ),
        ),
        row(
            "log loss (train / validation / test)",
            "train close to validation",
            lambda m: " / ".join(_f(m[k]["log_loss"]) for k in ("train", "validation", "test")),
        ),
        row(
            "best round / rounds run",
            "about 100-150",
            lambda m: f"{m['best_iteration'] + 1} / {m['rounds_run']}",
        ),
        row(
            "top features by split count",
            "wound depth, then stage",
            lambda m: top(m, "ranking_weight"),
        ),
        row("wound depth first?", "yes", depth_first),
        row("top features by total gain", "not given", lambda m: top(m, "ranking_total_gain")),
        "",
        "## Stiff against soft skin (same geometry, orientation and stage)",
        "",
        "The pairs of one geometry (its stages and orientations) are not independent, so "
        "the last column tests the geometries, each counted once by the sign of its median "
        "difference.",
        "",
        "| wound shape | paper | ours | sign test p (pairs) | geometries: stiff greater, p |",
        "|---|---|---|---|---|",
    ]

    def by_geometry(st: dict[str, Any] | None) -> str:
        if st is None or "geometries" not in st:
            return "n/a"
        gp = st["sign_test_p_geometries"]
        return f"{st['geometries_stiff_greater']}/{st['geometries']}, p {p_text(gp, relation=True)}"

    svs = metrics["stiff_vs_soft"]
    for shape, (k, n) in PAPER["stiff_soft"].items():
        st = svs.get(shape)
        ours = (
            "no pairs"
            if st is None
            else f"{100 * st['fraction_stiff_greater']:.1f}% ({st['stiff_greater']:,}/{st['pairs']:,})"
        )
        p = p_text(None if st is None else st["sign_test_p"])
        label = "cylindrical (paper: curved)" if shape == "cylindrical" else shape
        lines.append(
            f"| {label} | {100 * k / n:.1f}% ({k:,}/{n:,}), p < 0.001 | {ours} | {p} "
            f"| {by_geometry(st)} |"
        )
    for shape in sorted(set(svs) - set(PAPER["stiff_soft"])):  # the excision: not in the paper
        st = svs[shape]
        p = p_text(st["sign_test_p"])
        lines.append(
            f"| {shape} | not in the paper | {100 * st['fraction_stiff_greater']:.1f}% "
            f"({st['stiff_greater']:,}/{st['pairs']:,}) | {p} | {by_geometry(st)} |"
        )
    lines += surrogate_lines(metrics)
    lines += off_grid_report_lines(metrics)
    lines += cross_report_lines(metrics)
    if "max_location_profiles" in metrics:
        lines += profile_report_lines(metrics)
    lines += closure_report_lines(metrics)
    if "mesh_sensitivity" in metrics:
        lines += mesh_report_lines(metrics["mesh_sensitivity"])
    lines += [
        "",
        "## How these numbers differ from the paper's method",
        "",
        "- Quantile edges come from each scheme's **training rows only** (the paper binned over all "
        "rows, test rows included). Test rows outside the training range fall in the end classes.",
        "- The **geometry split** keeps every physical geometry (all geometric parameters except the "
        "mesh size factor) in one set; the random split, as in the paper, spreads the stages, skin "
        "types and orientations of one geometry over all three sets, which flatters the test score.",
        "- Early stopping uses the validation log loss, so validation scores are optimistic; the test "
        "rows are used once, after training.",
        '- "wound_depth" sums the importances of the wedge depth factor (the excision\'s too) and '
        "the cylinder aspect (offset) factor columns, mirroring the paper's combined column. "
        "Importance counts splits over all trees of all classes.",
        "- Maximal stress is the volume-weighted 99th percentile of von Mises (the published code "
        "took the percentile over nodal values).",
        "- Stiff > soft: ties count as not greater and are dropped from the two-sided sign test.",
        "- Figure 2 positions: y as (y + L)/2L (closure zone ends at 1/3 and 2/3; L + l/2 in place "
        "of L for the excision), x as "
        "(x - w/2)/(L + w/2) (0 = wound mid-plane), z as depth -z/T (0 = surface); values outside "
        "the range are clipped into the end bins (counts in metrics.json).",
        "",
        "## Figures",
        "",
        ", ".join(f"[{name}]({name})" for name in figures if name.endswith(".png"))
        or "None drawn (`analyze --no-figures`).",
        "",
    ]
    return "\n".join(lines)


def surrogate_lines(metrics: dict[str, Any]) -> list[str]:
    """The report's sections on the stress surrogate, the failure model and the importances."""
    sur = metrics.get("surrogate", {})
    fail = metrics.get("failure", {})
    lines = ["", "## Stress surrogate: log p99 with conformal intervals (test geometries)", ""]
    if "test" not in sur:
        lines.append(sur.get("statement", "no stress surrogate"))
    else:
        t = sur["test"]
        sizes = " / ".join(
            f"{sur['split_rows'][k]:,} ({sur['split_geometries'][k]})"
            for k in ("train", "stop", "calibration", "test")
        )
        lines += [
            f"{_surrogate_text(sur)} Rows (geometries) train / early stopping / calibration / "
            f"test: {sizes}. Test RMSE {_f(t['rmse_log'])} in log stress, R² {_f(t['r2_log'])}.",
            "",
            *(
                [
                    f"Only {sur['split_geometries']['test']} test geometries: the rows of one "
                    "geometry move together, so these coverages are coarse.",
                    "",
                ]
                if sur["split_geometries"]["test"] < 10
                else []
            ),
            "| nominal | empirical coverage (bootstrap interval over geometries) | covered / "
            "rows | median width (upper / lower) | lowest stage coverage |",
            "|---|---|---|---|---|",
        ]
        for level, c in t["coverage"].items():
            per = [v["empirical"] for v in c["by_stage"].values() if v["empirical"] is not None]
            lines.append(
                f"| {100 * float(level):g}% | {coverage_text(c)} | {c['covered']} / {c['rows']} "
                f"| {_f(c['median_width_factor'], '.3g')}x | {_f(min(per) if per else None)} |"
            )
    lines += ["", "## Failure model (jobs that did not converge)", "", fail.get("statement", "n/a")]
    lines += ["", "## Which parameters matter", ""]
    if "importance" in sur or "sensitivity" in sur:
        lines += importance_table(metrics)
    return lines


def _surrogate_text(sur: dict[str, Any]) -> str:
    """What the surrogate is and how its intervals were calibrated, in words."""
    cal = sur.get("calibration", "")
    if sur.get("surrogate", "trees") == "trees":
        return (
            "XGBoost regression of log p99 (stage as a feature); intervals: "
            f"{cal} (calibration rows whose geometries training never saw)."
        )
    gp = sur["gp"]
    floor = gp["noise_floor_log_sd"]
    return (
        f"Gaussian processes of log p99, one per wound shape, skin type and stage "
        f"({gp['groups']} groups; {gp['kernel']}, hyperparameters fitted), on the "
        "dimensionless factors: the stresses do not depend on `dermal_thickness_mm`, so rows "
        f"that differ only in it are averaged ({gp['rows']:,} training rows into "
        f"{gp['points']:,} points; their spread, the noise floor, is "
        f"{'n/a' if floor is None else format(floor, '.3g')} in log stress). The early-stopping "
        f"rows train too. Intervals: {cal}."
    )


def importance_table(metrics: dict[str, Any]) -> list[str]:
    """Split counts and total gain (classifier), TreeSHAP (tree surrogate) and Sobol indices
    (surrogate); n/a where a measure does not apply."""
    sur = metrics["surrogate"]
    cls = next(iter(metrics["schemes"].values()), None)
    shap = sur.get("importance", {}).get("shap", {}).get("grouped", {})
    sob = sur["sensitivity"]
    idx = sob["indices"]
    top = sob["ranking_total"][:3]
    lines = [
        f"Top three by Sobol total index: {', '.join(top)}. Sobol indices of the surrogate's "
        f"log p99 over the grid's values ({sob['evaluations']:,} surrogate calls, 95% bootstrap "
        "half-widths); mean |SHAP| in log stress (TreeSHAP, XGBoost pred_contribs, all rows; "
        "the tree surrogate only). Split counts and total gain: "
        + (f"the {next(iter(metrics['schemes']))} split classifier." if cls else "n/a."),
        "",
        "| parameter | splits (classifier) | total gain (classifier) | total gain (surrogate) "
        "| mean abs SHAP | Sobol S1 | Sobol ST |",
        "|---|---|---|---|---|---|---|",
    ]
    names = set(shap) | set(idx)
    if cls:
        names |= set(cls["importance"]["grouped"])
    for g in sorted(names, key=lambda g: (-idx.get(g, {}).get("ST", -1.0), -shap.get(g, 0.0), g)):
        c = cls["importance"]["grouped"].get(g) if cls else None
        sg = sur.get("importance", {}).get("grouped", {}).get(g, {})
        si = idx.get(g)
        s1 = "fixed" if si is None else f"{si['S1']:.3f} ± {si['S1_conf']:.3f}"
        st = "fixed" if si is None else f"{si['ST']:.3f} ± {si['ST_conf']:.3f}"
        lines.append(
            f"| {g} | {_f(c and c['weight'], '.0f')} | {_f(c and c['total_gain'], '.4g')} "
            f"| {_f(sg.get('total_gain'), '.4g')} | {_f(shap.get(g), '.4f')} | {s1} | {st} |"
        )
    lines += zero_index_notes(idx)
    return lines


# Why a parameter's Sobol index can be zero by construction (not for lack of data).
SCALE_NOTE = (
    "dermal_thickness_mm: every length of the model is a multiple of t_d (the subcutis, the "
    "patch, the wound, the mesh through its size law), the materials have no length scale and "
    "the loads are stresses, so the stresses do not depend on t_d: a stress model is "
    "scale-invariant in it, and its index is zero by construction, whatever the data."
)


def zero_index_notes(idx: dict[str, Any]) -> list[str]:
    """A note for each parameter whose Sobol total index is near zero, with the reason where
    the model's construction gives one (`SCALE_NOTE`)."""
    zero = [g for g, v in idx.items() if v.get("ST") is not None and abs(v["ST"]) < 0.005]
    if not zero:
        return []
    out = ["", f"Total index below 0.005: {', '.join(sorted(zero))}."]
    if "dermal_thickness_mm" in zero:
        out.append(SCALE_NOTE)
    return out


def write_report(path: str | Path, metrics: dict[str, Any], figures: Sequence[str]) -> None:
    """Write the report atomically."""
    atomic_write_bytes(path, render_report(metrics, figures).encode())

"""Other runs' rows for the stress surrogate: wounds between the grid's values.

``analyze RUN --calibrate-on RUN2`` takes the surrogate's conformal scores from RUN2's rows
(`regression.fit_surrogate`); ``--test-on RUN3`` reports on RUN3's rows, used for nothing
else (`off_grid_test`): the intervals' coverage at `COVERAGE_LEVELS`, the estimate's median
relative error, and the quantile-class accuracy of the surrogate's estimate and of each
classifier against that classifier's training quantile edges. Both runs are read as the
analysed one (`data`, the same row selection) and refused, in one line, when their rows use
another set of stress columns, another element degree, or a skin type (or its material),
wound shape or stage the models did not train on.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pandas as pd

from ..core.errors import AnalysisError
from ..store.reader import rows_element_degree
from .conformal import coverage
from .data import (
    drop_orphans,
    encode_features,
    load_results,
    run_or_none,
    select_rows,
    sweep_settings,
)
from .settings import COVERAGE_LEVELS, STRESS

if TYPE_CHECKING:
    from .fitting import SchemeFit
    from .surrogate import Surrogate

__all__ = [
    "OtherRows",
    "Reference",
    "off_grid_test",
    "read_other",
    "report_lines",
    "stress_columns",
]


class OtherRows(NamedTuple):
    """Another run's selected rows (its directory as given) and their model matrix."""

    source: str
    rows: pd.DataFrame
    X: np.ndarray


class Reference(NamedTuple):
    """What another run's rows must match: the analysed run's stress columns (those holding
    values), element degree, skin codes (c, kPa), shapes and stages; the model columns and
    `select_rows`' keyword arguments."""

    stress_columns: list[str]
    degree: int | None
    skins: Mapping[str, float]
    shapes: Sequence[str]
    stages: Sequence[int]
    features: Sequence[str]
    select: Mapping[str, Any]


def stress_columns(results: pd.DataFrame) -> list[str]:
    """The von Mises statistics (kPa) of a result table that hold a value."""
    return sorted(
        c for c in results.columns
        if "von_mises" in c and c.endswith("_kPa")
        and pd.to_numeric(results[c], errors="coerce").notna().any()
    )  # fmt: skip


def read_other(path: str | Path, option: str, ref: Reference) -> OtherRows:
    """The rows of the run ``path`` (given as ``option``), checked against ``ref``."""
    rd = Path(path)
    if not rd.is_dir():
        raise AnalysisError(f"{option} {rd}: no such run directory")
    run = run_or_none(rd)
    skins = sweep_settings(run)[1]
    results = drop_orphans(load_results(rd, run), run)[0]
    cols = stress_columns(results)
    if cols != list(ref.stress_columns):
        raise AnalysisError(
            f"{option} {rd}: its rows hold the stress columns {cols}, the analysed run's "
            f"{list(ref.stress_columns)}"
        )
    degree = rows_element_degree(results)
    if degree != ref.degree:
        raise AnalysisError(
            f"{option} {rd}: element degree {degree}, the analysed run's is {ref.degree}"
        )
    rows = select_rows(results, **ref.select)[0]
    if ref.select["stress"] != STRESS:
        rows = rows.assign(**{STRESS: rows[ref.select["stress"]]})
    names = sorted({str(v) for v in rows["skin_type"]})
    for what, have, known in (
        ("skin types", names, [str(k) for k in ref.skins]),
        ("wound shapes", [str(v) for v in rows["wound_shape"]], [str(k) for k in ref.shapes]),
        ("stages", [str(int(v)) for v in rows["stage"]], [str(k) for k in ref.stages]),
    ):
        extra = sorted(set(have) - set(known))
        if extra:
            raise AnalysisError(
                f"{option} {rd}: {what} {', '.join(extra)} the models did not train on "
                f"(trained: {', '.join(sorted(known))})"
            )
    for name in names:
        if skins.get(name) != ref.skins[name]:
            raise AnalysisError(
                f"{option} {rd}: skin type {name!r} has c = {skins.get(name)} kPa, the "
                f"analysed run's {ref.skins[name]} kPa"
            )
    return OtherRows(str(rd), rows, encode_features(rows, ref.skins, ref.features))


def _classes(
    stress: np.ndarray, estimate: np.ndarray, fit: SchemeFit, X: np.ndarray, nthread: int
) -> dict[str, Any]:
    """Quantile classes against ``fit``'s training edges: the surrogate's and the classifier's."""
    from .splits import assign_quantiles
    from .training import predict_proba

    true = assign_quantiles(stress, fit.edges_kPa)
    sur = assign_quantiles(estimate, fit.edges_kPa)
    cls = predict_proba(fit.trained.booster, X, nthread).argmax(axis=1)
    return {
        "edges_from": f"the {fit.scheme} split's training rows",
        "surrogate_accuracy": float(np.mean(sur == true)),
        "surrogate_within_one": float(np.mean(np.abs(sur - true) <= 1)),
        "classifier_accuracy": float(np.mean(cls == true)),
        "classifier_within_one": float(np.mean(np.abs(cls - true) <= 1)),
    }


def off_grid_test(
    model: Surrogate, scores: Mapping[str, Sequence[float]], other: OtherRows,
    fits: Sequence[SchemeFit], nthread: int = 2,
) -> dict[str, Any]:  # fmt: skip
    """The surrogate's intervals, estimate and classes, and the classifiers' classes, on
    ``other``'s rows."""
    y = np.log(other.rows[STRESS].to_numpy(dtype=np.float64))
    stage = other.rows["stage"].to_numpy(dtype=np.int64)
    mean, sd = model.predict_log(other.X)
    rel = np.abs(np.exp(mean - y) - 1.0)  # |estimate - stress| / stress
    return {
        "run": other.source,
        "rows": int(len(y)),
        "geometries": int(other.rows["geometry_id"].nunique()),
        "used_for": "this test only (neither fitting nor calibration)",
        "coverage": {str(lv): coverage(y, mean, stage, scores, lv, sd) for lv in COVERAGE_LEVELS},
        "median_relative_error": float(np.median(rel)),
        "median_relative_error_by_stage": {
            str(int(s)): float(np.median(rel[stage == s])) for s in np.unique(stage)
        },
        "quantile_classes": {
            f.scheme: _classes(np.exp(y), np.exp(mean), f, other.X, nthread) for f in fits
        },
    }


def report_lines(metrics: dict[str, Any]) -> list[str]:
    """The report's section on the off-grid test run (none without ``--test-on``)."""
    t = metrics.get("off_grid_test")
    if t is None:
        return []
    lines = ["", f"## Off the grid: {t['run']} (`--test-on`)", ""]
    if "coverage" not in t:
        return lines + [t.get("statement", "no off-grid test")]
    kind = metrics.get("surrogate", {}).get("surrogate", "trees")
    lines += [
        f"{t['rows']} rows of {t['geometries']} geometries whose factors lie between the "
        f"grid's values, used for {t['used_for']}. The {kind} surrogate's estimate is off by "
        f"a median {100 * t['median_relative_error']:.1f}% of the stress.",
        "",
        "| nominal | empirical coverage | covered / rows | median width (upper / lower) |",
        "|---|---|---|---|",
    ]
    for level, c in t["coverage"].items():
        w = c["median_width_factor"]
        emp = "n/a" if c["empirical"] is None else f"{c['empirical']:.3f}"
        lines.append(
            f"| {100 * float(level):g}% | {emp} | {c['covered']} / {c['rows']} "
            f"| {'n/a' if w is None else format(w, '.3g')}x |"
        )
    lines += [
        "",
        "| quantile classes (edges) | surrogate's estimate: exact / within one | classifier: "
        "exact / within one |",
        "|---|---|---|",
    ]
    for scheme, q in t["quantile_classes"].items():
        lines.append(
            f"| {scheme} split | {q['surrogate_accuracy']:.2f} / {q['surrogate_within_one']:.2f} "
            f"| {q['classifier_accuracy']:.2f} / {q['classifier_within_one']:.2f} |"
        )
    return lines

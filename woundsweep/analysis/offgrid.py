"""Other runs' rows for the stress surrogate: wounds between the grid's values.

``analyze RUN --calibrate-on RUN2`` takes the surrogate's conformal scores from RUN2's rows
(`regression.fit_surrogate`); ``--test-on RUN3`` reports on RUN3's rows, used for nothing
else (`off_grid_test`; given twice or more, on the runs pooled and on each alone): the
intervals' coverage at `COVERAGE_LEVELS` with its bootstrap interval over RUN3's geometries
(`conformal.coverage_interval`), the estimate's median relative error and mean log error (its
offset: positive where it over-predicts), and the quantile-class accuracy of the surrogate's
estimate and of each classifier against that classifier's training quantile edges. Every run is read as the
analysed one (`data`, the same row selection) and refused, in one line, when its rows use
another set of stress columns, another element degree, or a skin type (or its material),
wound shape or stage the models did not train on.

``--calibrate-on`` given two runs or more (`pool`): the intervals are calibrated on their
rows pooled, and their coverage off the grid is estimated by cross-calibration by run
(`cross_calibration`): each run in turn is tested with intervals calibrated on the other
runs' rows alone. The surrogate is fitted on the grid's rows only, so every fold tests rows
neither fitted nor calibrated on; each fold's coverage is reported with its bootstrap
interval, and the pooled estimate (all folds' covered rows over all their rows) with a
bootstrap that resamples each run's geometries apart. Split-conformal assumes the runs
exchangeable with each other and with the wounds asked about: random designs within the
grid's ranges (`sweeps/paper-random-*.yaml`) are; runs at fixed places between the grid's
values (a third of each interval, say) share those places in all their rows, and their
scores reflect them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pandas as pd

from ..core.errors import AnalysisError
from ..store.reader import rows_element_degree
from .conformal import INTERVAL_LEVEL, calibrate, coverage, coverage_interval, covered
from .data import (
    drop_orphans,
    encode_features,
    load_results,
    run_or_none,
    select_rows,
    sweep_settings,
)
from .settings import COVERAGE_LEVELS, STRESS
from .splits import geometry_groups

if TYPE_CHECKING:
    from .fitting import SchemeFit
    from .surrogate import Surrogate

__all__ = [
    "OtherRows",
    "Reference",
    "coverage_text",
    "cross_calibration",
    "cross_report_lines",
    "off_grid_test",
    "offset_text",
    "pool",
    "pool_name",
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


def pool_name(names: Sequence[str]) -> str:
    """``A and B pooled``, ``A, B and C pooled``."""
    return f"{', '.join(names[:-1])} and {names[-1]} pooled"


def pool(runs: Sequence[OtherRows]) -> OtherRows:
    """Several runs' rows as one (the source names them all)."""
    if len(runs) == 1:
        return runs[0]
    return OtherRows(
        pool_name([r.source for r in runs]),
        pd.concat([r.rows for r in runs], ignore_index=True),
        np.vstack([r.X for r in runs]),
    )


def _clusters(rows: pd.DataFrame) -> np.ndarray:
    """Each row's geometry for the coverage's bootstrap: rows that differ only in t_d are one
    (the same dimensionless wound; their errors move together)."""
    return geometry_groups(rows, scale_free=True)


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
        "coverage": {
            str(lv): coverage(y, mean, stage, scores, lv, sd, _clusters(other.rows))
            for lv in COVERAGE_LEVELS
        },
        "median_relative_error": float(np.median(rel)),
        "mean_log_error": float(np.mean(mean - y)),
        "median_relative_error_by_stage": {
            str(int(s)): float(np.median(rel[stage == s])) for s in np.unique(stage)
        },
        "quantile_classes": {
            f.scheme: _classes(np.exp(y), np.exp(mean), f, other.X, nthread) for f in fits
        },
    }


class _Scored(NamedTuple):
    """One run's rows as the surrogate sees them: log stress, stage, mean, scale, clusters."""

    y: np.ndarray
    stage: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    groups: np.ndarray


def _scored(model: Surrogate, other: OtherRows) -> _Scored:
    mean, sd = model.predict_log(other.X)
    return _Scored(
        np.log(other.rows[STRESS].to_numpy(dtype=np.float64)),
        other.rows["stage"].to_numpy(dtype=np.int64),
        mean,
        sd,
        _clusters(other.rows),
    )


def cross_calibration(model: Surrogate, runs: Sequence[OtherRows]) -> dict[str, Any]:
    """Coverage off the grid by cross-calibration by run: each of ``runs`` (two or more)
    tested with intervals calibrated on the others' rows pooled (normalised scores per stage,
    as `regression.fit_surrogate`); per fold and pooled over the folds, each coverage with
    its bootstrap interval over geometries (the pooled one resamples each run's apart)."""
    if len(runs) < 2:
        raise AnalysisError("cross-calibration needs two calibration runs or more")
    scored = [_scored(model, r) for r in runs]
    folds: list[dict[str, Any]] = []
    flags: dict[str, list[np.ndarray]] = {str(lv): [] for lv in COVERAGE_LEVELS}
    for i, (run, t) in enumerate(zip(runs, scored)):
        rest = [s for j, s in enumerate(scored) if j != i]
        scores = calibrate(
            np.concatenate([s.stage for s in rest]),
            np.concatenate([(s.y - s.mean) / s.sd for s in rest]),
        )
        for lv in COVERAGE_LEVELS:
            flags[str(lv)].append(covered(t.y, t.mean, t.stage, scores, lv, t.sd)[0])
        folds.append({
            "test_run": run.source,
            "calibrated_on": [r.source for j, r in enumerate(runs) if j != i],
            "calibration_rows": int(sum(len(s.y) for s in rest)),
            "rows": int(len(t.y)),
            "geometries": int(len(np.unique(t.groups))),
            "median_relative_error": float(np.median(np.abs(np.exp(t.mean - t.y) - 1.0))),
            "mean_log_error": float(np.mean(t.mean - t.y)),
            "coverage": {
                str(lv): coverage(t.y, t.mean, t.stage, scores, lv, t.sd, t.groups)
                for lv in COVERAGE_LEVELS
            },
        })  # fmt: skip
    groups = [s.groups for s in scored]
    rel = np.concatenate([np.abs(np.exp(s.mean - s.y) - 1.0) for s in scored])
    pooled: dict[str, Any] = {
        "rows": int(len(rel)),
        "geometries": int(sum(f["geometries"] for f in folds)),
        "median_relative_error": float(np.median(rel)),
        "mean_log_error": float(np.mean(np.concatenate([s.mean - s.y for s in scored]))),
        "coverage": {},
    }
    for level, inside in flags.items():
        n, k = sum(len(f) for f in inside), sum(int(f.sum()) for f in inside)
        pooled["coverage"][level] = {
            "nominal": float(level),
            "rows": n,
            "covered": k,
            "empirical": k / n if n else None,
            "interval": coverage_interval(inside, groups),
            "interval_level": INTERVAL_LEVEL,
        }
    return {
        "runs": [r.source for r in runs],
        "method": (
            f"cross-calibration by run: each of the {len(runs)} calibration runs tested with "
            "intervals calibrated on the others' rows alone; the intervals saved with the "
            "model are calibrated on all of them pooled"
        ),
        "folds": folds,
        "pooled": pooled,
    }


def coverage_text(c: Mapping[str, Any]) -> str:
    """A coverage as ``0.883 (90% 0.835-0.929)``: the empirical fraction with its bootstrap
    interval over geometries where one was computed."""
    if c.get("empirical") is None:
        return "n/a"
    ci = c.get("interval")
    if not ci:
        return f"{c['empirical']:.3f}"
    return f"{c['empirical']:.3f} ({100 * c['interval_level']:g}% {ci[0]:.3f}-{ci[1]:.3f})"


def offset_text(m: Mapping[str, Any]) -> str:
    """The estimate's mean offset from the stress, exp(mean log error) - 1, as ``+1.2%`` (a
    run whose every row is over-predicted by 1.2 % reads +1.2 %); n/a in older metrics."""
    e = m.get("mean_log_error")
    return "n/a" if e is None else f"{100 * math.expm1(e):+.1f}%"


def _result_cells(r: Mapping[str, Any]) -> str:
    """A tested run's table cells: rows (geometries), median error, mean offset, coverage at
    80 % and at 95 %."""
    cov = r["coverage"]
    return (
        f"{r['rows']} ({r['geometries']}) | {100 * r['median_relative_error']:.1f}% "
        f"| {offset_text(r)} | {coverage_text(cov.get('0.8', {}))} "
        f"| {coverage_text(cov.get('0.95', {}))}"
    )


def cross_report_lines(metrics: dict[str, Any]) -> list[str]:
    """The report's section on the cross-calibration by run (none without it)."""
    x = metrics.get("off_grid_cross_calibration")
    if x is None:
        return []
    lines = [
        "",
        "## Off the grid: cross-calibration by run (`--calibrate-on` twice or more)",
        "",
        f"The intervals are calibrated on the rows of {pool_name(x['runs'])}. Their "
        "coverage off the grid is estimated by testing each run with intervals calibrated on "
        "the others alone (the surrogate was fitted on none of them). Intervals of the "
        "coverage: bootstrap over the tested geometries, the calibration held fixed; the "
        "pooled one resamples each run's geometries apart.",
        "",
        "| tested on | calibrated on | rows (geometries) | median error | mean offset "
        "| coverage at 80% | coverage at 95% |",
        "|---|---|---|---|---|---|---|",
    ]
    for f in [
        *x["folds"],
        {**x["pooled"], "test_run": "all folds", "calibrated_on": ["the others"]},
    ]:
        lines.append(f"| {f['test_run']} | {', '.join(f['calibrated_on'])} | {_result_cells(f)} |")
    return lines


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
        f"a median {100 * t['median_relative_error']:.1f}% of the stress; its mean offset "
        f"is {offset_text(t)}.",
        "",
        "| nominal | empirical coverage (bootstrap interval over geometries) | covered / rows "
        "| median width (upper / lower) |",
        "|---|---|---|---|",
    ]
    for level, c in t["coverage"].items():
        w = c["median_width_factor"]
        emp = coverage_text(c)
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
    if t.get("by_run"):
        lines += [
            "",
            "Each run alone:",
            "",
            "| run | rows (geometries) | median error | mean offset | coverage at 80% "
            "| coverage at 95% |",
            "|---|---|---|---|---|---|",
        ]
        for r in t["by_run"]:
            lines.append(f"| {r['run']} | {_result_cells(r)} |")
    return lines

"""``woundsweep analyze``: every scheme fitted and evaluated, the stress surrogate with its
conformal intervals and Sobol indices, the failure model; then metrics, models, figures, report.

Settings are layered: `ModelSettings` defaults, the run's ``Sweep.analysis``, then the
caller's overrides. Everything lands in ``RUN_DIR/analysis/`` (or ``out_dir``), each file
written atomically.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from .. import __version__
from ..config.analysis import resolve_settings
from ..config.solver import element_name
from ..core.errors import AnalysisError
from ..core.fsutil import atomic_write_bytes
from ..core.layout import ANALYSIS_METRICS, ANALYSIS_REPORT, RunLayout
from ..store.reader import rows_element_degree
from .data import (
    drop_orphans,
    encode_features,
    load_results,
    run_or_none,
    select_rows,
    sweep_settings,
)
from .failure import fit_failure
from .fitting import fit_scheme
from .mesh_sensitivity import matched_ratios, mesh_sensitivity
from .model_io import json_bytes, save_companions, save_model
from .offgrid import (
    OtherRows,
    Reference,
    cross_calibration,
    off_grid_test,
    pool,
    read_other,
    stress_columns,
)
from .paper import location_summary, normalised_locations, stiff_vs_soft
from .profile_locations import profile_positions, profile_summary
from .report import write_report
from .settings import (
    IMPORTANCE_GROUPS,
    MIN_ROWS_PER_QUANTILE,
    SCHEMES,
    STRESS,
    model_features,
)
from .trained_on import trained_on

if TYPE_CHECKING:
    import pandas as pd

    from ..config.analysis import ModelSettings

__all__ = ["AnalysisOutput", "analysis_steps", "run_analysis"]


def analysis_steps(n_schemes: int) -> int:
    """How many times `run_analysis` calls ``echo``: once before each of its steps."""
    return n_schemes + 6


def _surrogate(
    rows: pd.DataFrame, X: np.ndarray, settings: ModelSettings, say: Callable[[str], None],
    calibration: OtherRows | None = None,
) -> tuple[Any, dict[str, Any]]:  # fmt: skip
    """The stress surrogate and its metrics with Sobol indices; or None and why not."""
    from .regression import fit_surrogate
    from .sensitivity import surrogate_sobol

    say(f"training the stress surrogate ({settings.surrogate}) on {len(rows)} rows...")
    try:
        fit = fit_surrogate(rows, X, settings, calibration)
    except AnalysisError as err:
        return None, {"statement": f"no stress surrogate: {err}"}
    say(f"Sobol indices of the surrogate ({settings.sobol_samples} base samples)...")
    sobol = surrogate_sobol(fit.model, fit.meta, settings.sobol_samples, settings.seed)
    return fit, {**fit.metrics, "sensitivity": sobol}


def _run_paths(given: str | Path | Sequence[str | Path] | None) -> list[Path]:
    """``--calibrate-on``'s or ``--test-on``'s runs: none, one, or several (a path or a
    sequence of them)."""
    if given is None:
        return []
    if isinstance(given, (str, Path)):
        return [Path(given)]
    return [Path(p) for p in given]


def _other_paths(rd: Path, calibrate_on: Sequence[Path], test_on: Sequence[Path]) -> None:
    """Refuse a ``--calibrate-on`` or ``--test-on`` run that is missing, or the same run as
    the analysed one or another option's (checked before anything is read)."""
    named = [("the analysed run", rd.resolve())]
    given = [("--calibrate-on", p) for p in calibrate_on] + [("--test-on", p) for p in test_on]
    for option, path in given:
        if not Path(path).is_dir():
            raise AnalysisError(f"{option} {path}: no such run directory")
        same = [k for k, v in named if Path(path).resolve() == v]
        if same:
            raise AnalysisError(f"{option} {path}: the same run as {same[0]}")
        named.append((f"{option}'s", Path(path).resolve()))


class AnalysisOutput(NamedTuple):
    """What `run_analysis` wrote."""

    out_dir: Path
    metrics: dict[str, Any]
    files: list[Path]


def run_analysis(
    run_dir: str | Path,
    overrides: Mapping[str, Any] | None = None,
    schemes: Sequence[str] = SCHEMES,
    out_dir: str | Path | None = None,
    echo: Callable[[str], None] | None = None,
    drop_interpenetrating: bool = False,
    keep_reopened: bool = False,
    keep_duplicates: bool = False,
    stress: str = STRESS,
    beside: Sequence[str | Path] = (),
    calibrate_on: str | Path | Sequence[str | Path] | None = None,
    test_on: str | Path | Sequence[str | Path] | None = None,
    figures: bool = True,
) -> AnalysisOutput:
    """Fit and evaluate each scheme; write metrics, models, figures and report.md.

    Settings: `ModelSettings` defaults, then the run's ``Sweep.analysis``, then ``overrides``.
    ``echo`` receives a line before each long step (training takes minutes on 70k rows).
    ``stress`` is the store's column the models learn (a von Mises statistic in kPa); the
    steps below read it under `STRESS`, and metrics.json and the model files name it.
    ``beside`` are runs closed by other closing loads, drawn beside this one's in Figure 2
    (`woundsweep.analysis.closures`). ``calibrate_on``: a run (wounds between the grid's
    values) whose rows calibrate the surrogate's intervals, or several: calibrated on their
    rows pooled, the coverage estimated by cross-calibration by run; ``test_on``: a run (or
    several, pooled, each also reported alone) whose rows test the surrogate and the
    classifiers and nothing else (`woundsweep.analysis.offgrid`). ``figures=False`` draws
    none (they are most of the time on a small store; the models and metrics are the same).
    """
    say = echo or (lambda _line: None)
    import xgboost as xgb

    rd = Path(run_dir)
    if not rd.is_dir():
        raise AnalysisError(f"{rd}: no such run directory")
    for s in schemes:
        if s not in SCHEMES:
            raise AnalysisError(f"unknown split scheme {s!r} (expected one of {SCHEMES})")
    cal_paths = _run_paths(calibrate_on)
    test_paths = _run_paths(test_on)
    _other_paths(rd, cal_paths, test_paths)
    say("reading the results...")
    run = run_or_none(rd)  # the sweep and manifest, read once for every step below
    sweep_analysis, skins = sweep_settings(run)
    settings = resolve_settings(sweep_analysis, overrides)
    q = settings.quantiles
    results, orphans = drop_orphans(load_results(rd, run), run)
    compared = []
    if beside:  # checked before any training: the runs' closing loads must differ
        from .closures import closure_entry, closure_rows, closure_summary, common_jobs

        if run is None:
            raise AnalysisError(f"--beside: {rd} has no sweep to say how it was closed")
        compared = common_jobs(
            [closure_entry(results, run)] + [closure_rows(other) for other in beside]
        )
        loads = [c[1] for c in compared]
        if len(set(loads)) != len(loads):
            raise AnalysisError(f"--beside: each run needs its own closing load, got {loads}")
        if compared[0][0].empty:
            raise AnalysisError("--beside: the runs have no converged job in common")
    degree = rows_element_degree(results)
    record = trained_on(run, results)
    column = stress
    if not (column.endswith("_kPa") and "von_mises" in column):
        raise AnalysisError(f"--stress {column}: expected a von Mises column in kPa")
    rows, counts = select_rows(
        results, drop_interpenetrating, keep_reopened, keep_duplicates, column
    )
    if column != STRESS:  # the steps below read the target under its default name
        rows = rows.assign(**{STRESS: rows[column]})
    counts["rows_not_in_manifest"] = orphans
    if len(rows) < MIN_ROWS_PER_QUANTILE * q:
        raise AnalysisError(
            f"{len(rows)} usable rows: at least {MIN_ROWS_PER_QUANTILE * q} are needed for {q} quantiles "
            "and the train/validation/test splits"
        )
    features = model_features(rows["wound_shape"].astype(str))
    X = encode_features(rows, skins, features)
    ref = Reference(
        stress_columns(results), degree, {str(k): skins[str(k)] for k in set(rows["skin_type"])},
        sorted({str(s) for s in rows["wound_shape"]}), sorted({int(s) for s in rows["stage"]}),
        features, {"drop_interpenetrating": drop_interpenetrating, "keep_reopened": keep_reopened,
                   "keep_duplicates": keep_duplicates, "stress": column},
    )  # fmt: skip
    # Read and checked before any training.
    cal_runs = [read_other(p, "--calibrate-on", ref) for p in cal_paths]
    cal_rows = pool(cal_runs) if cal_runs else None
    test_runs = [read_other(p, "--test-on", ref) for p in test_paths]
    test_rows = pool(test_runs) if test_runs else None
    fits = []
    for s in schemes:
        say(f"training the {s} split model on {len(rows)} rows ({q} quantiles)...")
        fits.append(fit_scheme(s, rows, X, skins, settings))
    surrogate, surrogate_metrics = _surrogate(rows, X, settings, say, cal_rows)
    say("training the failure model...")
    failure = fit_failure(results, skins, settings)
    svs, pairs = stiff_vs_soft(rows)
    locs = normalised_locations(rows)
    pos = profile_positions(rows)
    closures = None
    if compared:
        import pandas as pd

        closures = closure_summary(compared)
        pos = profile_positions(pd.concat([c[0] for c in compared], ignore_index=True))
    target = rows[STRESS].to_numpy(dtype=np.float64)
    metrics: dict[str, Any] = {
        "woundsweep_version": __version__,
        "xgboost_version": xgb.__version__,
        "stress": column,
        "stress_units": "kPa",
        "element_degree": degree,
        "element": element_name(degree) if degree is not None else "unknown",
        "features": list(features),
        "importance_groups": {
            k: list(v) for k, v in IMPORTANCE_GROUPS.items() if set(v) & set(features)
        },
        "settings": dataclasses.asdict(settings),
        "trained_on": record,
        "rows": counts,
        "stress_summary_kPa": {
            "min": float(target.min()),
            "median": float(np.median(target)),
            "max": float(target.max()),
            "all_rows_quantile_edges": np.quantile(target, np.linspace(0, 1, q + 1)).tolist(),
        },
        "schemes": {f.scheme: f.metrics for f in fits},
        "surrogate": surrogate_metrics,
        "failure": failure.metrics,
        "stiff_vs_soft": svs,
        "max_location": location_summary(locs),
        "max_location_profiles": profile_summary(pos),
    }
    if closures is not None:
        metrics["closures"] = closures
    if len(cal_runs) > 1 and surrogate is not None:
        metrics["off_grid_cross_calibration"] = cross_calibration(surrogate.model, cal_runs)
    if test_rows is not None and surrogate is None:
        metrics["off_grid_test"] = {
            "run": test_rows.source,
            "statement": surrogate_metrics["statement"],
        }
    elif test_rows is not None:
        scores = surrogate.meta["calibration_scores_log"]
        test = off_grid_test(surrogate.model, scores, test_rows, fits, settings.nthread)
        if len(test_runs) > 1:
            test["by_run"] = [
                off_grid_test(surrogate.model, scores, r, fits, settings.nthread) for r in test_runs
            ]
        metrics["off_grid_test"] = test
    metrics["mesh_sensitivity"] = mesh_sensitivity(rows, metrics)
    final = Path(out_dir) if out_dir is not None else RunLayout(rd).analysis_dir
    out = _staging_dir(final)
    files: list[Path] = []
    for f in fits:
        f.meta["trained_on"] = record  # predict compares it with the run it answers for
        f.meta["stress"] = column
        files += save_model(out, f)
    if surrogate is not None:
        files += save_companions(out, surrogate, failure)
    say("writing figures..." if figures else "no figures (--no-figures)...")
    figs: list[Path] = []
    if figures:
        from . import figures as drawing
        from .figures_mesh import mesh_ratio_figure
        from .figures_profiles import profile_max_locations

        # The closure zone's ends along the wound (Figure 2) are common to the trenches only:
        # an excision's zone and patch scale with its length.
        excisions = bool((rows["wound_shape"].astype(str) == "fusiform").any())
        zone_ends = None if excisions else (1 / 3, 2 / 3)
        stage = rows["stage"].to_numpy()
        figs = drawing.write_all(out, fits, target, stage, pairs, svs, locs, zone_ends)
        figs += drawing.save(profile_max_locations(pos, zone_ends), out, "max_location_profiles")
        ratios, _ = matched_ratios(rows)
        if not ratios.empty:
            figs += drawing.save(mesh_ratio_figure(ratios), out, "mesh_sensitivity")
        if surrogate is not None:
            figs += drawing.write_surrogate(out, surrogate, rows, surrogate_metrics["sensitivity"])
    files += figs
    metrics_path = out / ANALYSIS_METRICS
    atomic_write_bytes(metrics_path, json_bytes(metrics))
    files.append(metrics_path)
    say("writing metrics.json and report.md...")
    report_path = out / ANALYSIS_REPORT
    write_report(report_path, metrics, [p.name for p in figs])
    files.append(report_path)
    _swap_in(out, final)
    return AnalysisOutput(final, metrics, [final / p.relative_to(out) for p in files])


def _staging_dir(final: Path) -> Path:
    """A fresh directory beside ``final`` to write the analysis into (those of dead
    analyses removed): ``final`` is replaced only by a whole analysis."""
    final.parent.mkdir(parents=True, exist_ok=True)
    for old in final.parent.glob(f".{final.name}.*-*"):
        pid = old.name.rsplit("-", 1)[1]
        if not pid.isdigit() or not Path(f"/proc/{pid}").exists():
            shutil.rmtree(old, ignore_errors=True)
    stage = final.with_name(f".{final.name}.tmp-{os.getpid()}")
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    return stage


def _swap_in(stage: Path, final: Path) -> None:
    """Replace ``final`` by ``stage`` (two renames: a reader sees the old analysis, none for
    an instant, or the new one; never a mix)."""
    old = final.with_name(f".{final.name}.old-{os.getpid()}")
    if final.exists():
        os.rename(final, old)
    os.rename(stage, final)
    shutil.rmtree(old, ignore_errors=True)

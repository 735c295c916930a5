"""``woundsweep analyze RUN_DIR``: the stress-quantile model, its evaluation and the figures."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import click

from ..core.errors import AnalysisError

__all__ = ["cmd", "summary_lines"]


def _param(values: tuple[str, ...]) -> dict[str, str]:
    out = {}
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise AnalysisError(f"--param {item!r}: expected KEY=VALUE")
        out[key.strip()] = value.strip()
    return out


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.1f}%"


def _cov(level: str, c: dict[str, Any]) -> str:
    """``88.3% at 80% (90% 83.5-92.9%)``: a coverage with its bootstrap interval, if any."""
    ci = c.get("interval")
    tail = f" ({100 * c['interval_level']:g}% {100 * ci[0]:.1f}-{100 * ci[1]:.1f}%)" if ci else ""
    return f"{_pct(c['empirical'])} at {float(level):.0%}{tail}"


def summary_lines(metrics: dict[str, Any]) -> list[str]:
    from ..analysis.offgrid import offset_text
    from ..analysis.report import auc_text

    """A few lines for the terminal: rows, per-scheme scores, stiff vs soft."""
    rows = metrics["rows"]
    dup = rows.get("duplicate_rows", 0)
    lines = [
        f"rows: {rows['used_rows']} used of {rows['store_rows']} ({rows['converged_rows']} "
        f"converged; {dup} repeating an earlier stage's state "
        f"{'left out' if rows.get('duplicate_dropped', True) else 'kept'})"
    ]
    for scheme, m in metrics["schemes"].items():
        t = m["test"]
        sizes = "/".join(str(m["split_rows"][k]) for k in ("train", "validation", "test"))
        auc = auc_text(m)
        lines.append(
            f"{scheme:>8} split ({sizes}): test macro AUC {auc}, accuracy {t['accuracy']:.2f}, "
            f"best round {m['best_iteration'] + 1}, top features {', '.join(m['importance']['ranking_weight'][:2])}"
        )
    sur = metrics.get("surrogate", {})
    if "test" in sur:
        cov = ", ".join(_cov(lv, c) for lv, c in sur["test"]["coverage"].items())
        lines.append(
            f"stress surrogate: test coverage {cov} ({sur['test']['rows']} rows, "
            f"{sur['split_geometries']['test']} geometries); Sobol total index top 3: "
            + ", ".join(sur["sensitivity"]["ranking_total"][:3])
        )
    else:
        lines.append(sur.get("statement", "no stress surrogate"))
    off = metrics.get("off_grid_test")
    if off is not None and "coverage" in off:
        cov = ", ".join(_cov(lv, c) for lv, c in off["coverage"].items())
        lines.append(
            f"off the grid ({off['run']}, {off['rows']} rows): coverage {cov}, median "
            f"error {_pct(off['median_relative_error'])}, mean offset {offset_text(off)}"
        )
        for r in off.get("by_run", []):
            cov = ", ".join(_cov(lv, c) for lv, c in r["coverage"].items())
            lines.append(
                f"  {r['run']} ({r['rows']} rows): coverage {cov}, median error "
                f"{_pct(r['median_relative_error'])}, mean offset {offset_text(r)}"
            )
    elif off is not None:
        lines.append(f"off the grid ({off['run']}): {off['statement']}")
    cross = metrics.get("off_grid_cross_calibration")
    for f in [] if cross is None else [*cross["folds"], {**cross["pooled"], "test_run": None}]:
        cov = ", ".join(_cov(lv, c) for lv, c in f["coverage"].items())
        what = (
            "all folds pooled"
            if f["test_run"] is None
            else f"{f['test_run']}, calibrated on {', '.join(f['calibrated_on'])}"
        )
        lines.append(
            f"cross-calibration off the grid ({what}; {f['rows']} rows): coverage {cov}, "
            f"median error {_pct(f['median_relative_error'])}, mean offset {offset_text(f)}"
        )
    lines.append(f"failure model: {metrics.get('failure', {}).get('statement', 'n/a')}")
    for shape, st in metrics["stiff_vs_soft"].items():
        lines.append(
            f"stiff > soft ({shape}): {100 * st['fraction_stiff_greater']:.1f}% of {st['pairs']} pairs "
            f"from {st.get('geometries', '?')} geometries"
        )
    return lines


@click.command("analyze")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--quantiles", type=int, default=None, help="Number of stress quantile classes [sweep or 8]."
)
@click.option(
    "--seed", type=int, default=None, help="Seed of the splits and of XGBoost [sweep or 0]."
)
@click.option(
    "--split", "split", type=click.Choice(["random", "geometry", "both"]), default="both", show_default=True,
    help="random: rows drawn at random (the paper); geometry: no geometry in two sets.",
)  # fmt: skip
@click.option(
    "--nthread", type=int, default=None, help="XGBoost threads (fixed for reproducibility) [2]."
)
@click.option(
    "--param", "params", multiple=True, metavar="KEY=VALUE",
    help="Override an analysis setting, e.g. max_depth=4 or n_estimators=300 (repeatable).",
)  # fmt: skip
@click.option(
    "--drop-interpenetrating", is_flag=True,
    help="Leave out the rows whose flanks pass through each other (interpenetrating = 1).",
)  # fmt: skip
@click.option(
    "--keep-reopened", is_flag=True,
    help="Keep the rows whose sutured zone has reopened (closed = 0); left out by default.",
)  # fmt: skip
@click.option(
    "--keep-duplicates", is_flag=True,
    help="Keep the rows that repeat an earlier stage's state of their job (within 1e-6 "
    "relative); left out by default, and counted in the report.",
)  # fmt: skip
@click.option(
    "--stress", "stress", default="p99_von_mises_kPa", show_default=True, metavar="COLUMN",
    help="The store's von Mises column (kPa) the models learn.",
)  # fmt: skip
@click.option(
    "--beside", "beside", multiple=True, metavar="RUN_DIR",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="A run of the same jobs closed by another stages.closure_load: its Figure 2 is drawn "
    "beside this run's, and the report compares them (repeatable).",
)  # fmt: skip
@click.option(
    "--calibrate-on", "calibrate_on", metavar="RUN_DIR", multiple=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Calibrate the stress surrogate's intervals on this run's rows (wounds between the "
    "grid's values) instead of held-out grid geometries. Repeated: on the runs' rows pooled, "
    "with the coverage estimated by cross-calibration (each run tested with intervals "
    "calibrated on the others).",
)  # fmt: skip
@click.option(
    "--test-on", "test_on", metavar="RUN_DIR", multiple=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Report on this run's rows, used for nothing else: the surrogate's coverage at 80% and "
    "95%, its median error and mean offset, and the quantile-class accuracy of the surrogate "
    "and the classifiers. Repeated: on the runs' rows pooled, and on each alone.",
)  # fmt: skip
@click.option(
    "--figures/--no-figures", default=True, show_default=True,
    help="Draw the figures (PNG and SVG); --no-figures writes the same models, metrics and "
    "report without them, in about half the time on a small run.",
)  # fmt: skip
def cmd(
    run_dir: Path,
    quantiles: int | None,
    seed: int | None,
    split: str,
    nthread: int | None,
    params: tuple[str, ...],
    drop_interpenetrating: bool,
    keep_reopened: bool,
    keep_duplicates: bool,
    stress: str,
    beside: tuple[Path, ...],
    calibrate_on: tuple[Path, ...],
    test_on: tuple[Path, ...],
    figures: bool,
) -> None:
    """Fit the stress-quantile model (XGBoost) and write RUN_DIR/analysis/.

    Uses the converged rows of RUN_DIR/results with a positive maximal stress (volume-weighted
    p99 von Mises, kPa). Writes metrics.json, model_<split>.json (+ _meta.json), PNG and SVG
    figures and report.md. Settings: defaults, then the sweep's `analysis` section, then
    --param, then the dedicated flags (the stress surrogate: --param surrogate=trees|gp).
    --calibrate-on (repeatable) and --test-on take runs of wounds between the grid's values;
    their rows must have the same stress columns, element degree, skin types, shapes and
    stages. Every coverage comes with its 90% bootstrap interval over the tested geometries.
    The time it took is the last line, on stderr.
    """
    t0 = time.perf_counter()
    from tqdm import tqdm

    from ..analysis import SCHEMES, run_analysis
    from ..analysis.pipeline import analysis_steps

    overrides: dict[str, Any] = _param(params)
    for key, value in (("quantiles", quantiles), ("seed", seed), ("nthread", nthread)):
        if value is not None:
            overrides[key] = value
    schemes = SCHEMES if split == "both" else (split,)
    # On a terminal only (disable=None): an error stays the one line on stderr.
    bar = tqdm(total=analysis_steps(len(schemes)), desc="analyze", unit="step", disable=None)

    started: list[str] = []

    def step(line: str) -> None:  # a step begins: the one before it is done
        if bar.disable:  # not a terminal (a log file): the step as a line
            click.echo(line)
            return
        if started:
            bar.update(1)
        started.append(line)
        bar.set_description(line.rstrip("."))

    try:
        result = run_analysis(
            run_dir,
            overrides,
            schemes,
            echo=step,
            drop_interpenetrating=drop_interpenetrating,
            keep_reopened=keep_reopened,
            keep_duplicates=keep_duplicates,
            stress=stress,
            beside=beside,
            calibrate_on=calibrate_on or None,
            test_on=test_on or None,
            figures=figures,
        )
        bar.update(bar.total - bar.n)
    except BaseException:
        bar.leave = False  # the error line replaces the bar
        raise
    finally:
        bar.close()
    for line in summary_lines(result.metrics):
        click.echo(line)
    click.echo(f"wrote {len(result.files)} files to {result.out_dir} (see report.md)")
    rows = result.metrics["rows"]
    click.echo(
        f"analyze: {rows['used_rows']:,} of {rows['store_rows']:,} rows used,"
        f" {len(schemes)} split{'s' if len(schemes) > 1 else ''}, in"
        f" {time.perf_counter() - t0:.1f} s",
        err=True,
    )

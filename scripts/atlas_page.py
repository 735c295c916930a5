"""Write docs/atlas.md: the charted paper grid beside the paper's own results.

    python scripts/atlas_page.py runs/chart-paper --table charted/paper.parquet \
        [--beside runs/chart-paper-code]

Reads the packed table (what is charted and its CPU time), the run's `woundsweep analyze`
output (``analysis/metrics.json`` and ``report.md``), the Figure 2 positions of the run and of
every ``--beside`` run (another closing load on a share of the same jobs) and the paper's
numbers (`PAPER`, from its Results and Figures 2-3). Writes the generated part of the page
above the line `MARK` and keeps what is below it (the hand-written reasons for each
difference); copies the figures to ``figures/atlas/`` beside the page.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from woundsweep.analysis.closures import closure_rows, closure_summary
from woundsweep.analysis.offgrid import offset_text
from woundsweep.analysis.paper import stiff_vs_soft
from woundsweep.analysis.report import p_text
from woundsweep.analysis.settings import STRESS
from woundsweep.analysis.shipped import models_dir, read_record
from woundsweep.config.manifest import load_run
from woundsweep.core.errors import StoreError, SweepError
from woundsweep.execution.summary import busy_seconds
from woundsweep.store.packed import read_packed

MARK = "<!-- written by hand below -->"
# Figure 3's panels (A and B: training curves, C: split-count importance, D: ROCs), Figure 2,
# and the figures the paper did not have.
FIGURES = (
    "training_random.png", "importance_random.png", "roc_random.png", "roc_geometry.png",
    "max_location_profiles.png", "max_location.png", "stiff_vs_soft.png",
    "stress_distribution.png", "surrogate_test.png", "sobol.png", "mesh_sensitivity.png",
)  # fmt: skip
# The paper's Results (paper.md, "Results"; Figure 3's caption).
PAPER = {
    "rows": "11,664 x 6 = 69,984",
    "converged": "68,806 (98.3 %)",
    "cylindrical": "93.5 % (10,819/11,566), p < 0.001",
    "wedge": "79.9 % (8,873/11,105), p < 0.001",
    "modelled": "68,592 (stress > 0)",
    "split": "43,214 / 18,519 / 6,859",
    "auc": "above 0.85, micro = macro",
    "split_count": "wound depth, then stage",
    "along": "at the zone's ends (1/3, 2/3) under the Dirichlet closure, far less under Neumann",
}


def _pct(a: float, b: float) -> str:
    return f"{100 * a / b:.1f} %" if b else "n/a"


def _sample(c: dict[str, Any]) -> str:
    """How the charted jobs were taken."""
    if c["jobs"] == c["total"]:
        return "the whole grid, charted in whole shards of 486"
    return (
        "whole shards of 486 taken in a fixed random order, so the charted share is a random "
        "sample of the grid's shards"
    )


def charted(table: Path, run: Path) -> dict[str, Any]:
    """What the packed table holds: jobs, rows, converged rows, jobs through six stages per
    orientation, CPU time, the wall time while jobs ran and the table's size."""
    t, meta = read_packed(table)
    df = t.to_pandas()
    jobs = df.groupby("job_id").first()
    six = df.groupby("job_id")["status"].agg(lambda s: bool((s == "converged").all()))
    by_orient = {
        float(o): (int(six.loc[g.index].sum()), len(g)) for o, g in jobs.groupby("orientation_deg")
    }
    cpu = float(jobs["total_cpu_time_s"].sum())
    busy = busy_seconds(jobs["started_at_utc"], jobs["finished_at_utc"])
    return {
        "jobs": len(jobs),
        "total": len(load_run(run).manifest),
        "rows": len(df),
        "converged_rows": int((df["status"] == "converged").sum()),
        "six": by_orient,
        "cpu_h": cpu / 3600,
        "cpu_per_job": cpu / max(len(jobs), 1),
        "wall_h": busy / 3600,
        "bytes": table.stat().st_size,
        "sweep": meta.get("sweep"),
    }


def at_ends(runs: list[tuple[Any, str, float]]) -> dict[str, dict[str, str]]:
    """Per closing load and stage group: the share of converged rows whose along-wound maximum
    lies near the closure zone's ends (`woundsweep.analysis.closures`; with several runs, on
    the jobs they all have); ``jobs`` the number of jobs counted."""
    out: dict[str, dict[str, str]] = {}
    for load, entry in closure_summary(runs).items():
        out[load] = {
            k: f"{100 * g['at_zone_ends']:.0f} % of {g['rows']:,}"
            if g["at_zone_ends"] is not None
            else "n/a"
            for k, g in entry["groups"].items()
        }
        out[load]["jobs"] = f"{entry['jobs']:,}" if entry.get("jobs") is not None else "n/a"
    return out


def figure2_rows(
    own: tuple[Any, str, float], beside: dict[str, tuple[Any, str, float]]
) -> list[tuple[str, dict[str, str]]]:
    """The Figure 2 rows, (label, `at_ends` groups): the run's closure on every charted job,
    then, for each ``--beside`` run (by name), both closures on the jobs the two runs share.
    The runs are `closure_rows` entries, each read once."""
    rows = [(f"{own[1]} closure, every charted job", at_ends([own])[own[1]])]
    for name, other in beside.items():
        pair = at_ends([own, other])
        rows += [(f"{load} closure, the {g['jobs']} jobs of {name}", g) for load, g in pair.items()]
    return rows


def _auc(test: dict[str, Any]) -> str:
    ci = (test.get("auc_macro_interval") or {}).get("ci95")
    band = f" (95 % {ci[0]:.3f}-{ci[1]:.3f} over test geometries)" if ci else ""
    per = [a for a in test["auc_per_quantile"] if a is not None]
    low = f"{min(per):.3f}" if per else "n/a"
    absent = len(test["auc_per_quantile"]) - len(per)
    gone = f" ({absent} classes absent from the test rows)" if absent else ""

    def f(x: float | None) -> str:
        return "n/a" if x is None else f"{x:.3f}"

    return (
        f"macro {f(test['auc_macro'])}{band}, micro {f(test['auc_micro'])},"
        f" lowest class {low}{gone}"
    )


def _stiff(m: dict[str, Any], shape: str) -> str:
    s = m.get("stiff_vs_soft", {}).get(shape) or {}
    if not s.get("pairs"):
        return "no stiff/soft pairs charted"
    return (
        f"{100 * s['fraction_stiff_greater']:.1f} % ({s['stiff_greater']:,}/{s['pairs']:,}),"
        f" p {p_text(s['sign_test_p'], relation=True)}"
    )


def stiff_beside(beside: dict[str, tuple[Any, str, float]]) -> list[str]:
    """Table rows: stiff > soft per shape under each ``--beside`` run's closing load, over its
    converged rows with a stress (reopened or not, as the paper counted), paired as the
    analysis pairs them (same geometry, orientation and stage)."""
    lines = []
    for name, (rows, load, _) in beside.items():
        rows = rows[rows[STRESS] > 0]
        svs, _ = stiff_vs_soft(rows)
        jobs = rows["job_id"].nunique()
        for shape, label in (("cylindrical", "curved wounds"), ("wedge", "wedges")):
            lines.append(
                f"| stiff > soft, {label} ({load} closure, the {jobs:,} jobs of {name})"
                f" | {PAPER[shape]} | {_stiff({'stiff_vs_soft': svs}, shape)} |"
            )
    return lines


def _ranking(names: list[str], n: int = 4) -> str:
    return ", ".join(names[:n]) if names else "n/a"


def _coverage(cov: dict[str, Any]) -> str:
    """Coverage at 80 % / 95 %, each with its counts and, where computed, its bootstrap
    interval over the tested geometries."""

    def one(level: str) -> str:
        c = cov.get(level)
        if not c:
            return "n/a"
        ci = c.get("interval")
        band = f"; {100 * c['interval_level']:g} % {ci[0]:.3f}-{ci[1]:.3f}" if ci else ""
        return f"{c['empirical']:.3f} ({c['covered']:,}/{c['rows']:,}{band})"

    return f"{one('0.8')} / {one('0.95')}"


def _errors(r: dict[str, Any]) -> str:
    """A median relative error and a mean offset (`offgrid.offset_text`) as ``2.0 %, -1.9 %``."""
    off = offset_text(r).replace("%", " %")
    return f"{100 * r['median_relative_error']:.1f} %, mean offset {off}"


def _cross(m: dict[str, Any]) -> list[str]:
    """The rows of the cross-calibration by run: each fold, then the folds pooled."""
    x = m["off_grid_cross_calibration"]
    lines = [
        f"| surrogate off the grid: coverage at 80 % / 95 %, {f['test_run']} (calibrated on"
        f" {', '.join(f['calibrated_on'])}) | none | {_coverage(f['coverage'])},"
        f" {f['geometries']} geometries; median error {_errors(f)} |"
        for f in x["folds"]
    ]
    p = x["pooled"]
    runs = "both runs" if len(x["runs"]) == 2 else f"all {len(x['runs'])} runs"
    lines += [
        "| surrogate off the grid: coverage at 80 % / 95 %, folds pooled (the model's"
        f" intervals: calibrated on {runs} pooled) | none |"
        f" {_coverage(p['coverage'])}, {p['geometries']} geometries |",
        f"| surrogate off the grid, calibration runs: median error, mean offset | none | {_errors(p)} |",
    ]
    return lines


def _off_grid(m: dict[str, Any]) -> list[str]:
    t = m.get("off_grid_test")
    lines = _cross(m) if m.get("off_grid_cross_calibration") else []
    if not t:
        return lines or ["| surrogate off the grid (`--test-on`) | none | not measured |"]
    q = t["quantile_classes"]
    return lines + [
        f"| surrogate off the grid: coverage at 80 % / 95 %, {t['run']} | none |"
        f" {_coverage(t['coverage'])}, {t['rows']:,} rows of {t['geometries']} geometries never"
        " fitted or calibrated on |",
        f"| surrogate off the grid, {t['run']}: median error, mean offset | none | {_errors(t)} |",
        "| surrogate off the grid: quantile class exact / within one (geometry split's edges) |"
        f" none | {q['geometry']['surrogate_accuracy']:.2f} / {q['geometry']['surrogate_within_one']:.2f}"
        f" (classifier {q['geometry']['classifier_accuracy']:.2f} /"
        f" {q['geometry']['classifier_within_one']:.2f}) |",
    ]


def table(
    c: dict[str, Any],
    m: dict[str, Any],
    ends: list[tuple[str, dict[str, str]]],
    stiff_rows: Sequence[str] = (),
) -> str:
    """The side-by-side table, one row per result of the paper and what the project adds."""
    rows = m["rows"]
    rnd, geo = m["schemes"].get("random", {}), m["schemes"].get("geometry", {})
    sur = m.get("surrogate", {})
    sens = sur.get("sensitivity", {})
    six = ", ".join(f"{o:g} deg {a:,}/{b:,}" for o, (a, b) in sorted(c["six"].items()))
    split = rnd.get("split_rows", {})
    imp = rnd.get("importance", {})
    mesh = m.get("mesh_sensitivity", {}).get("importance", {}).get("surrogate_sobol_total")
    lines = [
        "| | paper | ours |",
        "|---|---|---|",
        f"| jobs x stages | {PAPER['rows']} | {c['jobs']:,} x 6 = {c['rows']:,}"
        f" ({_pct(c['jobs'], c['total'])} of the grid) |",
        f"| converged stage results | {PAPER['converged']} | {c['converged_rows']:,}"
        f" ({_pct(c['converged_rows'], c['rows'])}); jobs through six stages: {six} |",
        f"| stiff > soft, curved wounds (sign test) | {PAPER['cylindrical']} |"
        f" {_stiff(m, 'cylindrical')} |",
        f"| stiff > soft, wedges (sign test) | {PAPER['wedge']} | {_stiff(m, 'wedge')} |",
        *stiff_rows,
        f"| rows modelled | {PAPER['modelled']} | {rows['used_rows']:,}"
        f" ({rows.get('duplicate_rows', 0):,} repeating an earlier stage's state left out;"
        f" {rows.get('interpenetrating_rows', 0):,} with flanks inside each other kept) |",
        f"| split train / validation / test (random) | {PAPER['split']} |"
        f" {split.get('train', 0):,} / {split.get('validation', 0):,} / {split.get('test', 0):,} |",
    ]
    if rnd:
        lines.append(f"| AUC, random split | {PAPER['auc']} | {_auc(rnd['test'])} |")
    if geo:
        lines.append(
            f"| AUC, geometry split (unseen geometries) | not done | {_auc(geo['test'])} |"
        )
    lines += [
        f"| most important: split count (the paper's measure) | {PAPER['split_count']} |"
        f" {_ranking(imp.get('ranking_weight', []))} |",
        f"| most important: total gain | not given | {_ranking(imp.get('ranking_total_gain', []))} |",
        "| most important: Sobol total index of the surrogate | not done |"
        f" {_ranking(sens.get('ranking_total', []))} |",
    ]
    for label, groups in ends:
        lines.append(
            f"| Figure 2, along-wound maximum at the zone's ends ({label}):"
            f" stage 2; stages 3-6 | {PAPER['along']} |"
            f" {groups.get('stage 2', 'n/a')}; {groups.get('stages 3-6', 'n/a')} |"
        )
    lines += [
        "| surrogate interval coverage at 80 % / 95 %, held-out grid geometries | none |"
        f" {_coverage(sur.get('test', {}).get('coverage', {}))} ({sur.get('surrogate', 'trees')}) |",
        *_off_grid(m),
        f"| failure model | none | {m.get('failure', {}).get('statement', 'trained')} |",
        "| mesh factor's share of the Sobol total | not done |"
        + (
            f" {100 * mesh['share']:.2f} % (rank {mesh['rank']} of {mesh['of']}) |"
            if mesh
            else " n/a |"
        ),
    ]
    return "\n".join(lines)


def _other_runs(m: dict[str, Any]) -> list[tuple[str, str | None]]:
    """(placeholder, run directory) of each ``--calibrate-on`` and ``--test-on`` run; None
    where metrics.json does not name it (one calibration run)."""
    x = m.get("off_grid_cross_calibration")
    cal: list[str | None] = list(x["runs"]) if x else []
    if not cal and "off the grid" in m.get("surrogate", {}).get("calibration", ""):
        cal = [None]
    t = m.get("off_grid_test") or {}
    test = [r["run"] for r in t.get("by_run", [])] or ([t["run"]] if t.get("run") else [])
    return [(f"CAL{i + 1}", r) for i, r in enumerate(cal)] + [
        (f"TEST{i + 1}", r) for i, r in enumerate(test)
    ]


def analyze_command(m: dict[str, Any], beside: Sequence[Path] = ()) -> str:
    """The `woundsweep analyze` call that wrote ``metrics.json`` (its non-default parts), with
    a ``--beside BESIDEi`` for each run of another closing load."""
    parts = ["woundsweep analyze RUN"]
    if m.get("settings", {}).get("surrogate", "trees") != "trees":
        parts.append(f"--param surrogate={m['settings']['surrogate']}")
    for name, _ in _other_runs(m):
        parts.append(f"--{'calibrate' if name.startswith('CAL') else 'test'}-on {name}")
    parts += [f"--beside BESIDE{i + 1}" for i in range(len(beside))]
    return " ".join(parts)


def _sweep_name(run: str) -> str:
    try:
        return load_run(run).sweep.name
    except (OSError, StoreError, SweepError):  # a run not on this machine: its folder's name
        return Path(run).name


def off_grid_runs(m: dict[str, Any], beside: Sequence[Path] = ()) -> str:
    """What each placeholder of `analyze_command` stands for: a run of a sweep with its kept
    table unpacked into it."""
    named = [(k, _sweep_name(r)) for k, r in _other_runs(m) if r is not None]
    named += [(f"BESIDE{i + 1}", _sweep_name(str(b))) for i, b in enumerate(beside)]
    if not named:
        return ""
    each = "; ".join(f"{k}: `sweeps/{n}.yaml`, `charted/{n}.parquet`" for k, n in named)
    return f" The other runs are runs of a sweep with its kept table unpacked into them ({each})."


def commands(timings: Path, c: dict[str, Any]) -> str:
    """The section of the whole run's commands: each one's wall time, CPU time and peak
    memory (`scripts/atlas_build.py`'s ``timings.json``), the kept table's size and the
    shipped models'."""

    def row(t: dict[str, Any]) -> str:
        note = f" ({t['note']})" if t.get("note") else ""
        return (
            f"| `woundsweep {t['command']}`{note} | {t['wall_s']:.1f} | {t['cpu_s']:.1f} |"
            f" {t['peak_memory_MB']:,} |"
        )

    rows = "\n".join(row(t) for t in json.loads(timings.read_text()))
    models = models_dir()
    size = sum(p.stat().st_size for p in models.iterdir() if p.is_file())
    jobs = read_record(models)["jobs"]
    return f"""
## The whole run's commands

On the run of the {c["jobs"]:,} charted jobs, timed as this page was built (`make atlas-page`:
`scripts/atlas_build.py`; two cores; the CPU time includes the command's child processes):

| command | wall (s) | CPU (s) | peak memory (MB) |
|---|---|---|---|
{rows}

The kept table is {c["bytes"] / 1e6:.2f} MB; the shipped models (`woundsweep/models/`, `make
models`) are {size / 1e6:.2f} MB, trained on {jobs:,} jobs. The table keeps no fields, so
`atlas` draws no 3D view here (each job page says so); on a run that stores them (`run
--fields final`) `--views` draws the chosen jobs', and `make bench-scale` times that on the
whole grid.
"""


def page(
    run: Path, table_path: Path, beside: list[Path], timings: Path | None = None
) -> tuple[str, dict[str, Any]]:
    """The generated part of docs/atlas.md and the charted counts."""
    analysis = run / "analysis"
    m = json.loads((analysis / "metrics.json").read_text())
    c = charted(table_path, run)
    own = closure_rows(run)  # each run's rows read once, for every table row below
    others = {b.name: closure_rows(b) for b in beside}
    load = own[1]
    report = (analysis / "report.md").read_text()
    report = re.sub(r"^# .*\n", "", report)
    report = re.sub(r"\(([\w]+\.(?:png|svg))\)", r"(figures/atlas/\1)", report)
    report = re.sub(r"^## ", "### ", report, flags=re.M)
    text = f"""# The atlas charted

This page is built from {c["jobs"]:,} of the {c["total"]:,} jobs of `sweeps/paper.yaml`
({_pct(c["jobs"], c["total"])}; P2, the `{load}` closure), {_sample(c)}. CPU:
{c["cpu_h"]:.1f} CPU-hours, {c["cpu_per_job"]:.1f} s a job; {c["wall_h"]:.1f} hours of wall time
while jobs ran, on this project's machine (two cores, shared). The results are kept in
`{table_path.as_posix()}` ({c["bytes"] / 1e6:.2f} MB at the time); `make chart` continues from
it, so the table can hold more jobs than the page, which is written anew from it
(`charted/README.md`).

Commands: `make chart`, `make models`, then `make atlas-page` (`scripts/atlas_build.py`), which runs
`woundsweep generate sweeps/paper.yaml --out RUN`, `woundsweep unpack
{table_path.as_posix()} RUN`, `{analyze_command(m, beside)}` (settings in the report below),
then `python scripts/atlas_page.py RUN`.{off_grid_runs(m, beside)}
{commands(timings, c) if timings is not None else ""}
## The paper and ours, row by row

{table(c, m, figure2_rows(own, others), stiff_beside(others))}

Figure 3's panels: A and B `training_random.png`, C `importance_random.png`, D `roc_random.png`.

![Figure 2](figures/atlas/max_location_profiles.png)

![Figure 3A-B](figures/atlas/training_random.png)
![Figure 3C](figures/atlas/importance_random.png)
![Figure 3D](figures/atlas/roc_random.png)

## The analysis report of the charted grid

{report.strip()}
"""
    return text, c


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="the analysed run of the charted table")
    ap.add_argument("--table", type=Path, default=Path("charted/paper.parquet"))
    ap.add_argument("--beside", type=Path, action="append", default=[],
                    help="a run of the same jobs under another closing load (repeatable)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=Path("docs/atlas.md"))
    ap.add_argument("--timings", type=Path, help="scripts/atlas_build.py's timings.json")
    a = ap.parse_args(argv)
    if not (a.run / "analysis" / "metrics.json").is_file():
        print(f"atlas_page: {a.run} has no analysis (run `woundsweep analyze`)", file=sys.stderr)
        return 2
    text, c = page(a.run, a.table, a.beside, a.timings)
    figdir = a.out.parent / "figures" / "atlas"
    figdir.mkdir(parents=True, exist_ok=True)
    for name in FIGURES:
        if (a.run / "analysis" / name).is_file():
            shutil.copyfile(a.run / "analysis" / name, figdir / name)
    old = a.out.read_text() if a.out.exists() else ""
    hand = old[old.index(MARK) :] if MARK in old else f"{MARK}\n"
    tmp = a.out.with_suffix(".md.tmp")
    tmp.write_text(text + "\n" + hand)
    tmp.replace(a.out)
    print(f"{a.out}: {c['jobs']:,} of {c['total']:,} jobs charted; figures in {figdir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

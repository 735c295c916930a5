"""Summarise the closure of one or more run directories side by side, on the jobs all of them
stored (docs/validation.md, "Closing loads side by side").

Usage: python scripts/closure_summary.py RUN [RUN ...] [--fields]

Per run: jobs through six stages by orientation; per stage 2-6 the closed rows, the largest
overlap (fraction of w), the share of rows whose along-wound maximum lies within 0.05 of the
line's length of the closure zone's ends, the median ratio of p99 to stage 2's and of the
wound-local p99 to stage 2's, Newton steps, and the closing traction's range; CPU per job.
With ``--fields`` the closed rows are counted again from the stored displacement fields
(mirror pairs of the zone's surface nodes, read from the fields file, not the columns).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from woundsweep.config.manifest import load_run
from woundsweep.core.layout import RunLayout
from woundsweep.physics.closure import CLOSED_MAX_PER_W, CLOSED_MEDIAN_PER_W
from woundsweep.store.reader import read_results

ENDS_TOL = 0.05  # of the along-wound line's length


def _rows(run_dir: Path) -> tuple[pd.DataFrame, float]:
    run = load_run(run_dir)
    df = read_results(run_dir, run=run)
    return df, float(run.sweep.stages.closure_zone.y_fraction)


def _fields_closed(run_dir: Path, df: pd.DataFrame, y_frac: float) -> dict[int, int]:
    """Closed rows per stage from the stored displacement fields alone: the zone's surface
    edge nodes (z = top, |x - x_c| = w/2, |y - y_c| <= y_fraction L in the reference mesh of
    the fields file) paired across the mid-plane by y; gap = x_R - x_L deformed; closed by
    the module's tolerances on w."""
    closed: dict[int, int] = {}
    root = RunLayout(run_dir).fields_dir
    for _, rows in df.groupby("job_id"):
        first = rows.iloc[0]
        path, mesh_path = root / str(first["fields_file"]), root / str(first["mesh_file"])
        if not path.is_file() or not mesh_path.is_file():
            continue
        with h5py.File(mesh_path, "r") as m:
            X = m["mesh/points"][()]
        w, L = float(first["wound_width_mm"]), float(first["patch_half_length_mm"])
        lo, hi = X.min(axis=0), X.max(axis=0)
        xc, yc = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
        tol = 1e-9 * float(np.ptp(X, axis=0).max())
        edge = (np.abs(X[:, 2] - hi[2]) <= tol) & (np.abs(np.abs(X[:, 0] - xc) - w / 2) <= tol)
        edge &= np.abs(X[:, 1] - yc) <= y_frac * L + tol
        left = np.flatnonzero(edge & (X[:, 0] < xc))
        right = np.flatnonzero(edge & (X[:, 0] > xc))
        by_y = {round(float(X[i, 1]), 9): i for i in right}
        pairs = [
            (i, by_y[round(float(X[i, 1]), 9)]) for i in left if round(float(X[i, 1]), 9) in by_y
        ]
        if not pairs:
            continue
        pl, pr = np.array(pairs).T
        with h5py.File(path, "r") as f:
            for stage in range(2, 7):
                name = f"stage_{stage}/displacement_mm"
                if name not in f:
                    continue
                u = f[name][()]
                gap = (X[pr, 0] + u[pr, 0]) - (X[pl, 0] + u[pl, 0])
                ok = np.median(gap) <= CLOSED_MEDIAN_PER_W * w and gap.max() <= CLOSED_MAX_PER_W * w
                closed[stage] = closed.get(stage, 0) + int(ok)
    return closed


def summarise(run_dir: Path, jobs: set[str], fields: bool) -> None:
    df, y_frac = _rows(run_dir)
    df = df[df["job_id"].isin(jobs)]
    n = df["job_id"].nunique()
    print(f"== {run_dir} ({n} jobs)")
    six = df[(df["stage"] == 6) & (df["status"] == "converged")]
    for angle, g in df[df["stage"] == 1].groupby("orientation_deg"):
        done = six[six["orientation_deg"] == angle]["job_id"].nunique()
        print(f"  through six stages at {angle:g} deg: {done}/{g['job_id'].nunique()}")
    cpu = df.groupby("job_id")["job_cpu_time_s"].first()
    print(f"  CPU per job: mean {cpu.mean():.2f} s, median {cpu.median():.2f} s")
    s2 = df[df["stage"] == 2].set_index("job_id")
    counted = _fields_closed(run_dir, df, y_frac) if fields else {}
    head = (
        "  stage  conv  closed  fields  overlap/w  at-ends  p99/s2  wound/s2  newton  traction kPa"
    )
    print(head)
    for stage in range(1, 7):
        g = df[(df["stage"] == stage) & (df["status"] == "converged")].set_index("job_id")
        if g.empty:
            continue
        L = g["patch_half_length_mm"]
        t = (g["profile_along_wound_max_at_mm"] + L) / (2 * L)
        ends = np.minimum(np.abs(t - (0.5 - y_frac / 2)), np.abs(t - (0.5 + y_frac / 2)))
        at_ends = float((ends <= ENDS_TOL).mean())
        ratio = (g["p99_von_mises_kPa"] / s2["p99_von_mises_kPa"]).dropna()
        wound = "p99_von_mises_wound_kPa"
        wratio = (g[wound] / s2[wound]).dropna() if wound in g else pd.Series([np.nan])
        over = (g["closure_overlap_mm"] / g["wound_width_mm"]).max()
        closed = int(g["closed"].fillna(0).sum()) if stage > 1 else 0
        trac = g["closing_traction_kPa"].dropna() if "closing_traction_kPa" in g else []
        trac_txt = f"{trac.min():.1f}-{trac.max():.1f}" if len(trac) else "-"
        print(
            f"  {stage:>5}  {len(g):>4}  {closed:>6}  {counted.get(stage, '-')!s:>6}"
            f"  {over:>9.4f}  {at_ends:>7.0%}  {ratio.median():>6.3f}  {wratio.median():>8.3f}"
            f"  {g['newton_iterations'].mean():>6.1f}  {trac_txt}"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--fields", action="store_true", help="count closed rows from the fields")
    args = ap.parse_args()
    ids = [set(_rows(r)[0]["job_id"]) for r in args.runs]
    common = set.intersection(*ids)
    if not common:
        print("no job stored in every run", file=sys.stderr)
        return 1
    for r in args.runs:
        summarise(r, common, args.fields)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Mesh convergence of p99 on a benchmark set of paper geometries (`woundsweep converge`).

Usage::

    python benchmarks/convergence.py RUN_DIR [--jobs 1953,7786] [--factors 0.3,0.5,...,1.4]
                                             [--workers 2]

RUN_DIR is a run generated from sweeps/paper.yaml (``woundsweep generate sweeps/paper.yaml
--out RUN_DIR``, whose solver uses P2). The default jobs are fourteen paper geometries of
normal skin with t_d = 1 mm and f_s = 1 (T = 2 mm): a cylinder (a = 0.1) and a wedge (f_d =
0.5) of the smallest and of the largest patch (patch factors 1 and 3, f_w = 0.3; 1953, 1954,
2358, 7785, 7786, 8191), a cylinder and a wedge of patch factor 2 and f_w = 0.5 (L = 4 mm,
w = 2 mm; 2304, 2305, 8136, 8137), and the widest wedges (f_w = 0.8, w = 1.6 mm), deep
(f_d = 0.7, into the subcutis; 7983, 7984) and shallow (f_d = 0.3; 7965, 7966), each at
0 and 45 degrees.
Each job is solved with ``woundsweep converge RUN_DIR --job N --factors ...`` (its JSON and
figure land under RUN_DIR/convergence/), ``--workers`` jobs at once. The default levels are
the paper's factors and three finer ones (element sizes 1.19 to 0.63 of the reference): the
meshes are not nested, so the values scatter about the
error's law, and the least-squares fit over the six levels
(`woundsweep.studies.gci.fit_study`) separates the trend from the scatter. The summary prints,
per job and stage, p99 at each level, then the fit: its limit f0, the largest deviation of
the paper's factors (0.3, 0.5, 0.7) from it, their spread (max - min) / mean, the order p,
the standard deviation sigma (* when it is not below the data range: no trend above the
scatter) and the form; then the stage-2 closure force the same way. It counts the stages 1,
2 and 4-6 within 5 % of f0 at the paper's factors, those also with a monotone fit that the
scatter does not swamp, and those with a spread within 5 %. With three levels the finest
triple's Richardson extrapolation replaces the fit. Not part of ``make bench``: with P2 it
takes about ten minutes on two cores.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from woundsweep.studies.convergence import analyse_levels  # noqa: E402

__all__ = ["main"]

JOBS = (1953, 1954, 2304, 2305, 2358, 7785, 7786, 7965, 7966, 7983, 7984, 8136, 8137, 8191)
FACTORS = "0.3,0.5,0.7,1,1.4,2"
PAPER_FACTORS = (0.3, 0.5, 0.7)
TOLERANCE = 0.05
JUDGED_STAGES = ("1", "2", "4", "5", "6")


def _f(v: float | None, spec: str = ".2f") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def summary(
    study: dict, quantity: str, stages: tuple[str, ...]
) -> list[tuple[str, bool, bool, bool, str]]:
    """(stage, paper factors within tolerance of the limit, and also with a monotone fit the
    scatter does not swamp, spread within tolerance, printed line) per stage that has
    ``quantity``. The limit is the least-squares fit's with four or more levels, else the
    finest triple's Richardson extrapolation; the spread is (max - min) / mean at the paper's
    factors."""
    levels = study["levels"]
    paper = [i for i, lv in enumerate(levels) if lv["mesh_size_factor"] in PAPER_FACTORS]
    fitted = bool(study.get("fits"))
    rows = []
    for stage in stages:
        if quantity not in study["studies"].get(stage, {}):
            continue
        if fitted:
            fin = study["fits"][stage][quantity]
            devs = study["fit_deviations"][stage][quantity]
            trend = fin["kind"] == "monotone"
            sigma = fin["sigma"]
            form = f"{fin['kind']} {fin['fit']}".strip()
        else:
            fin = study["studies"][stage][quantity][-1]
            devs = study["deviations"][stage][quantity]
            trend, sigma, form = fin["kind"] == "monotone", None, fin["kind"]
        worst = max((abs(devs[i]) for i in paper if devs[i] is not None), default=None)
        # A paper factor whose stage did not converge is not within tolerance.
        missing = any(devs[i] is None for i in paper)
        close = not missing and worst is not None and worst <= TOLERANCE
        vals = [levels[i]["stages"][stage][quantity] for i in paper]
        spread = None
        if vals and all(v is not None for v in vals):
            spread = (max(vals) - min(vals)) / abs(sum(vals) / len(vals))
        values = " ".join(f"{_f(lv['stages'][stage][quantity]):>6}" for lv in levels)
        mark = "*" if fitted and fin["scattered"] else " "
        line = (
            f"{study['job_index']:>6} {stage:>5} {values} {_f(fin['extrapolated']):>6} "
            f"{_f(None if worst is None else 100 * worst, '.1f'):>6} "
            f"{_f(None if spread is None else 100 * spread, '.1f'):>8} "
            f"{_f(fin['order']):>5} {_f(sigma, '.3f'):>6}{mark} {form}"
        )
        rows.append(
            (stage, close, close and trend, spread is not None and spread <= TOLERANCE, line)
        )
    return rows


def _converge(run_dir: Path, job: int, factors: str) -> int:
    """``woundsweep converge`` of one job in its own process (its output to
    RUN_DIR/convergence/job_N.log)."""
    log = run_dir / "convergence" / f"job_{job}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "woundsweep", "converge", str(run_dir), "--job", str(job)]
    with log.open("w") as out:
        return subprocess.call([*cmd, "--factors", factors], stdout=out, stderr=out, cwd=ROOT)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--jobs", default=",".join(map(str, JOBS)))
    ap.add_argument("--factors", default=FACTORS)
    ap.add_argument(
        "--summary-only",
        action="store_true",
        help="summarise the stored studies (their levels' values), solve nothing",
    )
    ap.add_argument("--workers", type=int, default=1, help="jobs solved at once")
    args = ap.parse_args(argv)
    jobs = [int(j) for j in args.jobs.split(",")]
    if not args.summary_only:
        with ThreadPoolExecutor(max(1, args.workers)) as pool:
            codes = list(pool.map(lambda j: _converge(args.run_dir, j, args.factors), jobs))
        failed = [j for j, c in zip(jobs, codes) if c != 0]
        if failed:
            print(f"jobs {failed}: woundsweep converge failed", file=sys.stderr)
            return 1
    studies = []
    for job in jobs:
        path = args.run_dir / "convergence" / f"job_{job}.json"
        study = json.loads(path.read_text())
        study.update(analyse_levels(study["levels"]))  # the current estimators
        studies.append(study)
    levels = [lv["mesh_size_factor"] for lv in studies[0]["levels"]]
    factors = " ".join(f"{'m=' + format(f, 'g'):>6}" for f in levels)
    head = (
        f"{'job':>6} {'stage':>5} {factors} {'f0':>6} {'dev %':>6} {'spread %':>8} "
        f"{'p':>5} {'sigma':>6}  form"
    )
    print(
        "\np99 von Mises (kPa); f0 the limit, dev = largest |f - f0| / f0 and spread = "
        "(max - min) / mean at m = 0.3, 0.5, 0.7; * sigma not below the data range"
    )
    print(head)
    close = trend = tight = total = 0
    good: list[int] = []  # geometries with every judged stage within tolerance
    for study in studies:
        stages = ("1", "2", "3", "4", "5", "6")
        all_ok = True
        for stage, ok, ok_trend, ok_spread, line in summary(study, "p99_von_mises_kPa", stages):
            print(line)
            if stage in JUDGED_STAGES:
                close, trend, tight = close + ok, trend + ok_trend, tight + ok_spread
                total += 1
                all_ok = all_ok and ok
        if all_ok:
            good.append(study["job_index"])
    print("\nstage-2 closure force of the left flank (mN)")
    print(head)
    for study in studies:
        for *_, line in summary(study, "closure_force_left_mN", ("2",)):
            print(line)
    tol = f"{100 * TOLERANCE:g} %"
    print(
        f"\nstages 1, 2, 4-6 at m = 0.3, 0.5, 0.7: within {tol} of f0: {close} of {total}; "
        f"and with a monotone fit above the scatter: {trend} of {total}; "
        f"spread within {tol}: {tight} of {total}"
    )
    print(
        f"geometries with every stage 1, 2, 4-6 within {tol} of f0 at the paper's factors: "
        f"{len(good)} of {len(studies)} ({', '.join(map(str, good))})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

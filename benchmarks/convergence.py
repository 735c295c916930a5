"""Mesh convergence of p99 on a benchmark set of paper geometries (`woundsweep converge`).

Usage::

    python benchmarks/convergence.py RUN_DIR [--jobs 1953,7786] [--factors 0.3,0.5,0.7]

RUN_DIR is a run generated from sweeps/paper.yaml (``woundsweep generate sweeps/paper.yaml
--out RUN_DIR``, whose solver uses P2). The default jobs are six paper geometries: both
shapes, the smallest and the largest patch (patch factors 1 and 3), 0 and 45 degrees, with
t_d = 1 mm, f_s = 1, f_w = 0.3, normal skin (cylinders a = 0.1, wedges f_d = 0.5). Each job
is solved with ``woundsweep converge RUN_DIR --job N --factors ...`` (its JSON and figure
land under RUN_DIR/convergence/; with P2 one to three minutes per job on one core at the paper's three
factors, most of it the finest level). The summary prints, per job
and stage, p99 at each level, the finest triple's extrapolated value, the largest deviation
of the paper's factors (0.3, 0.5, 0.7) from it, their spread (max - min) / mean, the kind
of convergence and the observed order, then the stage-2 closure force the same way, and
counts the stages 1, 2 and 4-6 within 5 % with monotone convergence, and with a spread
within 5 %. Not part of ``make bench`` (it takes about a quarter of an hour).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from woundsweep.cli import main as woundsweep  # noqa: E402

__all__ = ["main"]

JOBS = (1953, 1954, 2358, 7785, 7786, 8191)
FACTORS = "0.3,0.5,0.7"
PAPER_FACTORS = (0.3, 0.5, 0.7)
TOLERANCE = 0.05
JUDGED_STAGES = ("1", "2", "4", "5", "6")


def _f(v: float | None, spec: str = ".2f") -> str:
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def summary(
    study: dict, quantity: str, stages: tuple[str, ...]
) -> list[tuple[str, bool, bool, str]]:
    """(stage, within tolerance of f_ext and monotone, spread within tolerance, printed line)
    per stage that has ``quantity``; the spread is (max - min) / mean at the paper's factors."""
    levels = study["levels"]
    paper = [i for i, lv in enumerate(levels) if lv["mesh_size_factor"] in PAPER_FACTORS]
    rows = []
    for stage in stages:
        per_q = study["studies"].get(stage, {})
        if quantity not in per_q:
            continue
        fin = per_q[quantity][-1]
        devs = study["deviations"][stage][quantity]
        worst = max((abs(devs[i]) for i in paper if devs[i] is not None), default=None)
        ok = fin["kind"] == "monotone" and worst is not None and worst <= TOLERANCE
        vals = [levels[i]["stages"][stage][quantity] for i in paper]
        spread = None
        if vals and all(v is not None for v in vals):
            spread = (max(vals) - min(vals)) / abs(sum(vals) / len(vals))
        values = " ".join(f"{_f(lv['stages'][stage][quantity]):>7}" for lv in levels)
        line = (
            f"{study['job_index']:>6} {stage:>5} {values} {_f(fin['extrapolated']):>7} "
            f"{_f(None if worst is None else 100 * worst, '.1f'):>6} "
            f"{_f(None if spread is None else 100 * spread, '.1f'):>8} "
            f"{fin['kind']:<11} {_f(fin['order']):>5} {'yes' if ok else 'no'}"
        )
        rows.append((stage, ok, spread is not None and spread <= TOLERANCE, line))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--jobs", default=",".join(map(str, JOBS)))
    ap.add_argument("--factors", default=FACTORS)
    ap.add_argument(
        "--summary-only", action="store_true", help="summarise the stored studies, solve nothing"
    )
    args = ap.parse_args(argv)
    jobs = [int(j) for j in args.jobs.split(",")]
    studies = []
    for job in jobs:
        cmd = ["converge", str(args.run_dir), "--job", str(job), "--factors", args.factors]
        if not args.summary_only and woundsweep(cmd) != 0:
            print(f"job {job}: woundsweep converge failed", file=sys.stderr)
            return 1
        path = args.run_dir / "convergence" / f"job_{job}.json"
        studies.append(json.loads(path.read_text()))
    levels = [lv["mesh_size_factor"] for lv in studies[0]["levels"]]
    factors = " ".join(f"{'m=' + format(f, 'g'):>7}" for f in levels)
    head = (
        f"{'job':>6} {'stage':>5} {factors} {'f_ext':>7} {'dev %':>6} {'spread %':>8} "
        f"{'kind':<11} {'p':>5} ok"
    )
    print(
        "\np99 von Mises (kPa); dev = largest |f - f_ext| / f_ext and spread = (max - min) / "
        "mean at m = 0.3, 0.5, 0.7"
    )
    print(head)
    passed = close = total = 0
    for study in studies:
        stages = ("1", "2", "3", "4", "5", "6")
        for stage, ok, tight, line in summary(study, "p99_von_mises_kPa", stages):
            print(line)
            if stage in JUDGED_STAGES:
                passed, close, total = passed + ok, close + tight, total + 1
    print("\nstage-2 closure force of the left flank (mN)")
    print(head)
    for study in studies:
        for _stage, _ok, _tight, line in summary(study, "closure_force_left_mN", ("2",)):
            print(line)
    tol = f"{100 * TOLERANCE:g} %"
    print(
        f"\nstages 1, 2, 4-6: within {tol} of f_ext at m = 0.3, 0.5, 0.7 with monotone "
        f"convergence: {passed} of {total}; spread within {tol}: {close} of {total}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The angle study of the clinical case: closing force and peak suture force against the angle
between the excision's long axis and the Langer line, for the three skin types.

Usage::

    python benchmarks/angle_study.py OUT_DIR [--angles 0,15,...,90] [-- CASE FLAGS]

Runs `woundsweep case` (the 2 cm upper-back ellipse of the paper's question, P2 at mesh size
factor 0.18, six sutures; no evened placement and no comparison) at each angle and skin type,
each into ``OUT_DIR/<skin>-<angle>``, then writes ``OUT_DIR/angle_study.csv`` and
``OUT_DIR/angle_study.png`` and prints the table. With ``--aspects 2.5,3,4`` it also solves
the same 2 cm ellipse of normal skin along the Langer line at those length-to-width ratios
(``OUT_DIR/aspect-<ratio>``) and prints the dog-ear height against the ratio
(``OUT_DIR/aspect_study.csv``). About half a minute per case on one core. With ``-- --threads``
the table adds each case's peak and end thread tensions (`woundsweep case --threads`).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

__all__ = ["main"]

SKINS = ("soft", "normal", "stiff")
WS = [sys.executable, "-m", "woundsweep"]


def _thread_columns(case: dict[str, Any]) -> dict[str, Any]:
    """With ``--threads`` among the case flags: the threads' tensions (mN), peak and ends."""
    th = case.get("threads")
    if not th:
        return {}
    t = th["tension_mN"]
    return {
        "peak_thread_tension_mN": max(t),
        "end_thread_tension_mN": min(t[0], t[-1]),
        "thread_status": th["status"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--angles", default="0,15,30,45,60,75,90")
    parser.add_argument("--skins", default=",".join(SKINS), help="skin types, e.g. normal")
    parser.add_argument("--aspects", default="", help="length / width ratios, e.g. 2.5,3,4")
    parser.add_argument("extra", nargs="*", help="further `woundsweep case` flags")
    args = parser.parse_args(argv)
    angles = [float(a) for a in args.angles.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for skin in args.skins.split(","):
        for angle in angles:
            out = args.out / f"{skin}-{angle:g}"
            case = _case(out, ["--angle-deg", f"{angle:g}", "--skin", skin, *args.extra])
            if case is None:
                continue
            forces = case["suture_force_mN"]
            rows.append(
                {
                    "skin_type": skin,
                    "angle_to_langer_deg": angle,
                    "closing_force_mN": case["closing_force_mN"],
                    "suture_force_sum_mN": sum(forces),
                    "peak_suture_force_mN": max(forces),
                    "end_suture_force_mN": min(forces[0], forces[-1]),
                    "dog_ear_height_mm": case["dog_ear_height_mm"],
                    "closed": case["closed"],
                    **_thread_columns(case),
                }
            )
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    df = pd.DataFrame(rows)
    df.to_csv(args.out / "angle_study.csv", index=False)
    print(df.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharex=True)
    for skin, g in df.groupby("skin_type"):
        axes[0].plot(g["angle_to_langer_deg"], g["closing_force_mN"], "o-", label=skin)
        axes[1].plot(g["angle_to_langer_deg"], g["peak_suture_force_mN"], "o-", label=skin)
    axes[0].set_ylabel("closing force (mN)")
    axes[1].set_ylabel("peak suture force (mN)")
    for ax in axes:
        ax.set_xlabel("angle of the long axis to the Langer line (deg)")
        ax.set_xticks(angles)
        ax.grid(alpha=0.3)
    axes[0].legend(title="skin")
    fig.suptitle("2 cm ellipse (3:1), upper back, six sutures, P2")
    fig.tight_layout()
    fig.savefig(args.out / "angle_study.png", dpi=120)
    aspects = [float(a) for a in args.aspects.split(",") if a]
    rows = []
    for ratio in aspects:
        width = 20.0 / ratio
        flags = ["--width-mm", f"{width:.6g}", "--angle-deg", "0", "--skin", "normal", *args.extra]
        case = _case(args.out / f"aspect-{ratio:g}", flags)
        if case is not None:
            forces = case["suture_force_mN"]
            rows.append(
                {
                    "length_to_width": ratio,
                    "width_mm": width,
                    "sutures": len(forces),
                    "closing_force_mN": case["closing_force_mN"],
                    "peak_suture_force_mN": max(forces),
                    "dog_ear_height_mm": case["dog_ear_height_mm"],
                }
            )
    if rows:
        df = pd.DataFrame(rows)
        df.to_csv(args.out / "aspect_study.csv", index=False)
        print(df.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    return 0


# The study reads the forces and the closure only: the report's other solves are skipped.
_ONLY_FORCES = ["--no-even", "--no-compare", "--no-band", "--no-scan", "--no-mesh-check"]


def _case(out: Path, flags: list[str]) -> dict[str, Any] | None:
    """``woundsweep case`` into ``out`` (kept: a rerun reads it) and its case.json."""
    if not (out / "case.json").is_file():
        cmd = [*WS, "case", "--out", str(out), *_ONLY_FORCES, *flags]
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0:
            print(f"{out.name}: {res.stderr.strip()}", file=sys.stderr)
            return None
    return json.loads((out / "case.json").read_text())


if __name__ == "__main__":
    raise SystemExit(main())

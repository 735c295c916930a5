"""The sutures' threads on the small test wound over three meshes at a fixed anchor radius:
apposition forces, the tensions tied at apposition, the knot tension T* of the tying rule
and the knots' draw (docs/validation.md, "Sutures as threads", Mesh).

Usage::

    python benchmarks/thread_mesh.py [--degree 1|2] [--factors 0.3,0.6,1.2]

The wound of `tests/physics/test_threads.py` (9 x 3 mm ellipse, three sutures), normal skin
along the Langer line; one line of JSON per mesh, then the change of T* between the last
two. About 2 minutes at P1 and 15 at P2 on one core. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from woundsweep.config.case import OPEN_GAP_mm
from woundsweep.physics.materials import JobMaterials

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "support"))
from small_wound import small_closure  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--degree", type=int, choices=(1, 2), default=2)
    ap.add_argument("--factors", default="0.3,0.6,1.2", help="mesh size factors, coarse first")
    a = ap.parse_args()
    knots = []
    for m in (float(f) for f in a.factors.split(",")):
        sc, case = small_closure(m, a.degree)
        ys = case.sutures.positions(case.length_mm)
        t0 = time.perf_counter()
        sc.close(JobMaterials.table2(case.skin_type, case.orientation_deg), case.orientation_deg)
        appose = sc.apposition_forces(ys)
        tied = sc.thread(case.sutures)
        t_tied = tied.state.suture_force_mN if tied.state is not None else np.full(len(ys), np.nan)
        step = sc.thread(case.sutures, apposed_gap_mm=OPEN_GAP_mm)
        knots.append(sc.knot_tension_mN)
        print(json.dumps({
            "degree": a.degree, "mesh_size_factor": m, "dofs": sc.domain.n_dofs,
            "status": step.status, "apposition_mN": np.round(appose, 2).tolist(),
            "tied_tension_mN": np.round(t_tied, 2).tolist(), "knot_tension_mN": sc.knot_tension_mN,
            "shortening_mm": np.round(sc.shortening_mm, 3).tolist(),
            "closest_approach_mm": np.round(sc.approach_at_sutures(), 4).tolist(),
            "surface_gap_mm": np.round(sc.gaps_at_sutures(), 3).tolist(),
            "time_s": round(time.perf_counter() - t0, 1),
        }), flush=True)  # fmt: skip
    if len(knots) >= 2 and None not in knots[-2:]:
        print(f"T* between the two finest meshes: {abs(knots[-1] / knots[-2] - 1):.1%}")


if __name__ == "__main__":
    main()

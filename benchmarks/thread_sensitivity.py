"""The sutures' threads on the small test wound against the pre-stretch and the skin type:
apposition forces, thread tensions and knot shortenings with the knots tightened until the
edges meet (docs/validation.md, "Sutures as threads").

Usage::

    python benchmarks/thread_sensitivity.py          # about 5 minutes on one core

The wound of `tests/physics/test_threads.py` (9 x 3 mm ellipse, P1 at m = 0.3, three sutures),
normal skin at TSF 1.05, 1.10 and 1.15, then soft and stiff skin at their Table 2 TSF; one
line of JSON per variant. Asserts nothing.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from woundsweep.config.case import OPEN_GAP_mm
from woundsweep.physics.materials import JobMaterials

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "support"))
from small_wound import small_closure  # noqa: E402

VARIANTS = (("normal", 1.05), ("normal", None), ("normal", 1.15), ("soft", None), ("stiff", None))


def main() -> None:
    for skin, tsf in VARIANTS:
        materials = JobMaterials.table2(skin, 90.0)
        if tsf is not None:
            materials = dataclasses.replace(materials, tsf=tsf)
        sc, case = small_closure()  # a new model each: the threads tie it
        ys = case.sutures.positions(case.length_mm)
        t0 = time.perf_counter()
        sc.close(materials, 90.0)
        appose = sc.apposition_forces(ys)
        step = sc.thread(case.sutures, apposed_gap_mm=OPEN_GAP_mm)
        tension = step.state.suture_force_mN if step.state is not None else np.full(len(ys), np.nan)
        print(json.dumps({
            "skin": skin, "tsf": materials.tsf, "status": step.status,
            "apposition_mN": np.round(appose, 1).tolist(),
            "tension_mN": np.round(tension, 1).tolist(),
            "shortening_mm": np.round(sc.shortening_mm, 2).tolist(),
            "time_s": round(time.perf_counter() - t0, 1),
        }), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()

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
import time

import numpy as np

from woundsweep.config.case import ClinicalCase, OPEN_GAP_mm
from woundsweep.config.solver import SolverSettings
from woundsweep.config.sutures import SuturePlan
from woundsweep.mesh.build import build_mesh
from woundsweep.physics.materials import JobMaterials
from woundsweep.physics.sutures import SuturedClosure

VARIANTS = (("normal", 1.05), ("normal", None), ("normal", 1.15), ("soft", None), ("stiff", None))


def main() -> None:
    case = ClinicalCase(
        length_mm=9.0, width_mm=3.0, dermal_thickness_mm=1.5, subcutis_thickness_mm=1.5,
        depth_mm=2.4, sutures=SuturePlan(count=3), mesh_size_factor=0.3, element_degree=1,
    )  # fmt: skip
    spec = case.geometry()
    spec = type(spec)(**{**spec.to_dict(), "patch_half_length_mm": 12.0})
    mesh = build_mesh(spec)
    ys = case.sutures.positions(case.length_mm)
    for skin, tsf in VARIANTS:
        materials = JobMaterials.table2(skin, 90.0)
        if tsf is not None:
            materials = dataclasses.replace(materials, tsf=tsf)
        sc = SuturedClosure(
            mesh, spec.lens(), case.zone_depth_fraction, SolverSettings(element_degree=1)
        )
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

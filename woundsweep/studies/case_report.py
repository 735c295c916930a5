"""The report of one clinical case (`woundsweep case`): report.md (its text: `case_text`),
case.json (the report's numbers) and the figures (`case_figures`; ``view.png``:
`case_view.view_png`, the sutured skin surface around the wound in 3D, its rim and the
threads drawn).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..config.case import OPEN_GAP_mm
from ..core.fsutil import atomic_write
from ..physics.suture_measures import SutureState
from .case import CaseResult, best_evened
from .case_details import mesh_change
from .case_figures import forces_png, wound_png
from .case_text import render
from .case_threads import threads_summary
from .case_verdict import Verdict, verdict
from .case_view import view_png

__all__ = ["write_report"]


def _state(st: SutureState) -> dict[str, Any]:
    return {
        "suture_y_mm": st.suture_y_mm.tolist(),
        "suture_force_mN": st.suture_force_mN.tolist(),
        "gap_max_mm": float(st.gap_mm.max()),
        "closed": bool((st.gap_mm <= OPEN_GAP_mm).all()),
        "dog_ear_height_mm": st.dog_ear_height_mm,
    }


def _summary(result: CaseResult, v: Verdict) -> dict[str, Any]:
    c = result.case
    st = result.sutured
    out: dict[str, Any] = {
        "length_mm": c.length_mm,
        "width_mm": c.width,
        "angle_to_langer_deg": c.angle_deg,
        "dermal_thickness_mm": c.dermis,
        "subcutis_thickness_mm": c.subcutis,
        "depth_mm": c.depth,
        "skin_type": c.skin_type,
        "skin_band": list(c.band),
        "dofs": result.dofs,
        "element_degree": c.element_degree,
        "mesh_size_factor": c.mesh_size_factor,
        "time_s": result.time_s,
        "costs": {k: {"solves": x.solves, "time_s": x.time_s} for k, x in result.costs.items()},
        "closing_force_mN": result.closing_force_mN,
        **_state(st),
        **threads_summary(result),
        "open_gap_mm": v.threshold_mm,
        "open_after_closure": [list(s) for s in v.after_closure],
        "load": {
            "strain": c.itch.strain, "kind": c.itch.kind,
            "to_wound_deg": v.load.to_wound_deg, "to_langer_deg": v.load.to_langer_deg,
        },
        "itch": [None if s.state is None else {"status": s.status, **_state(s.state)} for s in result.itch],
        "holds": v.holds,
        "opens_under_load": v.load.opens,
        "opened_under_load": [list(s) for s in v.load.opened],
        "peak_force_under_load_mN": v.load.peak_force_mN,
        "tear_through_N": v.tear_through_N,
        "margin": v.margin,
        "scan": [
            {"to_wound_deg": s.to_wound_deg, "to_langer_deg": s.to_langer_deg,
             "peak_force_mN": s.peak_force_mN, "opens": s.opens, "completed": s.completed}
            for s in v.scan
        ],
        "band": {
            b.skin_type: {
                "suture_force_mN": b.sutured.suture_force_mN.tolist(),
                "under_load_force_mN": (
                    None if b.loaded is None or b.loaded.last is None
                    else b.loaded.last.suture_force_mN.tolist()
                ),
            }
            for b in result.band
        },
    }  # fmt: skip
    best = best_evened(result)
    if best is not None:
        out["evened_y_mm"] = best.suture_y_mm.tolist()
        out["evened_force_mN"] = best.suture_force_mN.tolist()
    out["evened_rounds"] = [
        {"suture_y_mm": s.suture_y_mm.tolist(), "suture_force_mN": s.suture_force_mN.tolist()}
        for s in result.evened
    ]
    if result.mesh_check is not None:
        d = mesh_change(result)
        out["mesh_check"] = {
            "mesh_size_factor": result.mesh_check.mesh_size_factor,
            "dofs": result.mesh_check.dofs,
            "suture_force_mN": np.asarray(result.mesh_check.suture_force_mN).tolist(),
            "gap_max_mm": result.mesh_check.gap_max_mm,
            "element_size_ratio_at_wound": (
                float(result.mesh_check.h_ratio) if np.isfinite(result.mesh_check.h_ratio) else None
            ),
            "relative_change": None if d is None else d.tolist(),
        }
    if len(result.levels) > 1:
        out["mesh_levels"] = [
            {"mesh_size_factor": lv.mesh_size_factor, "dofs": lv.dofs,
             "suture_force_mN": lv.suture_force_mN.tolist(),
             "dog_ear_height_mm": lv.dog_ear_height_mm}
            for lv in result.levels
        ]  # fmt: skip
    if result.along is not None:
        out["along_langer_force_mN"] = result.along.suture_force_mN.tolist()
        out["along_langer_closing_force_mN"] = result.along_closing_force_mN
        out["along_langer_dog_ear_height_mm"] = result.along.dog_ear_height_mm
    return out


def _view_title(result: CaseResult) -> str:
    c = result.case
    return f"{c.length_mm:g} x {c.width:.3g} mm excision at {c.angle_deg:g} deg to the Langer line"


def write_report(result: CaseResult, out: Path, command: str, pages: tuple[str, ...] = ()) -> Path:
    """Write report.md, case.json and the figures into ``out``; return report.md's path.
    ``pages``: files beside them the report links to (``view.html``)."""
    out.mkdir(parents=True, exist_ok=True)
    v = verdict(result)
    summary = _summary(result, v)
    atomic_write(out / "case.json", lambda tmp: Path(tmp).write_text(json.dumps(summary, indent=1)))
    figs = [forces_png(result, out), wound_png(result, out),
            view_png(result.surface, out, _view_title(result)), *pages]  # fmt: skip
    text = render(result, command, figs, v)
    path = out / "report.md"
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))
    return path

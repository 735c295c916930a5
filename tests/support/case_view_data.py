"""A made-up `woundsweep case --view` result (numpy only, no finite elements): a box of skin
with its top at z = 0, three sutures across x = 0, a rim along x = 0 and two states with
known fields, for the tests of view.html (tests/studies/test_case_view.py and the browser's,
tests/viz/test_viz_case_browser.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from box_mesh import boundary_facets, box_tets

from woundsweep.config.case import ClinicalCase
from woundsweep.config.sutures import SuturePlan
from woundsweep.core.schema import TOP, X_MIN
from woundsweep.studies.case import CaseResult
from woundsweep.studies.case_view import CaseView, ViewState

__all__ = ["FORCES", "SUTURE_Y", "case_result", "displacement", "made_up_view", "write_page"]

SUTURE_Y = np.array([-4.0, 0.0, 4.0])
FORCES = np.array([50.0, 100.0, 60.0])


def displacement(points: np.ndarray, k: int) -> np.ndarray:
    """State k's displacement (mm): the halves pulled toward x = 0, a rise near it."""
    x, y, _ = points.T
    return np.c_[-0.05 * k * x, 0.01 * k * y, 0.2 * k * np.exp(-(x**2) / 4.0)]


def _top(points: np.ndarray, x: float, y: float) -> int:
    top = np.flatnonzero(np.abs(points[:, 2]) < 1e-12)
    return int(top[np.argmin(np.hypot(points[top, 0] - x, points[top, 1] - y))])


def made_up_view() -> CaseView:
    pts, cells = box_tets((6, 8, 2), (-6.0, -8.0, -2.0), (6.0, 8.0, 0.0))
    facets = boundary_facets(cells)
    tags = np.where(np.all(np.abs(pts[facets, 2]) < 1e-12, axis=1), TOP, X_MIN).astype(np.int32)
    bites = np.array([[_top(pts, -4.0, y), _top(pts, 4.0, y)] for y in SUTURE_Y])
    line = sorted(np.flatnonzero((np.abs(pts[:, 0]) < 1e-12) & (np.abs(pts[:, 2]) < 1e-12)),
                  key=lambda i: pts[i, 1])  # fmt: skip
    rim = np.c_[line[:-1], line[1:]]
    mid = pts[cells].mean(axis=1)
    t = np.linspace(0.0, 1.0, 5)
    profile = np.stack([np.c_[t * 12 - 6, 0 * t, 0 * t - 0.5] for _ in range(3)])
    states = [
        ViewState(
            label, displacement(pts, k), 5.0 * k + np.abs(mid[:, 0]), 9.0 * k, 12.0 * k, profile,
            np.stack([t + k, 2 * t + k, 3 * t + k]), SUTURE_Y, FORCES * k,
            np.linspace(-5.0, 5.0, 4), np.full(4, 10.0 * k), np.zeros(4),
        )
        for k, label in ((1, "sutured"), (2, "at the end of the load after closure"))
    ]  # fmt: skip
    return CaseView(pts, cells, np.ones(len(cells), np.int32), facets, tags, 2, bites, rim, states)


def case_result(view: CaseView | None = None) -> CaseResult:
    """A case result with ``view`` and nothing solved (what `write_view` reads)."""
    case = ClinicalCase(length_mm=12.0, angle_deg=25.0, sutures=SuturePlan(count=3))
    return CaseResult(
        case, 1000, 300.0, None, None, [], [], None, None, 10.0, [], None,  # type: ignore[arg-type]
        view=view or made_up_view(),
    )  # fmt: skip


def write_page(out: Path) -> Path:
    """view.html of the made-up case in ``out``."""
    from woundsweep.commands.case import write_view

    out.mkdir(parents=True, exist_ok=True)
    return out / write_view(case_result(), out)

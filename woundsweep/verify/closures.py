"""Known answers of the closing loads (`StageSettings.closure_load`) on demo job 0's cylinder
(t_d = 1, L = 4, a half-round slot of width 1.2 and depth 0.6; its zone |y| <= 4/3 and 0.3
below the surface), P2, normal skin at 45 degrees."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..config.paper import StageSettings
from ..config.solver import SolverSettings
from ..physics.materials import JobMaterials

__all__ = ["code_amplitude_ratio", "solved_median_gap_per_w", "traction_area_ratio"]

WIDTH_mm = 1.2
ZONE_PROJECTED_AREA_mm2 = (2 * 4.0 / 3.0) * 0.3


def _model(closure: str) -> Any:
    from ..config.geometry import GeometrySpec
    from ..mesh.build import build_mesh
    from ..physics.model import WoundModel

    mesh = build_mesh(GeometrySpec.cylindrical(1.0, 1.0, 4.0, WIDTH_mm, 0.0, 0.3))
    return WoundModel(mesh, SolverSettings(element_degree=2), StageSettings(closure_load=closure))


def traction_area_ratio() -> float:
    """A unit closing traction's pull on the left flank over the zone's projected area."""
    from ..physics.closing import dermal_zone_facets, traction_shape
    from ..physics.domain import dof_rows

    d = _model("solved").domain
    f = traction_shape(d, dermal_zone_facets(d))
    return float(f[dof_rows(d.zone_left_nodes, 0)].sum() / ZONE_PROJECTED_AREA_mm2)


def code_amplitude_ratio() -> float:
    """The published code's amplitude at the homogeneous pre-stretched state over 1.3 x 1.4
    times the dermis' P_xx there."""
    from ..physics.closing import code_traction_kPa
    from ..physics.materials import first_piola, homogeneous_state

    m = _model("paper-code")
    materials = JobMaterials.table2("normal", 45.0)
    m.set_materials(materials)
    m.u[:] = m.pretension_state().ravel()
    lam3 = homogeneous_state(materials.dermis, materials.tsf).lambda3
    P = first_piola(materials.dermis, np.diag([materials.tsf, materials.tsf, lam3]))
    return float(code_traction_kPa(m.domain, m.u, materials) / (1.3 * 1.4 * P[0, 0]))


def solved_median_gap_per_w() -> float:
    """|median surface gap| / w after stage 3 of the solved closure (NaN if a stage fails)."""
    from ..physics.job import run_stages

    m = _model("solved")
    recs = run_stages(m, JobMaterials.table2("normal", 45.0), 3)
    r3 = recs[2].result
    if r3.closure_gap_median_mm is None:
        return float("nan")
    return abs(float(r3.closure_gap_median_mm)) / WIDTH_mm

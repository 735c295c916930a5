"""The small test wound of the suture tests and the threads' benchmark: a 9 x 3 mm ellipse,
2.4 mm deep, dermis and subcutis 1.5 mm, three sutures, P1 at mesh size factor 0.3 (unless
given), on a patch 12 mm in half-length."""

from __future__ import annotations

from typing import Any

from woundsweep.config.case import ClinicalCase
from woundsweep.config.sutures import SuturePlan


def small_wound(mesh_size_factor: float = 0.3, element_degree: int = 1) -> tuple[ClinicalCase, Any]:
    """The case and its geometry (`GeometrySpec`, the patch's half-length set to 12 mm)."""
    case = ClinicalCase(
        length_mm=9.0, width_mm=3.0, dermal_thickness_mm=1.5, subcutis_thickness_mm=1.5,
        depth_mm=2.4, sutures=SuturePlan(count=3), mesh_size_factor=mesh_size_factor,
        element_degree=element_degree,
    )  # fmt: skip
    spec = case.geometry()
    return case, type(spec)(**{**spec.to_dict(), "patch_half_length_mm": 12.0})


def small_closure(
    mesh_size_factor: float = 0.3, element_degree: int = 1
) -> tuple[Any, ClinicalCase]:
    """A `SuturedClosure` on the small wound's mesh (not yet closed) and its case."""
    from woundsweep.config.solver import SolverSettings
    from woundsweep.mesh.build import build_mesh
    from woundsweep.physics.sutures import SuturedClosure

    case, spec = small_wound(mesh_size_factor, element_degree)
    solver = SolverSettings(element_degree=element_degree)
    return SuturedClosure(build_mesh(spec), spec.lens(), case.zone_depth_fraction, solver), case

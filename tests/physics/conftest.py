"""Fixtures of the physics tests: `cylinder_mesh` (the coarsest demo cylinder, P1)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def cylinder_mesh():
    """Demo job 0: t_d = 1, subcutis factor 1, L = 4, width 1.2, aspect 0 (depth 0.6), m = 0.3;
    the P1 mesh (its models take ``SolverSettings(element_degree=1)``)."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh

    return build_mesh(GeometrySpec.cylindrical(1.0, 1.0, 4.0, 1.2, 0.0, 0.3, element_degree=1))

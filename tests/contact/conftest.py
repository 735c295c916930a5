"""Fixtures of the contact tests: `squares` (two facing, non-matching triangulated squares),
`cylinder_mesh` (the coarsest demo cylinder, P1; as in tests/physics/conftest.py)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def squares():
    """Two facing unit squares with non-matching triangulations (3 x 3 against 4 x 4)."""
    from contact_surfaces import two_squares

    return two_squares(3, 4)


@pytest.fixture(scope="module")
def cylinder_mesh():
    """Demo job 0: t_d = 1, subcutis factor 1, L = 4, width 1.2, aspect 0 (depth 0.6), m = 0.3;
    the P1 mesh (gmsh only, no DOLFINx)."""
    from woundsweep.config.geometry import GeometrySpec
    from woundsweep.mesh.build import build_mesh

    return build_mesh(GeometrySpec.cylindrical(1.0, 1.0, 4.0, 1.2, 0.0, 0.3, element_degree=1))

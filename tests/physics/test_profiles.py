"""Von Mises line profiles (`woundsweep.physics.profiles`) on a gmsh mesh, without DOLFINx."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from woundsweep.config.geometry import GeometrySpec
from woundsweep.mesh.build import build_mesh
from woundsweep.physics.profiles import (
    PROFILE_POINTS,
    line_maxima,
    locate_cells,
    profile_lines,
    sample_profiles,
)

SPEC = GeometrySpec.wedge(1.0, 1.0, 2.0, 1.0, 0.6, 0.3, element_degree=1)  # L = 2, w = 1, T = 2


@pytest.fixture(scope="module")
def domain() -> SimpleNamespace:
    """The attributes of `WoundDomain` the profiles use, from the mesh arrays."""
    mesh = build_mesh(SPEC)
    X, cells = mesh.points, mesh.cells
    Dm = np.transpose(X[cells][:, 1:, :] - X[cells][:, :1, :], (0, 2, 1))
    return SimpleNamespace(
        X=X, cell_vertices=cells, Dm_inv=np.linalg.inv(Dm), midpoints=X[cells].mean(axis=1)
    )


def test_lines_are_the_papers(domain) -> None:
    pts = profile_lines(domain.X)
    assert pts.shape == (3, PROFILE_POINTS, 3)
    L, w, T = 2.0, 1.0, 2.0
    np.testing.assert_allclose(pts[0, [0, -1]], [[0, -L, 0], [0, L, 0]], atol=1e-12)
    np.testing.assert_allclose(pts[1, [0, -1]], [[0, 0, -T], [0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(pts[2, [0, -1]], [[-L, 0, 0], [L + w, 0, 0]], atol=1e-12)
    assert np.allclose(np.diff(pts[2, :, 0]), (2 * L + w) / (PROFILE_POINTS - 1))


def test_located_cells_hold_their_points(domain) -> None:
    rng = np.random.default_rng(1)
    picks = rng.choice(len(domain.cell_vertices), 50, replace=False)
    assert np.array_equal(locate_cells(domain, domain.midpoints[picks]), picks)
    # Outside the patch and inside the wound opening: no cell.
    outside = np.array([[-3.0, 0.0, -0.5], [0.5, 0.0, -0.05], [0.5, 1.0, -0.2]])
    assert (locate_cells(domain, outside) == -1).all()


def test_sampled_values_come_from_the_cell_at_the_point(domain) -> None:
    pts = profile_lines(domain.X)
    cells = locate_cells(domain, pts.reshape(-1, 3)).reshape(3, -1)
    # A cellwise field equal to the cell's midpoint x: sampled, it is within one cell of x.
    prof = sample_profiles(cells, domain.midpoints[:, 0])
    x = pts[..., 0]
    ok = np.isfinite(prof)
    assert np.nanmax(np.abs(prof - x)[ok]) < 0.5  # cell sizes are below 0.5 mm here
    # Across the patch, exactly the points over the wound opening 0 < x < w have no cell.
    over_wound = (x[2] > 1e-9) & (x[2] < 1.0 - 1e-9)
    assert np.array_equal(~ok[2], over_wound)
    assert ok[0].all() and ok[1].all()


def test_line_maxima_report_value_and_position(domain) -> None:
    pts = profile_lines(domain.X)
    cells = locate_cells(domain, pts.reshape(-1, 3)).reshape(3, -1)
    # Largest where the midpoint is closest to y = 0.7 (line 1) / z = -0.5 (line 2).
    m = domain.midpoints
    vm = 10.0 - np.abs(m[:, 1] - 0.7) - np.abs(m[:, 2] + 0.5)
    out = line_maxima(pts, sample_profiles(cells, vm))
    assert out["profile_along_wound_max_at_mm"] == pytest.approx(0.7, abs=0.3)
    assert out["profile_through_thickness_max_at_mm"] == pytest.approx(-0.5, abs=0.3)
    assert out["profile_along_wound_max_kPa"] == pytest.approx(
        np.nanmax(sample_profiles(cells, vm)[0])
    )
    assert set(out) == {f"profile_{n}_{k}" for n in ("along_wound", "through_thickness",
                        "across_patch") for k in ("max_kPa", "max_at_mm")}  # fmt: skip

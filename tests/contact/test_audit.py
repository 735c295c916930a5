"""The interpenetration audit (woundsweep.contact.audit) on the demo cylinder's P1 mesh.

The wound is a half-cylinder of radius R = w / 2 = 0.6 mm about the line x = x_c, z = 0,
through the whole patch (y in [-4, 4]); the right tissue is r > R, x > x_c. A left-flank node
placed at its mirror image plus 0.3 w along +x is inside the right tissue at the depth
min(r - R, -z) (the distance to the wound surface or to the skin surface), within the
facets' sagitta of the circle.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
import pytest

from woundsweep.contact import split_wound_flanks
from woundsweep.contact.audit import (
    P2_SUB_TETS,
    audit_interpenetration,
    audit_model,
    linear_cells,
)
from woundsweep.core.schema import WOUND_TAGS
from woundsweep.physics.element import EDGES, Element

W_MM, R_MM = 1.2, 0.6


@pytest.fixture(scope="module")
def wound(cylinder_mesh):
    """(X, cells, left_nodes, right_nodes, left_cells, right_cells, x_c, (left, right)) of
    the P1 mesh, the last the flanks' triangles."""
    X = np.asarray(cylinder_mesh.points, dtype=float)
    cells = np.asarray(cylinder_mesh.cells, dtype=np.int64)
    facets = np.asarray(cylinder_mesh.facets, dtype=np.int64)
    wf = facets[np.isin(cylinder_mesh.facet_tags, WOUND_TAGS)]
    wx = X[np.unique(wf), 0]
    x_c = 0.5 * (wx.min() + wx.max())
    left, right = split_wound_flanks(X, cells, wf, x_c)
    is_left = X[cells].mean(axis=1)[:, 0] < x_c
    return (X, cells, np.unique(left), np.unique(right), np.flatnonzero(is_left),
            np.flatnonzero(~is_left), x_c, (left, right))  # fmt: skip


def _audit(wound, u, tol, to_flanks=False):
    X, cells, ln, rn, lc, rc, _, (left, right) = wound
    faces = {"left_faces": left, "right_faces": right} if to_flanks else {}
    return audit_interpenetration(X, u, cells, ln, rn, lc, rc, tol, **faces)


def _mid_flank_nodes(wound, n: int) -> np.ndarray:
    """``n`` left-flank nodes between 30 and 60 degrees down the arc, away from each other."""
    X, _, ln, *_, x_c, _ = wound
    p = X[ln]
    angle = np.degrees(np.arctan2(-p[:, 2], x_c - p[:, 0]))
    pick = ln[(angle > 30) & (angle < 60) & (np.abs(p[:, 1]) < 2.5)]
    pick = pick[np.argsort(X[pick, 1])]
    return pick[np.linspace(0, len(pick) - 1, n).astype(int)]


def test_the_undeformed_wound_has_no_interpenetration(wound) -> None:
    X = wound[0]
    t0 = time.perf_counter()
    res = _audit(wound, np.zeros(X.size), 1e-6)
    assert time.perf_counter() - t0 < 2.0
    assert res.n_inside == 0 and len(res.nodes) == 0
    assert res.max_depth_mm < 1e-9  # only nodes on the other side's surface (shared ones)


def test_a_planted_deep_penetration_is_caught_at_its_depth(wound) -> None:
    X, *_, x_c, _ = wound
    nodes = _mid_flank_nodes(wound, 4)
    target = X[nodes].copy()
    target[:, 0] = 2 * x_c - target[:, 0] + 0.3 * W_MM  # mirror image, then 0.3 w into the tissue
    U = np.zeros_like(X)
    U[nodes] = target - X[nodes]
    res = _audit(wound, U.ravel(), 0.05 * W_MM)
    assert res.n_inside == 4
    np.testing.assert_array_equal(res.nodes, np.sort(nodes))
    expected = np.minimum(np.hypot(target[:, 0] - x_c, target[:, 2]) - R_MM, -target[:, 2])
    assert res.max_depth_mm == pytest.approx(expected.max(), abs=0.02)
    assert 0.2 < res.max_depth_mm < 0.3 * W_MM
    # Measured to the right flank alone: the radial depth r - R.
    res = _audit(wound, U.ravel(), 0.05 * W_MM, to_flanks=True)
    assert res.n_inside == 4
    radial = np.hypot(target[:, 0] - x_c, target[:, 2]) - R_MM
    assert res.max_depth_mm == pytest.approx(radial.max(), abs=0.02)


def test_a_node_past_the_flank_near_the_skin_is_deep_to_the_flank(wound) -> None:
    """Two left-flank nodes planted 0.3 w past the right flank, 0.05 mm below the skin: 0.05
    deep in the right tissue (the skin is near), about 0.3 deep through its flank."""
    X, *_, x_c, _ = wound
    nodes = _mid_flank_nodes(wound, 2)
    target = X[nodes].copy()
    target[:, 0] = x_c + R_MM + 0.3 * W_MM
    target[:, 2] = -0.05
    U = np.zeros_like(X)
    U[nodes] = target - X[nodes]
    res = _audit(wound, U.ravel(), 0.1)
    assert res.n_inside == 0 and res.max_depth_mm == pytest.approx(0.05, abs=1e-9)
    res = _audit(wound, U.ravel(), 0.1, to_flanks=True)
    assert res.n_inside == 2
    assert res.max_depth_mm == pytest.approx(np.hypot(0.3 * W_MM + R_MM, 0.05) - R_MM, abs=0.02)


def test_a_shallow_penetration_is_below_the_tolerance(wound) -> None:
    """A node at its mirror image moved 0.01 mm radially into the right tissue: inside, at a
    depth of about 0.01 mm; not counted at a tolerance of 0.02 mm, counted at 0.005 mm."""
    X, *_, x_c, _ = wound
    nodes = _mid_flank_nodes(wound, 2)
    target = X[nodes].copy()
    target[:, 0] = 2 * x_c - target[:, 0]
    radial = target - np.array([x_c, 0.0, 0.0])
    radial[:, 1] = 0.0
    target += 0.01 * radial / np.linalg.norm(radial, axis=1, keepdims=True)
    U = np.zeros_like(X)
    U[nodes] = target - X[nodes]
    res = _audit(wound, U.ravel(), 0.02)
    assert res.n_inside == 0
    assert 0.005 < res.max_depth_mm <= 0.01 + 1e-12
    assert _audit(wound, U.ravel(), 0.005).n_inside == 2


def test_p2_sub_tets_tile_their_cell() -> None:
    """The eight straight tetrahedra through a P2 cell's nodes fill it: volumes sum to the
    cell's, and random points of the cell lie in exactly one."""
    rng = np.random.default_rng(0)
    V = rng.normal(size=(4, 3))
    mids = np.array([0.5 * (V[a] + V[b]) for a, b in EDGES])
    P = np.vstack([V, mids])
    sub = P[P2_SUB_TETS]

    def vol(t):
        return np.abs(np.linalg.det(t[..., 1:, :] - t[..., :1, :])) / 6.0

    assert vol(sub).sum() == pytest.approx(vol(V), rel=1e-12)
    lam = rng.dirichlet(np.ones(4), size=200)
    pts = lam @ V
    M = np.transpose(sub[:, 1:, :] - sub[:, :1, :], (0, 2, 1))  # (8, 3, 3) edge columns
    b = np.linalg.solve(M[None], (pts[:, None, :] - sub[None, :, 0, :])[..., None])[..., 0]
    inside = (b.min(axis=2) > 0) & (b.sum(axis=2) < 1)
    assert np.all(inside.sum(axis=1) == 1)


def test_audit_model_on_a_p2_model_catches_the_planted_nodes(wound) -> None:
    """`audit_model` on a P2 model-like object (edge midpoints appended as nodes): the same
    planted penetration is caught, the undeformed state is clean."""
    X, cells, _, _, _, _, x_c, flanks = wound
    a, b = cells[:, [e[0] for e in EDGES]], cells[:, [e[1] for e in EDGES]]
    keys = np.minimum(a, b) * len(X) + np.maximum(a, b)
    uniq, inv = np.unique(keys.ravel(), return_inverse=True)
    ea, eb = uniq // len(X), uniq % len(X)
    X2 = np.vstack([X, 0.5 * (X[ea] + X[eb])])
    cell_nodes = np.hstack([cells, len(X) + inv.reshape(-1, 6)])
    assert linear_cells(cell_nodes)[0].shape == (8 * len(cells), 4)
    Dm = np.transpose(X[cells[:, 1:]] - X[cells[:, :1]], (0, 2, 1))
    element = Element(X2, cell_nodes, np.linalg.inv(Dm))
    flanks = tuple(element.sub_triangles(f) for f in flanks)  # as `WoundModel.flanks`
    domain = SimpleNamespace(X=X2, cell_nodes=cell_nodes, midpoints=X[cells].mean(axis=1), x_c=x_c)
    model = SimpleNamespace(domain=domain, flanks=flanks, u=np.zeros(X2.size))
    assert audit_model(model, 1e-6).n_inside == 0
    nodes = _mid_flank_nodes(wound, 3)
    U = np.zeros_like(X2)
    U[nodes, 0] = 2 * (x_c - X[nodes, 0]) + 0.3 * W_MM
    res = audit_model(model, 0.05 * W_MM, U.ravel())
    assert res.n_inside == 3 and res.max_depth_mm > 0.2
    assert audit_model(SimpleNamespace(flanks=None), 0.1).n_inside == 0

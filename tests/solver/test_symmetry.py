"""Newton's steps in the symmetric subspace (`woundsweep.solver.symmetry`): the basis against
the group's averaging operator, the projected solve against the full one, and whole jobs
solved both ways."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from woundsweep.solver.symmetry import Isometry, mirror_node_map, symmetry_basis


def _grid() -> np.ndarray:
    """Nodes of a 3 x 4 x 2 grid, mirror-symmetric about x = 1 and y = 0 (none on y = 0)."""
    xs, ys, zs = (0.0, 1.0, 2.0), (-1.5, -0.5, 0.5, 1.5), (0.0, -1.0)
    return np.array(list(itertools.product(xs, ys, zs)))


def _generators(X: np.ndarray, mirrors: bool) -> list[Isometry]:
    c = np.array([2.0, 0.0, 0.0])
    flips = [np.array([-1.0, 1.0, 1.0]), np.array([1.0, -1.0, 1.0])]
    if not mirrors:
        flips = [flips[0] * flips[1]]
    out = []
    for f in flips:
        nodes = mirror_node_map(X, np.where(f < 0, c - X, X), 1e-12)
        assert nodes is not None
        out.append(Isometry(nodes, f))
    return out


def _dense(g: Isometry) -> np.ndarray:
    """The group element as a dof matrix: (G u)[3 g(i) + k] = s_k u[3 i + k]."""
    n = len(g.nodes)
    G = np.zeros((3 * n, 3 * n))
    for i, k in itertools.product(range(n), range(3)):
        G[3 * g.nodes[i] + k, 3 * i + k] = g.signs[k]
    return G


def _group(gens: list[Isometry]) -> list[np.ndarray]:
    mats = [np.eye(3 * len(gens[0].nodes))]
    for g in gens:
        mats += [_dense(g) @ m for m in mats]
    return mats


@pytest.mark.parametrize("mirrors", [True, False])
def test_basis_spans_the_fixed_fields(mirrors: bool) -> None:
    X = _grid()
    gens = _generators(X, mirrors)
    basis = symmetry_basis(gens)
    P = basis.P.toarray()
    group = _group(gens)
    assert basis.order == len(group) == (4 if mirrors else 2)
    # Every column is fixed by every element, and the columns span the fixed subspace, whose
    # dimension is the trace of the averaging projector.
    for G in group:
        assert np.allclose(G @ P, P)
    Q = sum(group) / len(group)
    assert basis.n_reduced == round(np.trace(Q)) == np.linalg.matrix_rank(P)
    assert np.allclose(Q @ P, P)
    # The nodes on x = 1: u_x vanishes under the mirror (no column holds it); the half-turn
    # moves them to other nodes, so it keeps them.
    on_plane = np.flatnonzero(np.isclose(X[:, 0], 1.0))
    assert np.abs(P[3 * on_plane]).sum() == (0 if mirrors else len(on_plane))


@pytest.mark.parametrize("mirrors", [True, False])
def test_projected_solve_is_the_full_solve(mirrors: bool) -> None:
    """For an equivariant matrix and a symmetric right-hand side, P (P^T A P)^-1 P^T b is the
    full solution A^-1 b."""
    rng = np.random.default_rng(7)
    X = _grid()
    gens = _generators(X, mirrors)
    group = _group(gens)
    n = 3 * len(X)
    B = rng.standard_normal((n, n))
    A = sum(G.T @ (B @ B.T + n * np.eye(n)) @ G for G in group)
    v = rng.standard_normal(n)
    b = sum(G @ v for G in group)
    P = symmetry_basis(gens).P.toarray()
    x = np.linalg.solve(P.T @ A @ P, P.T @ b)
    assert np.allclose(P @ x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)


def test_no_map_without_a_mirror_image() -> None:
    X = _grid()
    X[0, 0] += 0.1
    assert mirror_node_map(X, np.where([True, False, False], 2.0 - X, X), 1e-6) is None


@pytest.mark.fem
@pytest.mark.parametrize("angle", [0.0, 45.0])
def test_a_job_solves_the_same_with_and_without_its_symmetry(deep_wedge_mesh, angle) -> None:
    """The deep wedge through stages 1-6 (contact engaged): the same Newton steps and
    states; the reduced systems hold a quarter (mirrors) or a half (half-turn) of the dofs."""
    from woundsweep.config.solver import SolverSettings
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    mats = JobMaterials.table2("stiff", angle)
    runs = []
    for symmetry in (True, False):
        m = WoundModel(deep_wedge_mesh, SolverSettings(element_degree=1, symmetry=symmetry))
        m.set_materials(mats)
        outs = [run_stage(m, k) for k in range(1, 7)]
        runs.append((m, outs))
    (ms, sym), (mf, full) = runs
    assert [o.solve.status for o in sym] == [o.solve.status for o in full] == ["converged"] * 6
    assert [o.solve.iterations for o in sym] == [o.solve.iterations for o in full]
    scale = np.abs(mf.u).max()
    assert np.abs(ms.u - mf.u).max() <= 1e-7 * scale
    basis = ms.domain.symmetry(angle == 0.0)
    ratio = basis.n_reduced / ms.domain.n_dofs
    assert (0.24 < ratio < 0.3) if angle == 0.0 else (0.49 < ratio < 0.55)
    assert mf.newton._sub is None and ms.newton._sub is not None

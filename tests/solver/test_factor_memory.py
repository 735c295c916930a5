"""Newton's memory over a long solve: each new matrix (a symmetric subspace set again, or a
contact stage's pattern grown) gets a fresh MUMPS factorisation and the old one is freed,
and the PETSc objects a problem drops at each step are freed, so a stage of hundreds of
steps holds what one step needs."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from woundsweep.config.solver import NewtonSettings
from woundsweep.core.schema import StageStatus
from woundsweep.solver.dirichlet import Dirichlet


def _factor_info(newton: Any) -> tuple[int, int]:
    """The current factor's ICNTL(14) and INFOG(22) (MB it holds). The factor's handle must
    not outlive this call: a Python reference keeps a destroyed solver's factorisation."""
    F = newton.ksp.getPC().getFactorMatrix()
    return F.getMumpsIcntl(14), F.getMumpsInfog(22)


def _newton(p: Any, **settings: Any) -> Any:
    """A NewtonSolver on ``p``, its matrix made from ``p.K``'s pattern."""
    from petsc4py import PETSc

    from woundsweep.solver.newton import NewtonSolver

    K = p.K
    A = PETSc.Mat().createAIJ(K.shape, csr=(K.indptr, K.indices, K.data))
    return NewtonSolver(p, A, NewtonSettings(**settings))


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


class _Poisson:
    """R(u) = K u - 1 with K the 7-point Laplacian on an n^3 grid plus the identity: linear
    and SPD, a sparse direct factorisation of tens of MB at n = 22."""

    multipliers = None

    def __init__(self, n: int) -> None:
        import scipy.sparse as sp

        d = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
        eye = sp.identity(n)
        lap = sp.kron(sp.kron(d, eye), eye) + sp.kron(sp.kron(eye, d), eye)
        self.K = (lap + sp.kron(sp.kron(eye, eye), d) + sp.identity(n**3)).tocsr()
        self.u = np.zeros(n**3)

    def solution(self) -> np.ndarray:
        return self.u

    def residual(self, b: Any) -> None:
        b.getArray()[:] = self.K @ self.u - 1.0

    def jacobian(self, A: Any) -> None:
        A.zeroEntries()
        K = self.K
        A.setValuesCSR(K.indptr, K.indices, K.data)
        A.assemble()

    def min_det(self, u: np.ndarray) -> float:
        return 1.0

    def max_strain(self, du: np.ndarray) -> float:
        return 0.0

    def length_scale(self) -> float:
        return 1.0


@pytest.mark.fem
def test_a_new_operator_frees_the_old_factorisation() -> None:
    import scipy.sparse as sp

    from woundsweep.solver.symmetry import SymmetryBasis

    p = _Poisson(22)
    K = p.K
    newton = _newton(p, rtol=0.0, atol=1e-9, stol=1e-12)
    basis = SymmetryBasis(sp.identity(K.shape[0], format="csr"), 1)
    rss, factor_mb = [], []
    for _ in range(10):
        p.u[:] = 0.0
        newton.set_symmetry(basis)  # a new reduced operator P^T A P: a new factorisation
        res = newton.solve(Dirichlet.none())
        assert res.status == StageStatus.CONVERGED
        icntl14, mb = _factor_info(newton)
        assert icntl14 == 100  # every new factor keeps the workspace headroom
        factor_mb.append(mb)
        rss.append(_rss_mb())
    np.testing.assert_allclose(K @ p.u, 1.0, atol=1e-8)
    # Eight more factorisations after the second: kept, they would add 8 x the factor's size.
    assert rss[-1] - rss[1] < 2 * max(factor_mb), (rss, factor_mb)


class _Temporaries(_Poisson):
    """R(u) = u - 100 on 100 dofs (a unit Jacobian), whose residual makes a fresh 1 MB
    PETSc vector each time and drops it, as a form assembled anew does."""

    def __init__(self) -> None:
        import scipy.sparse as sp

        self.K = sp.identity(100, format="csr")
        self.u = np.zeros(100)

    def residual(self, b: Any) -> None:
        from petsc4py import PETSc

        tmp = PETSc.Vec().createSeq(2**17)
        tmp.set(1.0)
        b.getArray()[:] = self.u - 100.0 * tmp.getArray(readonly=True)[: len(self.u)]

    def max_strain(self, du: np.ndarray) -> float:
        return float(np.abs(du).max())


@pytest.mark.fem
def test_objects_a_problem_drops_at_each_step_are_freed() -> None:
    """The strain limit (0.5 per update) makes 200 steps of the linear R(u) = u - 100; kept,
    the dropped vectors would hold 200 MB."""
    p = _Temporaries()
    newton = _newton(p, rtol=0.0, atol=1e-6, stol=1e-6, max_iterations=300)
    before = _rss_mb()
    res = newton.solve(Dirichlet.none())
    assert res.status == StageStatus.CONVERGED and res.iterations > 200
    np.testing.assert_allclose(p.u, 100.0)
    assert _rss_mb() - before < 20, _rss_mb() - before

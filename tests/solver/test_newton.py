"""Load continuation (woundsweep.solver.continuation) against a scripted Newton solver, and
Newton's convergence check and Dirichlet elimination on small problems."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from woundsweep.config.solver import NewtonSettings
from woundsweep.core.schema import StageStatus
from woundsweep.solver.continuation import LoadState, continuation
from woundsweep.solver.dirichlet import Dirichlet

CONVERGED, MAX_ITERATIONS = StageStatus.CONVERGED, StageStatus.MAX_ITERATIONS


class _Problem:
    def __init__(self) -> None:
        self.u = np.zeros(3)

    def solution(self) -> np.ndarray:
        return self.u


class _ScriptedNewton:
    """Converges (3 steps) at load factors up to ``limit``, fails (10 steps) above; records
    the factors tried and leaves u = s after a success, garbage after a failure."""

    def __init__(self, limit: float, settings: NewtonSettings) -> None:
        self.problem = _Problem()
        self.settings = settings
        self.gamma = 1.0
        self.limit = limit
        self.tried: list[float] = []
        self.s = 0.0

    def reset(self) -> None:
        self.gamma = 1.0

    def solve(self, bc: Any, offset: Any, force_scale: float, policy: Any = None) -> Any:
        from woundsweep.solver.newton import NewtonResult

        s = self.s
        self.tried.append(s)
        ok = s <= self.limit + 1e-12
        self.problem.u[:] = s if ok else np.nan
        status = CONVERGED if ok else MAX_ITERATIONS
        return NewtonResult(status, 3 if ok else 10, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0)


def _run(
    limit: float, first_step: float, max_step: float = 1.0, **settings: Any
) -> tuple[_ScriptedNewton, Any]:
    newton = _ScriptedNewton(limit, NewtonSettings(**settings))

    def load(s: float) -> LoadState:
        newton.s = s
        return LoadState(Dirichlet.none(), None)

    res = continuation(newton, load, first_step=first_step, max_step=max_step)  # type: ignore[arg-type]
    return newton, res


def test_a_cut_near_the_end_halves_the_step_actually_tried() -> None:
    # s = 0.75 converges; the next increment (0.75, clipped to s = 1) fails. Halving the
    # unclipped 0.75 would try s = 1 again; halving the tried 0.25 gives 0.875.
    newton, res = _run(limit=0.9, first_step=0.75)
    assert newton.tried[:3] == [0.75, 1.0, 0.875]
    assert all(a != b for a, b in zip(newton.tried, newton.tried[1:]))  # no repeated failure
    assert res.status == MAX_ITERATIONS  # s > 0.9 never converges
    assert res.load_reached == pytest.approx(max(s for s in newton.tried if s <= 0.9))
    assert newton.problem.u[0] == pytest.approx(res.load_reached)  # the last converged state


def test_increments_double_up_to_the_largest_step() -> None:
    newton, res = _run(limit=1.0, first_step=0.125, max_step=0.25)
    assert res.status == CONVERGED and res.cuts == 0
    assert newton.tried == pytest.approx([0.125, 0.375, 0.625, 0.875, 1.0])


def test_continuation_reaches_the_end_and_counts_cuts() -> None:
    newton, res = _run(limit=1.0, first_step=0.25)
    assert res.status == CONVERGED and res.load_reached == 1.0 and res.cuts == 0
    # 0.25, then doubled increments after easy (3-step) successes: 0.75, 1.0 (clipped)
    assert newton.tried == [0.25, 0.75, 1.0]
    assert res.iterations == 9 and res.increments == 3


def test_failures_in_a_row_end_the_stage_after_max_load_cuts() -> None:
    newton, res = _run(limit=0.1, first_step=0.5, max_load_cuts=2)
    # 0.5 fails, 0.25 fails, 0.125 fails: three failures in a row > 2 cuts
    assert newton.tried == [0.5, 0.25, 0.125]
    assert res.status == MAX_ITERATIONS and res.load_reached == 0.0 and res.cuts == 3
    np.testing.assert_array_equal(newton.problem.u, 0.0)  # restored to the start


def test_a_path_that_needs_ever_smaller_increments_ends() -> None:
    # Every s <= 0.3 converges in 3 steps, no s > 0.3 does: each success resets the count of
    # failures in a row, so only the smallest increment (the first / 2**max_load_cuts) ends
    # the approach to s = 0.3 before the stage's step budget.
    newton, res = _run(limit=0.3, first_step=0.5)
    ds_min = 0.5 / 2**6
    assert res.status == MAX_ITERATIONS
    assert 0.3 - 2 * ds_min < res.load_reached <= 0.3
    done = [0.0] + [s for s in newton.tried if s <= 0.3]
    gaps = [s - max(d for d in done if d < s) for s in newton.tried]
    assert min(gaps) >= ds_min
    assert len(newton.tried) <= 14  # without the smallest increment: until 1000 steps


class _Small:
    """A few-dof problem of the `woundsweep.solver.NonlinearProblem` protocol; subclasses give
    R (``_grad``) and its Jacobian."""

    multipliers = None

    def __init__(self, u0: list[float]) -> None:
        self.u = np.array(u0, dtype=float)

    def solution(self) -> np.ndarray:
        return self.u

    def _grad(self) -> np.ndarray:
        raise NotImplementedError

    def residual(self, b: Any) -> None:
        b.getArray()[:] = self._grad()

    def min_det(self, u: np.ndarray) -> float:
        return 1.0

    def max_strain(self, du: np.ndarray) -> float:
        return float(np.abs(du).max())

    def length_scale(self) -> float:
        return 1.0


class _UnitSlope(_Small):
    """A one-dof problem whose Jacobian is 1 everywhere (subclasses give R)."""

    def jacobian(self, A: Any) -> None:
        A.zeroEntries()
        A.setValues([0], [0], [1.0])
        A.assemble()


def _unit_matrix() -> Any:
    """A 1 x 1 assembled PETSc matrix holding 1 (the one-dof solves' tangent)."""
    from petsc4py import PETSc

    A = PETSc.Mat().createAIJ([1, 1], nnz=1)
    A.setUp()
    A.setValues([0], [0], [1.0])
    A.assemble()
    return A


class _Arctan(_Small):
    """R(u) = atan(u) componentwise, E = sum u atan(u) - log(1 + u^2) / 2: from |u| > 1.39
    the full Newton step overshoots, so the first updates are damped."""

    def _grad(self) -> np.ndarray:
        return np.arctan(self.u)

    def jacobian(self, A: Any) -> None:
        A.zeroEntries()
        A.setValues([0, 1], [0, 1], np.diag(1.0 / (1.0 + self.u**2)).ravel())
        A.assemble()


@pytest.mark.fem
def test_convergence_is_judged_after_a_full_newton_step() -> None:
    """A loose tolerance that a damped update already meets: Newton must still take a full,
    undamped step from there and stop only if that step meets the tolerances; the state it
    returns is then one that a full step changes by less than stol."""
    from petsc4py import PETSc

    from woundsweep.solver.newton import NewtonSolver, Policy

    p = _Arctan([3.0, -2.0])
    A = PETSc.Mat().createAIJ([2, 2], nnz=2)
    A.setUp()
    A.setValues([0, 1], [0, 1], np.ones(4))
    A.assemble()
    # Met long before the root; an update may not grow the residual (the full steps from the
    # start overshoot to ever larger |u|).
    st = NewtonSettings(rtol=0.0, atol=0.5, stol=0.5, residual_growth=1.0)
    newton = NewtonSolver(p, A, st)
    steps: list[tuple[float, np.ndarray]] = []  # (gamma of the update, residual after it)
    real = newton._relax

    def relax(*args: Any) -> Any:
        out = real(*args)
        steps.append((out.gamma, p._grad().copy()))
        return out

    newton._relax = relax  # type: ignore[method-assign]
    res = newton.solve(Dirichlet.none(), policy=Policy(st))
    assert res.status == CONVERGED
    damped = [i for i, (g, r) in enumerate(steps) if g < 1.0]
    assert damped, "the start must need damped steps"
    # A damped update met the tolerance (|R| <= atol) and was not accepted as converged...
    first_ok = next(i for i, (g, r) in enumerate(steps) if np.linalg.norm(r) <= st.atol)
    assert steps[first_ok][0] < 1.0
    # ... a full step followed it (the convergence check's, not a relaxed one: one more
    # iteration than the relaxed updates), and its result is the returned state.
    assert res.iterations == len(steps) + 1
    r = np.arctan(p.u)
    assert np.linalg.norm(r) <= st.atol
    du = -r * (1.0 + p.u**2)  # the full step from the returned state
    assert np.abs(du).max() <= st.stol


@pytest.mark.fem
def test_an_intermediate_increment_stops_at_the_path_tolerance() -> None:
    """Under ``Policy.path`` (a state inside a load ramp) a solve ends as soon as the
    residual meets path_rtol, without the full-step test; the same solve without it goes on
    to rtol and a full step of size below stol."""
    from petsc4py import PETSc

    from woundsweep.solver.newton import NewtonSolver, Policy

    st = NewtonSettings(rtol=1e-10, atol=0.0, stol=1e-10, path_rtol=1e-2)
    counts = {}
    for path in (True, False):
        p = _Arctan([1.0, -0.5])
        A = PETSc.Mat().createAIJ([2, 2], nnz=2)
        A.setUp()
        A.setValues([0, 1], [0, 1], np.ones(4))
        A.assemble()
        newton = NewtonSolver(p, A, st)
        res = newton.solve(Dirichlet.none(), force_scale=1.0, policy=Policy(st, path=path))
        assert res.status == CONVERGED
        r = float(np.linalg.norm(np.arctan(p.u)))
        if path:
            assert st.rtol < r <= st.path_rtol  # stopped at the path tolerance, not beyond
        else:
            assert r <= st.rtol
        counts[path] = res.iterations
    assert counts[True] < counts[False]


def test_only_the_end_of_a_ramp_is_solved_to_the_full_tolerance() -> None:
    """Continuation solves every increment before s = 1 under the path policy, the last
    without it."""
    newton = _ScriptedNewton(1.0, NewtonSettings())
    seen: list[tuple[float, bool]] = []
    real = newton.solve

    def solve(bc: Any, offset: Any, force_scale: float, policy: Any = None) -> Any:
        seen.append((newton.s, bool(policy.path)))
        return real(bc, offset, force_scale, policy)

    newton.solve = solve  # type: ignore[method-assign]

    def load(s: float) -> LoadState:
        newton.s = s
        return LoadState(Dirichlet.none(), None)

    res = continuation(newton, load, first_step=0.25)  # type: ignore[arg-type]
    assert res.status == CONVERGED
    assert seen == [(0.25, True), (0.75, True), (1.0, False)]


class _Jump(_UnitSlope):
    """R(u) = u + sign(u): no root, and a full Newton step from u = 1 lands on u = -1 and
    back, the 2-cycle a semi-smooth step can fall into."""

    def _grad(self) -> np.ndarray:
        return self.u + np.sign(self.u)

    def max_strain(self, du: np.ndarray) -> float:
        return 0.0


class _Ring(_UnitSlope):
    """R(u) = u - r(u), r = 2, 3, 4, 1 on the unit cells around u = 1, 2, 3, 4: no root, and
    full Newton steps from u = 1 go round 1 -> 2 -> 3 -> 4 -> 1, a 4-cycle (the semi-smooth
    contact step's active set can cycle with period 4)."""

    def _grad(self) -> np.ndarray:
        cell = int(np.clip(np.floor(self.u[0] - 0.5), 0, 3))  # 0..3 around u = 1..4
        return self.u - (1.0 + (cell + 1) % 4)

    def max_strain(self, du: np.ndarray) -> float:
        return 0.0


class _Cusp(_Small):
    """R(u) = sign(u) |u|^(2/3): each full Newton step lands at -u/2, an oscillation that
    converges (linearly), not a cycle."""

    def _grad(self) -> np.ndarray:
        return np.sign(self.u) * np.abs(self.u) ** (2.0 / 3.0)

    def jacobian(self, A: Any) -> None:
        A.zeroEntries()
        A.setValues([0], [0], [(2.0 / 3.0) * np.abs(self.u[0]) ** (-1.0 / 3.0)])
        A.assemble()

    def max_strain(self, du: np.ndarray) -> float:
        return 0.0


@pytest.mark.fem
def test_a_cycle_stalls_the_solve_and_a_converging_oscillation_does_not() -> None:

    from woundsweep.solver.newton import STALL_UPDATES, NewtonSolver, Policy

    st = NewtonSettings(rtol=0.0, atol=1e-6, stol=1e-6)
    # A 2-cycle and a 4-cycle end after STALL_UPDATES updates, not the step budget (60); the
    # cusp's oscillation converges.
    for problem, status in ((_Jump([1.0]), MAX_ITERATIONS), (_Ring([1.0]), MAX_ITERATIONS),
                            (_Cusp([1.0]), CONVERGED)):  # fmt: skip
        A = _unit_matrix()
        res = NewtonSolver(problem, A, st).solve(
            Dirichlet.none(), force_scale=10.0, policy=Policy.contact(st)
        )
        assert res.status == status
        if status == MAX_ITERATIONS:
            assert res.iterations == STALL_UPDATES
        else:
            assert abs(problem.u[0]) < 1e-8 and res.iterations > STALL_UPDATES


class _Springs(_Small):
    """E = u.K u / 2 - f.u with a full SPD K: linear, so one Newton step solves it."""

    K = np.array([[4.0, -1.0, 0.5], [-1.0, 3.0, -0.8], [0.5, -0.8, 2.0]])
    f = np.array([1.0, -2.0, 0.3])

    def _grad(self) -> np.ndarray:
        return self.K @ self.u - self.f

    def jacobian(self, A: Any) -> None:
        A.zeroEntries()
        A.setValues([0, 1, 2], [0, 1, 2], self.K.ravel())
        A.assemble()

    def max_strain(self, du: np.ndarray) -> float:
        return 0.0  # linear: no step-size limit


@pytest.mark.fem
@pytest.mark.parametrize("symmetric", [False, True])
def test_prescribed_values_couple_into_the_free_dofs(symmetric: bool) -> None:
    """u_2 = 0.7 prescribed from u = 0: the free dofs must solve K_ff u_f = f_f - K_f2 0.7.
    The symmetric (LDL^T) path eliminates column 2 too, so that coupling must reach the
    right-hand side; the LU path keeps it in the matrix. The problem is linear, so the first
    step is exact and the second (the full-step check) moves nothing: two iterations."""
    from petsc4py import PETSc

    from woundsweep.solver.newton import NewtonSolver, Policy

    p = _Springs([0.0, 0.0, 0.0])
    A = PETSc.Mat().createAIJ([3, 3], nnz=3)
    A.setUp()
    A.setValues([0, 1, 2], [0, 1, 2], np.ones(9))
    A.assemble()
    st = NewtonSettings(rtol=0.0, atol=1e-12, stol=1e-12)
    newton = NewtonSolver(p, A, st)
    rows = np.array([2], dtype=np.int32)
    res = newton.solve(Dirichlet(rows, np.array([0.7])), policy=Policy(st, symmetric=symmetric))
    assert res.status == CONVERGED
    K, f = _Springs.K, _Springs.f
    expected = np.linalg.solve(K[:2, :2], f[:2] - K[:2, 2] * 0.7)
    np.testing.assert_allclose(p.u, [*expected, 0.7], rtol=0, atol=1e-12)
    assert res.iterations == 2
    assert newton._pc_kind == ("cholesky" if symmetric else "lu")


class _Far(_UnitSlope):
    """R(u) = u - 100 from u = 0: linear, but the strain limit (0.5 per update) makes every
    update 0.5 long, a steady descent of 0.5 % of the residual per update."""

    def _grad(self) -> np.ndarray:
        return self.u - 100.0


@pytest.mark.fem
def test_a_slow_descent_stalls_only_without_the_residual_rule() -> None:

    from woundsweep.solver.newton import STALL_UPDATES, NewtonSolver, Policy

    st = NewtonSettings(rtol=0.0, atol=1e-6, stol=1e-6)
    for policy, steps in ((Policy(st), st.max_iterations), (Policy.contact(st), STALL_UPDATES)):
        problem = _Far([0.0])
        A = _unit_matrix()
        res = NewtonSolver(problem, A, st).solve(Dirichlet.none(), force_scale=100.0, policy=policy)
        assert res.status == MAX_ITERATIONS and res.iterations == steps
        assert problem.u[0] == pytest.approx(0.5 * steps, rel=0.01)

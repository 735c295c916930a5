"""Newton's method with adaptive relaxation over assembled PETSc objects.

One Newton step solves ``J du = -R`` (MUMPS, KSP ``preonly``: LDL^T for a symmetric tangent,
else LU) and applies ``u += gamma du``. With a symmetry basis P (`NewtonSolver.set_symmetry`)
the factorised matrix is P^T J P and du = P x (`woundsweep.solver.symmetry`); every step is
checked against the full J.
The relaxation factor gamma follows a FIRE-like rule: it shrinks (x0.5) when an update is too
large (its largest cellwise displacement-gradient increment exceeds ``max_strain_step``), when
it would invert an element (min J <= 0), or when the residual grows; it grows (x2, up to 1)
after every step accepted without shrinking.

Under ``Policy.residual_rule`` = False (the contact stages) the residual may grow: a full
step of the semi-smooth contact Newton overshoots penalty forces it corrects at the next step,
so only inversion and the strain limit shrink gamma there.

A problem may keep part of its tangent out of the assembled matrix, as a low-rank term
(``low_rank``: J = A + U diag(c) U^T); Newton factorises A alone and solves by the Woodbury
identity (`woundsweep.solver.lowrank`).

A problem may carry variables beside u that Newton updates with each step: its
``multipliers`` (a `Multipliers`, e.g. `woundsweep.contact.ContactMultipliers`, the contact
stages' semi-smooth step), or None.

Dirichlet conditions are imposed strongly by row elimination on flat dof indices: the
constrained rows of J become identity rows and the right-hand side holds ``g - u`` there, so
a step with gamma = 1 meets them exactly. The matrix keeps its nonzero pattern, so MUMPS's
symbolic factorisation is done once per matrix and only the numeric one per step.

Convergence (``stol`` is relative to the problem's length scale ``ell``):
``||R_free||_2 <= atol + rtol * f_scale`` and ``max |g - u| <= stol * ell`` and the last
increment ``||du||_inf <= stol * ell``, where that last increment must be a full Newton step
(fresh tangent, gamma = 1): a state that meets the tolerances after a damped update is not
yet converged; Newton takes a full step from it and tests again, so a
converged state is one a full, undamped step leaves within the tolerances. ``f_scale`` is
the larger of the given force scale and the current full residual norm (reactions
included), unless ``Policy.fixed_scale``. Under ``Policy.path`` (an increment before the end
of a load ramp, whose state is not a result) a solve ends once
``||R_free||_2 <= atol + path_rtol * f_scale`` with the Dirichlet values met, without the
full-step test.

Statuses (`woundsweep.core.schema.StageStatus`): converged, max-iterations (the step budget, or,
without the residual rule, a stall: ``STALL_UPDATES`` updates in a row, the Dirichlet values
met, none of which brought the free residual below ``STALL_FACTOR`` times its last low), diverged
(non-finite or exploding residual, or no acceptable relaxation), inverted (every relaxation
inverts an element), linear-solver-failed (factorisation error or non-finite solution).
"""

from __future__ import annotations

import logging
import math
import time
from typing import NamedTuple, Protocol

import numpy as np
from petsc4py import PETSc

from ..config.solver import NewtonSettings
from ..core.schema import StageStatus
from .dirichlet import Dirichlet
from .lowrank import LowRankUpdate
from .multipliers import NO_MULTIPLIERS, Multipliers
from .symmetry import Subspace, SymmetryBasis

__all__ = ["Multipliers", "NewtonResult", "NewtonSolver", "NonlinearProblem", "Policy"]

_log = logging.getLogger(__name__)
LINEAR_RTOL = 1e-6  # accepted relative residual of a direct solve
# A stall: STALL_UPDATES updates in a row (the Dirichlet values met) that do not bring the free
# residual below STALL_FACTOR times its last low. The semi-smooth contact step can fall into
# cycles of its active set (exact 2-cycles, and near-4-cycles that drift by 1e-3 of the
# update's size); no cycle test catches every period and drift, while any cycle makes no
# progress. The solve stops instead of spending its step budget, and the continuation cuts
# the load increment. Only without the residual rule (the contact stages): under it no update
# grows the residual much, and a slow but steady descent (stage 1 of soft skin along the
# Langer line: 34 steps) is not a cycle.
STALL_FACTOR, STALL_UPDATES = 0.5, 10
CONVERGED = StageStatus.CONVERGED
MAX_ITERATIONS = StageStatus.MAX_ITERATIONS
DIVERGED = StageStatus.DIVERGED
INVERTED = StageStatus.INVERTED
LINEAR_SOLVER_FAILED = StageStatus.LINEAR_SOLVER_FAILED


class Policy(NamedTuple):
    """How one stage's Newton solves are run and judged."""

    settings: NewtonSettings
    fixed_scale: bool = False  # the force scale stays the given one (not grown by |R|)
    symmetric: bool = False  # the tangent is symmetric: LDL^T instead of LU (`NewtonSolver`)
    residual_rule: bool = True  # reject updates that grow the residual past residual_growth
    # An intermediate state of a load ramp: converged once the residual meets path_rtol (and
    # the Dirichlet values stol), without the full-step test; only the stage's end is stored.
    path: bool = False

    @classmethod
    def contact(cls, settings: NewtonSettings) -> Policy:
        """The contact stages': dead loads (a symmetric tangent, LDL^T), the force scale of
        the stage's start (a penetrating start's penalty forces must not set the tolerance),
        and the semi-smooth step's overshoots allowed (no residual rule)."""
        return cls(settings, fixed_scale=True, symmetric=True, residual_rule=False)


class NonlinearProblem(Protocol):
    """What Newton needs from a discretised problem (all arrays in dof order, flat)."""

    @property
    def multipliers(self) -> Multipliers | None:
        """Variables carried beside u, if any (read-only here: Newton never reassigns them,
        so a problem may narrow the type, e.g. to `ContactMultipliers`)."""
        ...

    def solution(self) -> np.ndarray:
        """Writable view of the current displacement dofs."""
        ...

    def residual(self, b: PETSc.Vec) -> None:
        """Assemble R(u) into ``b`` (no boundary conditions applied)."""
        ...

    def jacobian(self, A: PETSc.Mat) -> None:
        """Assemble dR/du into ``A`` (finalised, no boundary conditions applied)."""
        ...

    def min_det(self, u: np.ndarray) -> float:
        """Smallest cellwise det F at displacement ``u``."""
        ...

    def max_strain(self, du: np.ndarray) -> float:
        """Largest cellwise Frobenius norm of grad(du)."""
        ...

    def length_scale(self) -> float:
        """A length (mm) for the increment tolerance."""
        ...


class NewtonResult(NamedTuple):
    """Outcome of one Newton solve (one load increment)."""

    status: str
    iterations: int
    residual_norm: float
    force_scale: float
    min_det: float
    assembly_time_s: float
    factor_time_s: float
    solve_time_s: float
    residual_time_s: float


def free_dropped_petsc_objects() -> None:
    """Free the PETSc objects Python has dropped. petsc4py (3.18 and later) does not destroy
    an object when its Python reference goes: it joins a garbage list that only
    ``PETSc.garbage_cleanup`` empties, so temporaries made at every step of a long stage
    (the problem's assembled vectors, a contact pattern's matrices) would accumulate."""
    cleanup = getattr(PETSc, "garbage_cleanup", None)  # absent before petsc4py 3.18
    if cleanup is not None:
        cleanup()


class _Step(NamedTuple):
    """An accepted update: relaxation, whether it was reduced, and the new state's data."""

    gamma: float
    shrunk: bool
    r: np.ndarray
    min_det: float
    residual_time_s: float


class NewtonSolver:
    """Relaxed Newton over assembled PETSc objects; reuse one instance across stages."""

    def __init__(self, problem: NonlinearProblem, A: PETSc.Mat, settings: NewtonSettings) -> None:
        self.problem = problem
        self.settings = settings  # the default policy's
        self._policy = Policy(settings)  # the policy of the solve in progress
        self.A = A
        # Rows keep their nonzero slots when zeroed, so the symbolic factorisation stays valid.
        self.A.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
        self.b, self.dx = A.createVecs()[1], A.createVecs()[0]
        self.rvec = self.b.duplicate()
        self._Adu = self.b.duplicate()  # the linear solve's check, A du
        self.ksp: PETSc.KSP | None = None  # made for each new operator (`_direct_solver`)
        self._factored = False
        self._pc_kind = "lu"
        self.gamma = 1.0
        # The symmetric subspace (`set_symmetry`), or None: the full space.
        self._sub: Subspace | None = None
        self._low_rank = getattr(problem, "low_rank", None)
        self._woodbury: LowRankUpdate | None = None  # the current step's low-rank term

    def _direct_solver(self, op: PETSc.Mat, kind: str) -> None:
        """A new MUMPS solver (``kind``: lu or cholesky) for ``op``, the old one destroyed. A new
        solver, not the old one's PC pointed at the new matrix: that left the old factorisation
        allocated (60-80 MB at each growth of a contact stage's pattern, GBs over a long stage)
        and gave the new factor MUMPS's default workspace."""
        if self.ksp is not None:
            self.ksp.destroy()
        self.ksp = PETSc.KSP().create(op.getComm())
        self.ksp.setType("preonly")
        self.ksp.setErrorIfNotConverged(False)
        pc = self.ksp.getPC()
        pc.setType(kind)
        pc.setFactorSolverType("mumps")
        self.ksp.setOperators(op)
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(14, 100)  # headroom: fewer -9 failures on 3D meshes

    def set_symmetry(self, basis: SymmetryBasis | None) -> None:
        """Solve the linear systems in the span of ``basis.P`` (`woundsweep.solver.symmetry`),
        or in the full space (None)."""
        self._sub = None if basis is None else Subspace(basis)
        self._factored = False

    def reset(self) -> None:
        """Forget the adaptive state at the start of a stage (the relaxation and the carried
        multipliers): its result must not depend on what the solver did before it (earlier
        stages, or other jobs on a reused model)."""
        self.gamma = 1.0
        self.multipliers.reset()

    @property
    def multipliers(self) -> Multipliers:
        """The problem's carried multipliers (no-ops for a problem without them)."""
        return self.problem.multipliers or NO_MULTIPLIERS

    # -- pieces ---------------------------------------------------------------------------

    def _residual(self, offset: np.ndarray | None) -> tuple[np.ndarray, float]:
        t0 = time.perf_counter()
        self.problem.residual(self.rvec)
        r = self.rvec.getArray(readonly=True).copy()
        if offset is not None:
            r -= offset
        return r, time.perf_counter() - t0

    def _factor(self, rows: np.ndarray, rhs: np.ndarray) -> tuple[float, float]:
        """Assemble J with identity rows at ``rows`` and factorise: (assembly s, factor s).

        Under `Policy.symmetric` the columns at ``rows`` are eliminated too, so the matrix
        stays symmetric and MUMPS factorises it as LDL^T (symmetric indefinite), about 1.5x
        faster than LU; the prescribed values' column terms then move to ``rhs`` (in place).
        """
        t0 = time.perf_counter()
        self.problem.jacobian(self.A)
        kind = "cholesky" if self._policy.symmetric else "lu"
        if kind == "cholesky":
            if np.any(rhs[rows]):  # values still to impose: lift their columns (dx, b: scratch)
                x = self.dx.getArray()
                x[:] = 0.0
                x[rows] = rhs[rows]
                self.A.mult(self.dx, self.b)
                lifted = self.b.getArray(readonly=True).copy()
                lifted[rows] = 0.0
                rhs -= lifted
            self.A.zeroRowsColumns(rows, diag=1.0)
        else:
            self.A.zeroRows(rows, diag=1.0)
        t1 = time.perf_counter()  # the restriction P^T J P counts as factorisation
        op = self.A
        if self._sub is not None:
            op, new = self._sub.operator(self.A)
            self._factored = self._factored and not new  # a new matrix: analysed again
        if kind != self._pc_kind:
            self._pc_kind = kind
            self._factored = False
        if not self._factored:
            self._direct_solver(op, kind)
            self._factored = True
        assert self.ksp is not None
        self.ksp.setUp()
        self.ksp.getPC().setUp()  # numeric factorisation now, so it is timed on its own
        self._woodbury = None
        lr = self._low_rank() if self._low_rank is not None else None
        if lr is not None:
            self._woodbury = LowRankUpdate(lr[0], lr[1], rows, rhs, self._apply_inverse)
        return t1 - t0, time.perf_counter() - t1

    def _apply_inverse(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs with the current factors (in the symmetric subspace if set)."""
        ksp = self.ksp
        assert ksp is not None, "no factorisation yet"
        self.b.getArray()[:] = rhs
        if self._sub is None:
            ksp.solve(self.b, self.dx)
        else:
            self._sub.solve(ksp, self.b, self.dx)
        if ksp.getConvergedReason() < 0:
            return np.full(len(rhs), np.nan)
        return self.dx.getArray(readonly=True).copy()

    def _linear_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """Solve with the current factors; None on failure or an inaccurate solution.

        A (near-)singular tangent can factorise without a MUMPS error and give a finite but
        meaningless answer, so the true residual ||A du - b|| is checked (one product).
        """
        du = self._apply_inverse(rhs)
        wb = self._woodbury
        if wb is not None:
            du = wb.correct(du)
        if not np.all(np.isfinite(du)):
            return None
        self.dx.getArray()[:] = du
        self.A.mult(self.dx, self._Adu)
        Adu = self._Adu.getArray(readonly=True).copy()
        if wb is not None:
            Adu += wb.apply(du)
        err = np.linalg.norm(Adu - rhs)
        # A symmetric step cannot remove the right-hand side's antisymmetric part (rounding
        # of a symmetric state, relatively large only where the residual is near zero); a
        # problem that is not symmetric leaves a larger error and fails.
        floor = 0.0 if self._sub is None else self._sub.antisymmetric_norm(rhs)
        return du if err <= LINEAR_RTOL * max(float(np.linalg.norm(rhs)), 1e-300) + floor else None

    # -- the solve ----------------------------------------------------------------------

    def solve(
        self,
        bc: Dirichlet,
        offset: np.ndarray | None = None,
        force_scale: float = 0.0,
        policy: Policy | None = None,
    ) -> NewtonResult:
        """Solve R(u) - offset = 0 at the free dofs with u = bc's values at its rows.

        ``policy`` defaults to the solver's settings with the residual rule."""
        self._policy = policy if policy is not None else Policy(self.settings)
        st = self._policy.settings
        u = self.problem.solution()
        rows, values = bc.rows, bc.target
        ell = self.problem.length_scale()
        free = np.ones(len(u), dtype=bool)
        free[rows] = False
        t_asm = t_fac = t_sol = t_res = 0.0

        self.multipliers.begin()
        r, dt = self._residual(offset)
        t_res += dt
        last_inc = math.inf
        min_det = self.problem.min_det(u)
        res_norm = math.inf
        scale = force_scale
        it = 0
        full = False  # the last update was a full Newton step (fresh tangent, gamma = 1)
        low = math.inf  # the free residual's last low (the stall test)
        stalled = 0  # updates since it was set

        def result(status: str) -> NewtonResult:
            return NewtonResult(status, it, res_norm, scale, min_det, t_asm, t_fac, t_sol, t_res)

        while True:
            if not np.all(np.isfinite(r)):
                return result(DIVERGED)
            r_free = np.where(free, r, 0.0)
            res_norm = float(np.linalg.norm(r_free))
            if not self._policy.fixed_scale:
                scale = max(scale, float(np.linalg.norm(r)))
            bc_err = values - u[rows]
            bc_ok = bool(np.max(np.abs(bc_err), initial=0.0) <= st.stol * ell)
            res_ok = res_norm <= st.atol + st.rtol * scale
            _log.debug(
                "newton it=%d |R|=%.3e scale=%.3e bc=%.2e inc=%.2e gamma=%.3g",
                it,
                res_norm,
                scale,
                float(np.max(np.abs(bc_err), initial=0.0)),
                last_inc,
                self.gamma,
            )
            at_end = res_ok and full and last_inc <= st.stol * ell
            on_path = self._policy.path and res_norm <= st.atol + st.path_rtol * scale
            if bc_ok and (at_end or on_path):
                self.multipliers.commit()
                return result(CONVERGED)
            if res_norm > st.divergence_factor * max(scale, st.atol):
                return result(DIVERGED)
            if not bc_ok or res_norm <= STALL_FACTOR * low or self._policy.residual_rule:
                low = res_norm if bc_ok else math.inf
                stalled = 0
            elif it > 0:
                stalled += 1
            if it >= st.max_iterations or stalled >= STALL_UPDATES:
                return result(MAX_ITERATIONS)
            it += 1
            rhs = -r_free
            rhs[rows] = bc_err
            free_dropped_petsc_objects()
            try:
                ta, tf = self._factor(rows, rhs)
                t_asm += ta
                t_fac += tf
                t0 = time.perf_counter()
                du = self._linear_solve(rhs)
                t_sol += time.perf_counter() - t0
            except PETSc.Error:
                return result(LINEAR_SOLVER_FAILED)
            u0 = u.copy()
            if res_ok and bc_ok and du is not None:
                # The convergence check: a full, undamped Newton step from a state that meets
                # the tolerances must meet them again and be smaller than stol.
                pred = self.multipliers.predict(du)
                u += du
                min_det = self.problem.min_det(u)
                if min_det > 0:
                    self.multipliers.accept(pred, 1.0)
                    r, dt = self._residual(offset)
                    t_res += dt
                    last_inc = float(np.max(np.abs(du), initial=0.0))
                    full = True
                    continue
                u[:] = u0
            # Adaptive relaxation: limit the update size, then back off on inversion/growth.
            if du is None:
                return result(LINEAR_SOLVER_FAILED)
            prescribing = not bc_ok
            limit = st.residual_growth * max(res_norm, st.atol + st.rtol * scale)
            step = self._relax(u0, du, free, offset, limit, prescribing)
            if isinstance(step, str):
                u[:] = u0
                return result(step)
            t_res += step.residual_time_s
            r, min_det = step.r, step.min_det
            last_inc = float(np.max(np.abs(u - u0), initial=0.0))
            full = step.gamma == 1.0
            self.gamma = step.gamma if step.shrunk else min(1.0, 2.0 * step.gamma)

    def _relax(
        self,
        u0: np.ndarray,
        du: np.ndarray,
        free: np.ndarray,
        offset: np.ndarray | None,
        limit: float,
        prescribing: bool,
    ) -> _Step | str:
        """Set u = u0 + gamma du for the largest acceptable gamma; else restore u0 and give
        the failure status. Under `Policy.residual_rule` the residual may grow by at most
        ``limit`` (no limit while Dirichlet values are still being imposed: the load enters
        through them)."""
        st = self._policy.settings
        u = self.problem.solution()
        pred = self.multipliers.predict(du)
        strain = self.problem.max_strain(du)
        gamma = min(self.gamma, st.max_strain_step / strain) if strain > 0 else self.gamma
        shrunk = gamma < self.gamma
        check = self._policy.residual_rule and not prescribing
        why, t_res = DIVERGED, 0.0
        while True:
            u[:] = u0 + gamma * du
            det = self.problem.min_det(u)
            if det > 0:
                saved = self.multipliers.snapshot()
                self.multipliers.accept(pred, gamma)
                r_try, dt = self._residual(offset)
                t_res += dt
                n_try = float(np.linalg.norm(np.where(free, r_try, 0.0)))
                if np.all(np.isfinite(r_try)) and (not check or n_try <= limit):
                    return _Step(gamma, shrunk, r_try, det, t_res)
                self.multipliers.restore(saved)
                why = DIVERGED
            else:
                why = INVERTED
            gamma *= 0.5
            shrunk = True
            if gamma < st.gamma_min:
                u[:] = u0
                return why

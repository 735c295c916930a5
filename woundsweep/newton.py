"""Newton's method with adaptive relaxation and load continuation (the paper's solver, done right).

One Newton step solves ``J du = -R`` (MUMPS LU, KSP ``preonly``) and applies ``u += gamma du``.
The relaxation factor gamma follows the paper's FIRE-like rule: it shrinks (x0.5) when an
update is too large (its largest cellwise displacement-gradient increment exceeds
``max_strain_step``), when it would invert an element (min J <= 0), or when the residual
grows; it grows (x2, up to 1) after every step accepted without shrinking.

Where the problem has a potential E (``NonlinearProblem.energy``; the contact stages, whose
loads are all dead) and ``energy_merit`` is set, updates are accepted by Armijo's rule on E
instead of the residual rule, and a Newton step that does not descend E (an indefinite
tangent: an unstable equilibrium nearby) or finds no acceptable relaxation is replaced by
the step of the tangent with its free diagonal scaled by 1 + mu (mu = 1e-4 ... 1e4, x10, the
first that descends; modified Newton), so every update lowers E and the iterates move toward
a stable equilibrium (`NewtonSolver._relax`, `NewtonSolver._shifted`).

Dirichlet conditions are imposed strongly by row elimination on flat dof indices: the
constrained rows of J become identity rows and the right-hand side holds ``g - u`` there, so
a step with gamma = 1 meets them exactly. The matrix keeps its nonzero pattern, so MUMPS's
symbolic factorisation is done once per matrix and only the numeric one per step.

Convergence (documented tolerances; ``stol`` is relative to the mesh's length scale ``ell``):
``||R_free||_2 <= atol + rtol * f_scale`` and ``max |g - u| <= stol * ell`` and the last
increment ``||du||_inf <= stol * ell``. ``f_scale`` is the larger of the stage's starting
internal-force norm and the current full residual norm (reactions included), so the test is
relative to the forces that actually act. When the residual test passes but the increment
test does not, one chord step (reusing the factorisation) measures the increment.

Statuses: ``converged``, ``max-iterations``, ``diverged`` (non-finite or exploding residual, or
no acceptable relaxation), ``inverted`` (every relaxation inverts an element),
``linear-solver-failed`` (factorisation error or non-finite solution).

`continuation` ramps a stage's change with a load factor s in [0, 1]: the increment halves
after a failure (up to ``max_load_cuts`` times in a row) and doubles after an easy success.
Measured on a wounded test patch (3 jobs x stages 1-3): one first increment needed 84 Newton
steps in all, four first increments 154, a secant predictor made two-step ramps worse.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple, Protocol

import numpy as np
from petsc4py import PETSc

__all__ = [
    "CONVERGED",
    "DIVERGED",
    "INVERTED",
    "LINEAR_SOLVER_FAILED",
    "MAX_ITERATIONS",
    "NOT_RUN",
    "STATUSES",
    "ContinuationResult",
    "LoadState",
    "NewtonResult",
    "NewtonSettings",
    "NewtonSolver",
    "NonlinearProblem",
    "continuation",
]

_log = logging.getLogger(__name__)
LINEAR_RTOL = 1e-6  # accepted relative residual of a direct solve

CONVERGED = "converged"
MAX_ITERATIONS = "max-iterations"
DIVERGED = "diverged"
INVERTED = "inverted"
LINEAR_SOLVER_FAILED = "linear-solver-failed"
NOT_RUN = "not-run"
STATUSES = (CONVERGED, MAX_ITERATIONS, DIVERGED, INVERTED, LINEAR_SOLVER_FAILED, NOT_RUN)


@dataclasses.dataclass(frozen=True)
class NewtonSettings:
    """Numerical settings (sweep section ``solver``; unknown keys there are ignored here)."""

    max_iterations: int = 60  # Newton steps per load increment
    max_stage_iterations: int = 1000  # Newton steps per stage (all increments): bounds the cost
    rtol: float = 1e-8  # residual, relative to the force scale
    atol: float = 1e-10  # residual floor, mN
    stol: float = 1e-8  # increment and Dirichlet mismatch, relative to the length scale
    load_steps: int = 1  # first load increment = 1 / load_steps of the stage's change
    max_load_cuts: int = 6  # consecutive halvings of the load increment before giving up
    max_strain_step: float = 0.5  # largest |grad du| (Frobenius, per cell) of one update
    gamma_min: float = 1.0 / 64.0  # smallest relaxation factor tried
    residual_growth: float = 4.0  # accept an update while ||R|| grows by at most this factor
    divergence_factor: float = 1e6  # ||R|| above this times the force scale: diverged
    # Residual tolerance of the contact stages: their residual is only piecewise smooth (a
    # contact point that changes its master facet turns its force by the facets' angle, a
    # jump), and below the size of such jumps Newton can only cycle. Measured at 45 degrees
    # (session 10): with 1e-5 (and the increment at 1e-6) failing jobs stalled at 1e-4 to
    # 1.5e-4 of the force scale, so 1e-4 (Abaqus' default force tolerance is 5e-3 of the
    # average force).
    contact_rtol: float = 1e-4
    # The contact stages measure the increment against ``contact_stol``: frictionless sliding
    # leaves the flanks' tangential position nearly free, so a smaller increment is noise of
    # the forces' kinks. The surface model uses the energy merit (``energy_merit``); the
    # residual rule with ``contact_residual_growth`` is for a contact problem without a
    # potential (1: no update may raise the residual); the depth model keeps
    # ``residual_growth`` (the monotone rule stalled it).
    contact_stol: float = 1e-5
    contact_residual_growth: float = 1.0
    # Line search on the total potential instead of the residual norm, where the problem
    # has one (``NonlinearProblem.energy``; the contact stages): see `NewtonSolver.solve`.
    energy_merit: bool = False
    energy_gamma_min: float = 2.0**-20

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any] | None) -> NewtonSettings:
        """Settings from a sweep's ``solver`` mapping; missing keys keep their defaults."""
        if not values:
            return cls()
        kwargs = {}
        for f in dataclasses.fields(cls):
            if f.name in values:
                cast = {"int": int, "bool": bool}.get(str(f.type), float)
                kwargs[f.name] = cast(values[f.name])
        return cls(**kwargs)


class NonlinearProblem(Protocol):
    """What Newton needs from a discretised problem (all arrays in dof order, flat)."""

    def solution(self) -> np.ndarray:
        """Writable view of the current displacement dofs."""

    def residual(self, b: PETSc.Vec) -> None:
        """Assemble R(u) into ``b`` (no boundary conditions applied)."""

    def jacobian(self, A: PETSc.Mat) -> None:
        """Assemble dR/du into ``A`` (finalised, no boundary conditions applied)."""

    def min_det(self, u: np.ndarray) -> float:
        """Smallest cellwise det F at displacement ``u``."""

    def max_strain(self, du: np.ndarray) -> float:
        """Largest cellwise Frobenius norm of grad(du)."""

    def length_scale(self) -> float:
        """A length (mm) for the increment tolerance."""

    # Optional: ``energy() -> float | None``, the potential (mN mm) whose gradient is R at the
    # current state, or None when the loads have none (a follower load).


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


class _Step(NamedTuple):
    """An accepted update: relaxation, whether it was reduced, and the new state's data."""

    gamma: float
    shrunk: bool
    r: np.ndarray
    min_det: float
    residual_time_s: float
    factor_time_s: float


class NewtonSolver:
    """Relaxed Newton over assembled PETSc objects; reuse one instance across stages."""

    def __init__(self, problem: NonlinearProblem, A: PETSc.Mat, settings: NewtonSettings) -> None:
        self.problem = problem
        self.settings = settings
        self.A = A
        # Rows keep their nonzero slots when zeroed, so the symbolic factorisation stays valid.
        self.A.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
        self.b, self.dx = A.createVecs()[1], A.createVecs()[0]
        self.rvec = self.b.duplicate()
        self.ksp = PETSc.KSP().create(A.getComm())
        self.ksp.setOperators(A)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
        self.ksp.setErrorIfNotConverged(False)
        self._factored = False
        self._factored_rows = np.zeros(0, dtype=np.int32)
        self.gamma = 1.0
        self._mu = 0.0  # the last shift that gave a descent step (`_shifted`; see `reset`)
        # The force scale grows with the full residual norm (reactions included) unless this
        # is off; then it stays the ``force_scale`` given to `solve`.
        self.scale_from_residual = True

    def reset(self) -> None:
        """Forget the adaptive state (relaxation, shift) at the start of a stage: its result
        must not depend on what the solver did before it (earlier stages, or other jobs on a
        reused model). A load cut resets only the relaxation: the shift that gave descent
        steps before the cut is a good start after it (measured: resetting it there too made
        the 45-degree stiff cylinder of test_stages_contact end `max-iterations`)."""
        self.gamma = 1.0
        self._mu = 0.0

    # -- pieces ---------------------------------------------------------------------------

    def _residual(self, offset: np.ndarray | None) -> tuple[np.ndarray, float]:
        t0 = time.perf_counter()
        self.problem.residual(self.rvec)
        r = self.rvec.getArray(readonly=True).copy()
        if offset is not None:
            r -= offset
        return r, time.perf_counter() - t0

    def _energy(self, offset: np.ndarray | None) -> float | None:
        """Potential of ``R - offset`` at the current state, or None if there is none."""
        energy = getattr(self.problem, "energy", None)
        e = energy() if energy is not None else None
        if e is None:
            return None
        if offset is not None:
            e -= float(np.dot(offset, self.problem.solution()))
        return e

    def _factor(self, rows: np.ndarray) -> tuple[float, float]:
        """Assemble J with identity rows at ``rows`` and factorise: (assembly s, factor s)."""
        t0 = time.perf_counter()
        self.problem.jacobian(self.A)
        self.A.zeroRows(rows, diag=1.0)
        t1 = time.perf_counter()
        if not self._factored:
            self.ksp.setOperators(self.A)
            pc = self.ksp.getPC()
            pc.setFactorSetUpSolverType()
            F = pc.getFactorMatrix()
            F.setMumpsIcntl(14, 100)  # workspace headroom: fewer -9 failures on 3D meshes
            self._factored = True
        self.ksp.setUp()
        self.ksp.getPC().setUp()  # numeric factorisation now, so it is timed on its own
        self._factored_rows = rows.copy()
        return t1 - t0, time.perf_counter() - t1

    def _linear_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """Solve with the current factors; None on failure or an inaccurate solution.

        A (near-)singular tangent can factorise without a MUMPS error and give a finite but
        meaningless answer, so the true residual ||A du - b|| is checked (one product).
        """
        self.b.getArray()[:] = rhs
        self.ksp.solve(self.b, self.dx)
        if self.ksp.getConvergedReason() < 0:
            return None
        du = self.dx.getArray(readonly=True).copy()
        if not np.all(np.isfinite(du)):
            return None
        check = self.b.duplicate()
        self.A.mult(self.dx, check)
        err = np.linalg.norm(check.getArray(readonly=True) - rhs)
        return du if err <= LINEAR_RTOL * max(np.linalg.norm(rhs), 1e-300) else None

    # -- the solve ----------------------------------------------------------------------

    def solve(
        self,
        rows: np.ndarray,
        values: np.ndarray,
        offset: np.ndarray | None = None,
        force_scale: float = 0.0,
    ) -> NewtonResult:
        """Solve R(u) - offset = 0 at the free dofs with u[rows] = values."""
        st = self.settings
        u = self.problem.solution()
        rows = np.asarray(rows, dtype=np.int32)
        values = np.asarray(values, dtype=float)
        ell = self.problem.length_scale()
        free = np.ones(len(u), dtype=bool)
        free[rows] = False
        t_asm = t_fac = t_sol = t_res = 0.0

        r, dt = self._residual(offset)
        t_res += dt
        last_inc = math.inf
        min_det = self.problem.min_det(u)
        res_norm = math.inf
        scale = force_scale
        it = 0
        chord_done = False

        def result(status: str) -> NewtonResult:
            return NewtonResult(status, it, res_norm, scale, min_det, t_asm, t_fac, t_sol, t_res)

        while True:
            if not np.all(np.isfinite(r)):
                return result(DIVERGED)
            r_free = np.where(free, r, 0.0)
            res_norm = float(np.linalg.norm(r_free))
            if self.scale_from_residual:
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
            if res_ok and bc_ok and last_inc <= st.stol * ell:
                # A problem that froze part of its linearisation (the contact pairing) checks
                # it at the converged state; if a new one moves the forces, iterate on.
                refresh = getattr(self.problem, "refresh", None)
                if refresh is not None and refresh(st.atol + st.rtol * scale):
                    r, dt = self._residual(offset)
                    t_res += dt
                    last_inc = math.inf
                    chord_done = False
                    continue
                return result(CONVERGED)
            if res_norm > st.divergence_factor * max(scale, st.atol):
                return result(DIVERGED)
            rhs = -r_free
            rhs[rows] = bc_err
            same_rows = np.array_equal(rows, self._factored_rows)
            if res_ok and bc_ok and self._factored and same_rows and not chord_done:
                # Chord step: the residual is small; measure the increment with the old factors.
                t0 = time.perf_counter()
                du = self._linear_solve(rhs)
                t_sol += time.perf_counter() - t0
                chord_done = True
                if du is not None:
                    u += du
                    last_inc = float(np.max(np.abs(du), initial=0.0))
                    min_det = self.problem.min_det(u)
                    r, dt = self._residual(offset)
                    t_res += dt
                    continue
            if it >= st.max_iterations:
                return result(MAX_ITERATIONS)
            it += 1
            chord_done = False
            try:
                ta, tf = self._factor(rows)
                t_asm += ta
                t_fac += tf
                t0 = time.perf_counter()
                du = self._linear_solve(rhs)
                t_sol += time.perf_counter() - t0
            except PETSc.Error:
                return result(LINEAR_SOLVER_FAILED)

            # Adaptive relaxation: limit the update size, then back off on inversion/growth.
            u0 = u.copy()
            prescribing = not bc_ok
            e0 = self._energy(offset) if st.energy_merit and not prescribing else None
            if du is None and e0 is None:
                return result(LINEAR_SOLVER_FAILED)
            limit = st.residual_growth * max(res_norm, st.atol + st.rtol * scale)
            step: _Step | str = LINEAR_SOLVER_FAILED
            if du is not None:
                step = self._relax(u0, du, r_free, free, offset, limit, e0, prescribing)
            if isinstance(step, str) and e0 is not None:
                step = self._shifted(u0, rhs, r_free, free, offset, e0)
                if not isinstance(step, str):
                    t_fac += step.factor_time_s
            if isinstance(step, str):
                u[:] = u0
                return result(step)
            t_res += step.residual_time_s
            r, min_det = step.r, step.min_det
            last_inc = float(np.max(np.abs(u - u0), initial=0.0))
            self.gamma = step.gamma if step.shrunk else min(1.0, 2.0 * step.gamma)

    def _relax(
        self,
        u0: np.ndarray,
        du: np.ndarray,
        r_free: np.ndarray,
        free: np.ndarray,
        offset: np.ndarray | None,
        limit: float,
        e0: float | None,
        prescribing: bool,
    ) -> _Step | str:
        """Set u = u0 + gamma du for the largest acceptable gamma; else restore u0 and give
        the failure status.

        With a potential E (``e0`` = E(u0)) and a descent direction (dE = r . du < 0), gamma
        is accepted by Armijo's rule E(u0 + gamma du) <= E(u0) + 1e-4 gamma dE: E is C1 where
        R is only C0 (contact activation), so a step across many kinks that raises |R| can
        still be taken, and a minimiser is reached where a residual rule stalls. Otherwise
        the residual may grow by at most ``limit`` (no limit while Dirichlet values are
        still being imposed: the load enters through them).
        """
        st = self.settings
        u = self.problem.solution()
        strain = self.problem.max_strain(du)
        gamma = min(self.gamma, st.max_strain_step / strain) if strain > 0 else self.gamma
        shrunk = gamma < self.gamma
        slope = float(np.dot(r_free, du))
        if e0 is not None and not slope < 0.0:
            return DIVERGED  # uphill: the tangent is indefinite along du (`_shifted`)
        use_energy = e0 is not None
        g_min = st.energy_gamma_min if use_energy else st.gamma_min
        # Rounding of the assembled sums: a few ulps of the terms' size.
        ulps = 64.0 * np.finfo(float).eps * abs(e0 or 0.0)
        why, t_res = DIVERGED, 0.0
        while True:
            u[:] = u0 + gamma * du
            det = self.problem.min_det(u)
            if det > 0:
                e_try = self._energy(offset) if use_energy else None
                if e_try is None or e_try <= e0 + 1e-4 * gamma * slope + ulps:  # type: ignore[operator]
                    r_try, dt = self._residual(offset)
                    t_res += dt
                    n_try = float(np.linalg.norm(np.where(free, r_try, 0.0)))
                    if np.all(np.isfinite(r_try)) and (prescribing or use_energy or n_try <= limit):
                        return _Step(gamma, shrunk, r_try, det, t_res, 0.0)
                why = DIVERGED
            else:
                why = INVERTED
            gamma *= 0.5
            shrunk = True
            if gamma < g_min:
                u[:] = u0
                return why

    def _shifted(
        self,
        u0: np.ndarray,
        rhs: np.ndarray,
        r_free: np.ndarray,
        free: np.ndarray,
        offset: np.ndarray | None,
        e0: float,
    ) -> _Step | str:
        """Modified Newton when the Newton step is no descent of the potential (the tangent
        is indefinite: an unstable equilibrium nearby) or finds no acceptable relaxation:
        solve with the tangent's free diagonal scaled by 1 + mu, mu = 1e-4 ... 1e4 (x10), and
        take the first step that lowers the potential. A large enough shift makes the matrix
        positive definite, so the step goes downhill toward a stable equilibrium."""
        t0 = time.perf_counter()
        d0 = self.A.getDiagonal()
        base = d0.getArray(readonly=True).copy()
        extra = np.where(free, np.abs(base), 0.0)
        mu = max(1e-4, self._mu / 10.0)
        try:
            while mu <= 1e4:
                d0.getArray()[:] = base + mu * extra
                self.A.setDiagonal(d0)
                self.ksp.setUp()
                self.ksp.getPC().setUp()
                du = self._linear_solve(rhs)
                if du is not None:
                    step = self._relax(u0, du, r_free, free, offset, math.inf, e0, False)
                    if not isinstance(step, str):  # a descent step, accepted by Armijo
                        self._mu = mu
                        _log.debug("newton: shifted tangent, mu=%.1e", mu)
                        return step._replace(factor_time_s=time.perf_counter() - t0)
                    self.problem.solution()[:] = u0
                mu *= 10.0
        except PETSc.Error:
            return LINEAR_SOLVER_FAILED
        finally:
            # The factors are of a shifted matrix: no chord step may reuse them.
            self._factored_rows = np.zeros(0, dtype=np.int32)
        return DIVERGED


class LoadState(NamedTuple):
    """Constraint values and out-of-balance offset at a load factor s."""

    values: np.ndarray
    offset: np.ndarray | None


class ContinuationResult(NamedTuple):
    """Outcome of a stage solved by load continuation."""

    status: str
    iterations: int
    increments: int
    cuts: int
    load_reached: float
    residual_norm: float
    min_det: float
    assembly_time_s: float
    factor_time_s: float
    solve_time_s: float
    residual_time_s: float


def continuation(
    newton: NewtonSolver,
    rows: np.ndarray,
    load: Callable[[float], LoadState],
    force_scale: float = 0.0,
    first_step: float | None = None,
) -> ContinuationResult:
    """Ramp s from 0 to 1, solving at each increment; halve the increment after failures.

    The first increment is ``first_step`` (default ``1 / settings.load_steps``).
    """
    st = newton.settings
    u = newton.problem.solution()
    s = 0.0
    ds = float(first_step) if first_step is not None else 1.0 / max(1, st.load_steps)
    cuts_in_row = cuts = its = incs = 0
    times = np.zeros(4)
    last: NewtonResult | None = None
    newton.reset()
    while s < 1.0 - 1e-12:
        s_next = min(1.0, s + ds)
        u_saved = u.copy()
        state = load(s_next)
        res = newton.solve(rows, state.values, state.offset, force_scale)
        last = res
        its += res.iterations
        times += (res.assembly_time_s, res.factor_time_s, res.solve_time_s, res.residual_time_s)
        if res.status == CONVERGED:
            if its > st.max_stage_iterations and s_next < 1.0:  # out of budget, not done
                return ContinuationResult(
                    MAX_ITERATIONS, its, incs + 1, cuts, s_next, res.residual_norm, res.min_det,
                    *times,
                )  # fmt: skip
            incs += 1
            s = s_next
            cuts_in_row = 0
            if res.iterations <= 4:
                ds *= 2.0
            continue
        u[:] = u_saved
        cuts += 1
        cuts_in_row += 1
        newton.gamma = 1.0
        if cuts_in_row > st.max_load_cuts or its > st.max_stage_iterations:
            return ContinuationResult(
                res.status, its, incs, cuts, s, res.residual_norm, res.min_det, *times
            )
        # Halve the step actually tried: ds can exceed what was left to s = 1.
        ds = 0.5 * (s_next - s)
    assert last is not None
    return ContinuationResult(
        CONVERGED, its, incs, cuts, 1.0, last.residual_norm, last.min_det, *times
    )

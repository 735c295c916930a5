"""Load continuation: a stage's change ramped by a load factor s in [0, 1].

Each increment is solved by Newton from the last converged state; the increment halves after
a failure (up to ``max_load_cuts`` times in a row, and not below the first increment /
2**max_load_cuts) and doubles after an easy success (at most 4 Newton steps). Each increment
starts from the last converged state.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .dirichlet import Dirichlet
from .newton import CONVERGED, MAX_ITERATIONS, NewtonResult, NewtonSolver, Policy

__all__ = ["ContinuationResult", "LoadState", "continuation"]


class LoadState(NamedTuple):
    """The Dirichlet condition and the out-of-balance offset at a load factor s."""

    bc: Dirichlet
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
    load: Callable[[float], LoadState],
    force_scale: float = 0.0,
    first_step: float | None = None,
    policy: Policy | None = None,
    max_step: float = 1.0,
) -> ContinuationResult:
    """Ramp s from 0 to 1, solving at each increment; halve the increment after failures.

    The first increment is ``first_step`` (default ``1 / settings.load_steps``), and an
    increment doubles up to ``max_step``; ``policy`` (default: the solver's settings) is
    passed to every Newton solve.
    """
    policy = policy if policy is not None else Policy(newton.settings)
    st = policy.settings
    u = newton.problem.solution()
    s = 0.0
    ds = float(first_step) if first_step is not None else 1.0 / max(1, st.load_steps)
    ds_min = ds / 2.0**st.max_load_cuts  # a path that needs smaller increments has ended
    cuts_in_row = cuts = its = incs = 0
    times = np.zeros(4)
    last: NewtonResult | None = None
    newton.reset()
    while s < 1.0 - 1e-12:
        s_next = min(1.0, s + ds)
        u_saved = u.copy()
        state = load(s_next)
        # Only the stage's end (s = 1) is a result; the states before it only carry the path.
        step_policy = policy if s_next >= 1.0 else policy._replace(path=True)
        res = newton.solve(state.bc, state.offset, force_scale, step_policy)
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
                ds = min(2.0 * ds, max_step)
            continue
        u[:] = u_saved
        cuts += 1
        cuts_in_row += 1
        newton.gamma = 1.0
        stalled = 0.5 * (s_next - s) < ds_min
        if cuts_in_row > st.max_load_cuts or stalled or its > st.max_stage_iterations:
            return ContinuationResult(
                res.status, its, incs, cuts, s, res.residual_norm, res.min_det, *times
            )
        # Halve the step actually tried: ds can exceed what was left to s = 1.
        ds = 0.5 * (s_next - s)
    assert last is not None
    return ContinuationResult(
        CONVERGED, its, incs, cuts, 1.0, last.residual_norm, last.min_det, *times
    )

"""Load continuation (woundsweep.newton.continuation) against a scripted Newton solver."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from woundsweep.newton import (
    CONVERGED,
    MAX_ITERATIONS,
    LoadState,
    NewtonResult,
    NewtonSettings,
    continuation,
)


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

    def solve(self, rows: Any, values: Any, offset: Any, force_scale: float) -> NewtonResult:
        s = self.s
        self.tried.append(s)
        ok = s <= self.limit + 1e-12
        self.problem.u[:] = s if ok else np.nan
        status = CONVERGED if ok else MAX_ITERATIONS
        return NewtonResult(status, 3 if ok else 10, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0)


def _run(limit: float, first_step: float, **settings: Any) -> tuple[_ScriptedNewton, Any]:
    newton = _ScriptedNewton(limit, NewtonSettings(**settings))

    def load(s: float) -> LoadState:
        newton.s = s
        return LoadState(np.zeros(0), None)

    res = continuation(newton, np.zeros(0, dtype=np.int32), load, first_step=first_step)  # type: ignore[arg-type]
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

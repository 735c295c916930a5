"""Load paths as data: a `LoadStep` record says where a step starts from, the dead loads it
sets, the Dirichlet conditions it ramps to, whether the out-of-balance force of its start is
released, and the contact penalty it ramps; `run_load_step` runs any such record on a
`woundsweep.physics.model.WoundModel` with the one continuation policy.

The six stages (`woundsweep.physics.stages`), the sutured closure and the load after closure
(`woundsweep.physics.sutures`) are records of this kind (docs/design.md, "Stages as recipes").
Over a step's load factor s in [0, 1] (`woundsweep.solver.continuation`): the Dirichlet
values move linearly from where the start has them to their targets; the out-of-balance force
of the start under the step's loads is released linearly (R(u) - (1 - s) R(u_start) = 0 at
the free dofs), so s = 0 is exactly the starting state; the penalty grows geometrically.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core.schema import StageStatus
from ..solver.continuation import ContinuationResult, LoadState, continuation
from ..solver.dirichlet import Dirichlet
from ..solver.newton import Policy
from .model import WoundModel

__all__ = [
    "SUPPORT_ROUNDS",
    "SUPPORT_TOL",
    "LoadStep",
    "PenaltyRamp",
    "SetUp",
    "Solve",
    "StepResult",
    "combine",
    "run_load_step",
    "set_up",
    "settle_support",
]

# A contact step's state is accepted when no engaged point's support step differs from the
# one it was solved with by more than SUPPORT_TOL; at most SUPPORT_ROUNDS re-solves get it there.
SUPPORT_TOL, SUPPORT_ROUNDS = 1e-3, 3
# The counts and times of a `ContinuationResult` that add up over consecutive solves.
_SUMMED = ("iterations", "increments", "cuts", "assembly_time_s", "factor_time_s",
           "solve_time_s", "residual_time_s")  # fmt: skip


class Solve(enum.Enum):
    """How a step's Newton solves are run (`woundsweep.solver.newton.Policy`)."""

    DEAD_LOADS = "dead-loads"  # every load dead: symmetric tangent, the residual rule
    CONTACT = "contact"  # `Policy.contact`: the semi-smooth contact step's overshoots allowed


@dataclass(frozen=True)
class PenaltyRamp:
    """The flank contact's penalty over a step: ``before_kPa`` at the start (the penalty the
    start's out-of-balance force is taken at; 0 is contact off), then geometrically from
    ``from_kPa`` to ``to_kPa``. The first increment spans ``first_decades`` of it and none
    more than ``max_decades`` (None: the whole ramp in one increment, halved if needed)."""

    from_kPa: float
    to_kPa: float
    before_kPa: float = 0.0
    first_decades: float | None = None
    max_decades: float | None = None

    def penalty(self, s: float) -> float:
        """The penalty at load factor ``s``, kPa."""
        return self.from_kPa ** (1.0 - s) * self.to_kPa**s

    def increments(self) -> tuple[float, float]:
        """(first, largest) increment of the load factor."""
        decades = max(float(np.log10(self.to_kPa / self.from_kPa)), 1e-9)

        def share(d: float | None) -> float:
            return 1.0 if d is None else min(1.0, d / decades)

        return share(self.first_decades), share(self.max_decades)


@dataclass(frozen=True, eq=False)
class LoadStep:
    """One continuation of a load path (module docstring). Fields left None leave the model's
    state as it is."""

    name: str
    hold: tuple[Dirichlet, ...]  # the conditions at the end; values None: held at the start
    start: np.ndarray | None = None  # the displacement it starts from (flat dofs, mm)
    traction: tuple[object, object] | None = None  # lateral faces' P per layer (dermis, subcutis)
    closure_forces: np.ndarray | None = None  # dead nodal closing forces (flat dofs, mN)
    release: bool = True  # release the start's out-of-balance force over the step
    penalty: PenaltyRamp | None = None
    tie_at_start: bool = False  # the tie's reference is the start state
    solve: Solve = Solve.DEAD_LOADS
    first_step: float | None = None  # the first increment (None: 1 / load_steps)
    settle_support: bool = False  # re-solve until the contact support is the one solved with


@dataclass(frozen=True, eq=False)
class StepResult:
    """What `run_load_step` did: the continuation's outcome, the Dirichlet condition it ended
    under, and the penalty at the load it reached (kPa; None without a ramp)."""

    solve: ContinuationResult
    bc: Dirichlet
    penalty_reached_kPa: float | None


class SetUp(NamedTuple):
    """A `LoadStep` set up on a model: what the continuation takes."""

    load: Callable[[float], LoadState]  # the condition and offset at load factor s
    force_scale: float  # mN: the internal force's norm at the start
    policy: Policy
    first: float | None  # the first increment (None: 1 / load_steps)
    largest: float  # the largest increment
    end: Dirichlet  # the condition at s = 1


def set_up(model: WoundModel, step: LoadStep) -> SetUp:
    """Put ``model`` at ``step``'s start (state, loads, tie, penalty) and build its ramp: at
    s = 0 the start is in equilibrium."""
    u = model.u
    problem, contact = model.problem, model.contact
    if step.traction is not None:
        model.forms.set_loads(*step.traction)
    if step.start is not None:
        u[:] = step.start
    if step.closure_forces is not None:
        problem.closure_load = step.closure_forces
    if step.tie_at_start and model.tie is not None:
        model.tie.set_reference(u)
    ramp = step.penalty
    if ramp is not None:
        if contact is None:
            raise ValueError(f"{step.name}: a penalty ramp needs a wound's flank contact")
        contact.reset_timers()
        contact.k_V_kPa = ramp.before_kPa
    offset = problem.residual_array() if step.release else None
    start = Dirichlet.union([Dirichlet(h.rows) for h in step.hold], u)
    end = Dirichlet.union(step.hold, u)
    if offset is not None:
        offset[start.rows] = 0.0
    scale = float(np.linalg.norm(problem.internal_force()))

    def load(s: float) -> LoadState:
        if ramp is not None:
            assert contact is not None
            contact.k_V_kPa = ramp.penalty(s)
        off = None if offset is None else (1.0 - s) * offset
        return LoadState(start.toward(end, s), off)

    if step.solve is Solve.CONTACT:
        policy = Policy.contact(model.settings)
    else:
        policy = Policy(model.settings, symmetric=True)
    first, largest = (step.first_step, 1.0) if ramp is None else ramp.increments()
    return SetUp(load, scale, policy, first, largest, end)


def run_load_step(model: WoundModel, step: LoadStep) -> StepResult:
    """Set up ``step`` on ``model`` and solve it by load continuation; the contact is left at
    the ramp's end penalty whatever the outcome."""
    ramp = step.penalty
    try:
        run = set_up(model, step)
        res = continuation(
            model.newton, run.load, run.force_scale, run.first, run.policy, run.largest
        )
        if step.settle_support:
            res = settle_support(model, res, run)
    finally:
        if ramp is not None and model.contact is not None:
            model.contact.k_V_kPa = ramp.to_kPa
    reached = None if ramp is None else ramp.penalty(res.load_reached)
    return StepResult(res, run.end, reached)


def combine(first: ContinuationResult, then: ContinuationResult) -> ContinuationResult:
    """``then`` with the counts and times of ``first`` added: consecutive solves as one."""
    return then._replace(**{f: getattr(first, f) + getattr(then, f) for f in _SUMMED})


def settle_support(model: WoundModel, res: ContinuationResult, run: SetUp) -> ContinuationResult:
    """Newton holds each point's support step at the solve's start (`FlankContact.
    freeze_support`); a converged state is a result only if the support it reached is the
    one it was solved with, so it is solved again at the step's end load, support taken
    from it, until it is (at most ``SUPPORT_ROUNDS`` times; else max-iterations)."""
    c = model.contact
    assert c is not None
    rounds = 0
    while res.status == StageStatus.CONVERGED and c.support_change(model.u) > SUPPORT_TOL:
        if rounds == SUPPORT_ROUNDS:
            return res._replace(status=StageStatus.MAX_ITERATIONS)
        again = continuation(
            model.newton, lambda s: run.load(1.0), run.force_scale, 1.0, run.policy
        )
        res = combine(res, again)
        rounds += 1
    return res

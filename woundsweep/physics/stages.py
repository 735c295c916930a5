"""The six stages of primary-intention closure (paper: "Modeling primary intention in six
stages") as recipes (`woundsweep.physics.loadpath.LoadStep`) over a wound model.

1. Pre-tension: the lateral faces and the deep face stretched by the tension scaling factor.
2. The lateral Dirichlet conditions replaced by the traction of healthy skin; the closure
   zone's wound nodes moved onto the mid-plane (Dirichlet closure).
3. The closure's Dirichlet condition replaced by its consistent nodal reactions, a dead load.
4-6. Contact of the flanks at penalty k_V = 1, 5, 100 GPa, under the same closure load.

docs/model.md states each stage's boundary conditions and loads and why they depart from the
paper where they do; docs/design.md lists the records. `run_stage` builds a stage's record
from the model's state, runs it (`run_load_step`) and measures the state it reached.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse

from ..contact import ContactModel
from ..core.schema import DERMIS, STAGES, SUBCUTIS, StageStatus, start_stage
from ..solver.dirichlet import Dirichlet
from .domain import dof_rows
from .loadpath import LoadStep, PenaltyRamp, Solve, StepResult, run_load_step
from .model import StageOutcome, WoundModel
from .stability import lowest_eigenvalues

__all__ = [
    "CONTACT_MAX_DECADES",
    "CONTACT_START_kPa",
    "contact_ramp",
    "run_stage",
    "stability",
    "stage_recipe",
]

CONTACT_START_kPa = 1.0  # stage 4's penalty ramp starts here: far below the tissue moduli
# Stage 4's penalty grows by half a decade in its first increment and by at most this many
# decades per increment after it: larger jumps (increments double after easy ones) push the
# flanks apart faster than Newton can follow.
CONTACT_FIRST_DECADES, CONTACT_MAX_DECADES = 0.5, 1.5


def contact_ramp(to_kPa: float) -> PenaltyRamp:
    """Contact brought in from off: the penalty from `CONTACT_START_kPa` to ``to_kPa`` (stage
    4 and the sutured closure), so an overlap left by the closure is pushed out gradually
    instead of by a force of order k_V at once."""
    return PenaltyRamp(
        min(CONTACT_START_kPa, to_kPa), to_kPa, 0.0, CONTACT_FIRST_DECADES, CONTACT_MAX_DECADES
    )


def stage_recipe(model: WoundModel, stage: int) -> LoadStep:
    """Stage ``stage``'s record at the model's current state (the previous stage's result)."""
    if model.materials is None:
        raise RuntimeError("set_materials() first")
    d = model.domain
    gauge = Dirichlet(d.gauge_rows())
    if stage == 1:
        # Pre-tension (eqs. 12-14): u = (TSF - 1)(x - x_c) on the x faces, likewise in y, and
        # in-plane on the deep face (u_z = 0 there). Newton starts from the unwounded patch's
        # solution, which meets these conditions exactly: it corrects only the wound's
        # disturbance.
        tsf = model.materials.tsf
        hold = [
            Dirichlet(dof_rows(nodes, comp), (tsf - 1.0) * (d.X[nodes, comp] - centre))
            for nodes, comp, centre in (
                (d.x_face_nodes, 0, d.x_c),
                (d.y_face_nodes, 1, d.y_c),
                (d.bottom_nodes, 0, d.x_c),
                (d.bottom_nodes, 1, d.y_c),
            )
        ]
        hold.append(Dirichlet(dof_rows(d.bottom_nodes, 2), np.zeros(len(d.bottom_nodes))))
        start: np.ndarray | None = model.pretension_state().ravel()
        return LoadStep("pre-tension", tuple(hold), start, (0.0, 0.0), release=False)
    if stage == 2:
        # Healthy-skin traction on the lateral faces (eqs. 15-16) and the Dirichlet closure
        # u_x = x_c - x on the closure zone (eq. 18).
        P = model.homogeneous
        zone = Dirichlet(dof_rows(d.zone_nodes, 0), d.x_c - d.X[d.zone_nodes, 0])
        return LoadStep("dirichlet-closure", (gauge, zone), traction=(P[DERMIS].P, P[SUBCUTIS].P))
    assert model.closing_forces is not None, "stage 2 first"
    if stage == 3:
        # Closure by a load (eqs. 17, 19): the Dirichlet closure's consistent nodal reactions
        # of stage 2 as dead nodal forces (docs/model.md, "Closure load").
        return LoadStep("load-closure", (gauge,), closure_forces=model.closing_forces)
    if model.contact is None:  # no wound: nothing can touch; the stage re-solves stage 3's loads
        return LoadStep(f"contact-{stage}", (gauge,))
    # Stages 4-6: the closure load plus flank contact at this stage's penalty. Stage 4 restarts
    # from the stage-2 state (docs/model.md) with the closed zone tied where stage 2 closed it,
    # and brings the penalty up from contact off; stages 5 and 6 start in contact equilibrium
    # at the previous stage's penalty and are solved in one increment (a cut halves it).
    k_to = model.contact_penalty_kPa[stage - 4]
    start = None
    if stage == 4:
        ramp = contact_ramp(k_to)
        start = model.displacements[start_stage(4)]
    else:
        k_from = min(model.contact_penalty_kPa[stage - 5], k_to)
        ramp = PenaltyRamp(k_from, k_to, before_kPa=k_from)
    return LoadStep(
        f"contact-{stage}",
        (gauge,),
        start,
        closure_forces=model.closing_forces,
        penalty=ramp,
        tie_at_start=stage == 4,
        solve=Solve.CONTACT,
        settle_support=True,
    )


def run_stage(model: WoundModel, stage: int) -> StageOutcome:
    """Run one stage from the model's current state (the previous stage's result)."""
    if model.materials is None:
        raise RuntimeError("set_materials() first")
    if stage not in STAGES:
        raise ValueError(f"stage {stage} is not implemented (available: {STAGES})")
    if stage > 1 and stage - 1 not in model.results:
        raise RuntimeError(f"stage {stage} needs stage {stage - 1} first")
    t0 = time.perf_counter()
    step = run_load_step(model, stage_recipe(model, stage))
    if stage == 1:
        diag: dict[str, float] = {}
    elif stage == 2:
        diag = _closed_by_dirichlet(model)
    elif stage == 3:
        diag = _closed_by_load(model)
    else:
        diag = _in_contact(model, step)
    out = StageOutcome(stage, step.solve, time.perf_counter() - t0, diag)
    model.record(out)
    return out


def _closed_by_dirichlet(model: WoundModel) -> dict[str, float]:
    """Stage 2: the closure's reactions become the closing load of stages 3-6 (u_x is held,
    so they act along x only)."""
    d = model.domain
    r = model.problem.residual_array()
    zone_rows = dof_rows(d.zone_nodes, 0)
    model.hold_closure_reactions(r, zone_rows)
    return {
        "closure_force_left_mN": float(r[dof_rows(d.zone_left_nodes, 0)].sum()),
        "closure_force_right_mN": float(r[dof_rows(d.zone_right_nodes, 0)].sum()),
        "pin_reaction_max_mN": model.pin_reaction(r),
        "lateral_force_mN": model.lateral_force(),
    }


def _closed_by_load(model: WoundModel) -> dict[str, float]:
    """Stage 3: the closing load as a mean traction over the deformed zone, and the pins."""
    assert model.closing_forces is not None
    d = model.domain
    r = model.problem.residual_array()
    area = model.deformed_zone_area("left") + model.deformed_zone_area("right")
    total = float(np.abs(model.closing_forces[dof_rows(d.zone_nodes, 0)]).sum())
    return {
        "closure_traction_kPa": total / area if area > 0 else 0.0,
        "pin_reaction_max_mN": model.pin_reaction(r),
    }


def _in_contact(model: WoundModel, step: StepResult) -> dict[str, float]:
    """Stages 4-6: pins, tie and contact at the state reached, at the penalty it was reached
    with; where the stage stalled, the stability of that state (`stability.py`)."""
    c = model.contact
    if c is None or step.penalty_reached_kPa is None:
        return {}
    k_to = c.k_V_kPa
    diag: dict[str, float] = {}
    if step.solve.status != StageStatus.CONVERGED:
        # Stalled at a stable state, or at a limit point of the path?
        diag.update(stability(model, step.bc.rows, step.penalty_reached_kPa))
        c.k_V_kPa = step.penalty_reached_kPa
    try:
        diag.update(_contact_diagnostics(model, c))
    finally:
        c.k_V_kPa = k_to
    return diag


def _contact_diagnostics(model: WoundModel, c: ContactModel) -> dict[str, float]:
    """Pin reaction, tie and contact forces and penetration at ``c``'s penalty."""
    u = model.u
    diag: dict[str, float] = {}
    r = model.problem.residual_array()
    diag["pin_reaction_max_mN"] = model.pin_reaction(r)
    diag["contact_penalty_kPa"] = c.k_V_kPa
    if model.tie is not None:
        diag["tie_force_mN"] = model.tie.force_mN(u, c.k_V_kPa)
        diag["tie_max_slip_mm"] = float(np.max(np.abs(model.tie.slip(u)), initial=0.0))
    detect, assemble, searches = c.detect_time_s, c.assembly_time_s, c.searches
    summ = c.summary(u)
    diag.update(
        {
            "n_penetrating": summ.n_penetrating,
            "max_penetration_mm": summ.max_penetration_mm,
            "max_penetration_rel": summ.max_penetration_rel,
            "contact_force_mN": summ.contact_force_mN,
            "contact_detect_time_s": detect,
            "contact_assembly_time_s": assemble,
            "contact_searches": searches,
        }
    )
    return diag


def stability(model: WoundModel, rows: np.ndarray, k_V_kPa: float) -> dict[str, float]:
    """Lowest eigenvalue nearest zero (mN/mm) of the free-dof tangent at the current state
    with penalty ``k_V_kPa`` (NaN if it cannot be computed). With the dead closure load
    every load is dead, so the tangent is the Hessian of the total potential and its sign
    decides the stability of that equilibrium."""
    c = model.contact
    assert c is not None
    A = model.problem.A
    saved = c.k_V_kPa
    c.k_V_kPa = k_V_kPa
    c.mult = None  # the potential's own Hessian, not a failed solve's semi-smooth tangent
    free = np.ones(A.getSize()[0], dtype=bool)
    free[rows] = False
    try:
        model.problem.jacobian(A)
        ai, aj, av = A.getValuesCSR()
        K = scipy.sparse.csr_matrix((av, aj, ai), shape=A.getSize())
        try:
            eig = float(lowest_eigenvalues(K, free)[0])
        except ArithmeticError:
            eig = float("nan")
    finally:
        c.k_V_kPa = saved
    return {"stability_min_eig_mN_per_mm": eig, "stability_penalty_kPa": k_V_kPa}

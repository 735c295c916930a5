"""The six stages of primary-intention closure (paper: "Modeling primary intention in six
stages") as recipes (`woundsweep.physics.loadpath.LoadStep`) over a wound model.

1. Pre-tension: the lateral faces and the deep face stretched by the tension scaling factor.
2. The lateral Dirichlet conditions replaced by the traction of healthy skin; the closure
   zone's wound nodes moved onto the mid-plane (Dirichlet closure).
3. The closure's Dirichlet condition replaced by a closing load, dead, chosen by the stage
   settings' ``closure_load`` (`woundsweep.config.paper.CLOSURE_LOADS`): the Dirichlet
   closure's consistent nodal reactions; the published code's uniform traction; or a
   uniform traction on the zone's dermal part whose amplitude is solved so that the zone's
   median surface gap is zero (`woundsweep.physics.closing`).
4-6. Contact of the flanks at penalty k_V = 1, 5, 100 GPa, under the same closing load.

docs/model.md states each stage's boundary conditions and loads and why they depart from the
paper where they do; docs/design.md lists the records. `run_stage` builds a stage's record
from the model's state, runs it (`run_load_step`) and measures the state it reached.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import scipy.sparse

from ..contact import ContactModel, audit_model
from ..core.schema import DERMIS, STAGES, SUBCUTIS, StageStatus, start_stage
from ..solver.dirichlet import Dirichlet
from .closing import code_traction_facets, code_traction_kPa, dermal_zone_facets, traction_shape
from .closure import OVERLAP_PER_W
from .domain import dof_rows
from .loadpath import LoadStep, PenaltyRamp, Solve, StepResult, combine, run_load_step
from .model import StageOutcome, WoundModel
from .stability import lowest_eigenvalues

__all__ = [
    "AMPLITUDE_SOLVES",
    "AMPLITUDE_TOL_PER_W",
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
# The solved closure's amplitude: adjusted in stage 3 until the zone's median surface gap is
# within AMPLITUDE_TOL_PER_W of the wound width, at most AMPLITUDE_SOLVES solves. Stages 4-6
# hold it: under contact the median gap is not monotone in the amplitude (the flanks pressed
# together in the middle bulge apart beside it), so it has no well-posed root there.
AMPLITUDE_TOL_PER_W, AMPLITUDE_SOLVES = 1e-6, 12


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
        # Pre-tension (eqs. 12-14): the healthy state's in-plane displacement
        # u = (TSF - 1)(x - x_c, y - y_c) on the lateral faces (both components: at an oblique
        # Langer line healthy skin carries an in-plane shear there) and on the deep face
        # (u_z = 0 there). Newton starts from the unwounded patch's solution, which meets
        # these conditions exactly: it corrects only the wound's disturbance.
        tsf = model.materials.tsf
        lateral = np.union1d(d.x_face_nodes, d.y_face_nodes)
        hold = [
            Dirichlet(dof_rows(nodes, comp), (tsf - 1.0) * (d.X[nodes, comp] - centre))
            for nodes in (lateral, d.bottom_nodes)
            for comp, centre in ((0, d.x_c), (1, d.y_c))
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
        # Closure by a load (eqs. 17, 19), dead nodal forces held from stage 2 (docs/model.md,
        # "Closure load"); from the stage-2 state, without contact.
        return LoadStep("load-closure", (gauge,), closure_forces=model.closing_forces)
    if model.contact is None:  # no wound: nothing can touch; the stage re-solves stage 3's loads
        return LoadStep(f"contact-{stage}", (gauge,))
    # Stages 4-6: the closing load plus flank contact at this stage's penalty. Stage 4 starts
    # where the closure says (`schema.start_stage`): the reactions' from the stage-2 state
    # with the closed zone tied where stage 2 closed it, the published code's from stage 1,
    # the solved closure's from stage 3; it brings the penalty up from contact off. Stages 5
    # and 6 start in contact equilibrium at the previous stage's penalty and are solved in
    # one increment (a cut halves it).
    k_to = model.contact_penalty_kPa[stage - 4]
    start = None
    if stage == 4:
        ramp = contact_ramp(k_to)
        start = model.displacements[start_stage(4, model.closure_load)]
    else:
        k_from = min(model.contact_penalty_kPa[stage - 5], k_to)
        ramp = PenaltyRamp(k_from, k_to, before_kPa=k_from)
    return LoadStep(
        f"contact-{stage}",
        (gauge,),
        start,
        closure_forces=model.closing_forces,
        penalty=ramp,
        tie_at_start=stage == 4 and model.tie is not None,
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
    solves = None
    if stage == 3 and model.closure_load == "solved" and model.closure_line is not None:
        step, solves = _solve_amplitude(model)
    else:
        step = run_load_step(model, stage_recipe(model, stage))
    if stage == 1:
        diag: dict[str, float] = {}
    elif stage == 2:
        diag = _closed_by_dirichlet(model)
    elif stage == 3:
        diag = _closed_by_load(model)
    else:
        diag = _in_contact(model, step)
    if stage >= 2 and step.solve.status == StageStatus.CONVERGED:
        diag.update(_audit(model))
    if stage >= 3 and model.closing_traction_kPa is not None:
        diag["closing_traction_kPa"] = model.closing_traction_kPa
    if solves is not None:
        diag["closing_amplitude_solves"] = solves
    out = StageOutcome(stage, step.solve, time.perf_counter() - t0, diag)
    model.record(out)
    return out


def _closing_load(model: WoundModel, r: np.ndarray) -> None:
    """Stage 2's end: keep the closing load of stages 3-6 (`StageSettings.closure_load`).
    ``r`` is the residual, whose zone rows are the Dirichlet closure's reactions (u_x is
    held, so they act along x only)."""
    d = model.domain
    if model.closure_load == "reactions" or not d.has_wound:
        model.hold_closure_reactions(r, dof_rows(d.zone_nodes, 0))
        return
    assert model.materials is not None
    if model.closure_load == "paper-code":
        shape = traction_shape(d, code_traction_facets(d))
        model.hold_closing_traction(shape, code_traction_kPa(d, model.u, model.materials))
        return
    # The solved closure starts from the amplitude whose total force on the left flank is
    # the Dirichlet closure's.
    shape = traction_shape(d, dermal_zone_facets(d))
    left = dof_rows(d.zone_left_nodes, 0)
    unit = float(shape[shape > 0].sum())
    model.hold_closing_traction(shape, float(r[left].sum()) / unit if unit > 0 else 0.0)


def _amplitude_step(model: WoundModel, recipe: LoadStep) -> LoadStep:
    """``recipe`` re-solved from the current state with the model's closing load: the load
    moves linearly from the last amplitude to the new one."""
    return replace(
        recipe,
        name=f"{recipe.name}-amplitude",
        start=None,
        closure_forces=model.closing_forces,
    )


def _next_amplitude(tried: list[tuple[float, float]]) -> float:
    """The next amplitude from the (amplitude, median gap) pairs so far, the gap falling as
    the amplitude grows: a secant step from the last two (10 % the way the gap asks for the
    first, or where the gap does not fall), held within a factor of two and, once amplitudes
    on both sides of a closed gap are known, inside that bracket (else its midpoint)."""
    a1, g1 = tried[-1]
    step = 1.1 if g1 > 0 else 0.9
    if a1 == 0.0:
        return 1.0
    nxt = a1 * step
    if len(tried) > 1:
        a0, g0 = tried[-2]
        slope = (g1 - g0) / (a1 - a0) if a1 != a0 else 0.0
        if slope < 0.0:
            nxt = float(np.clip(a1 - g1 / slope, 0.5 * a1, 2.0 * a1))
    opened = [a for a, g in tried if g > 0]
    passed = [a for a, g in tried if g < 0]
    if opened and passed:
        lo, hi = max(opened), min(passed)
        if not lo < nxt < hi:
            nxt = 0.5 * (lo + hi)
    return nxt


def _solve_amplitude(model: WoundModel) -> tuple[StepResult, int]:
    """Stage 3 of the solved closure: its record solved, then the closing traction's
    amplitude adjusted (`_next_amplitude`), each adjustment a load step from the state before,
    until the zone's median surface gap is within `AMPLITUDE_TOL_PER_W` of w. Returns the
    step (max-iterations when the solves run out) and the number of solves."""
    line = model.closure_line
    forces, amp = model.closing_forces, model.closing_traction_kPa
    assert line is not None and forces is not None and amp is not None
    shape = forces / amp if amp else forces
    tol = AMPLITUDE_TOL_PER_W * line.width_mm
    recipe = stage_recipe(model, 3)
    step = run_load_step(model, recipe)
    tried: list[tuple[float, float]] = []
    for solves in range(1, AMPLITUDE_SOLVES + 1):
        if step.solve.status != StageStatus.CONVERGED:
            return step, solves
        gap = line.measure(model.u).gap_median_mm
        if abs(gap) <= tol:
            return step, solves
        tried.append((amp, gap))
        amp = _next_amplitude(tried)
        model.hold_closing_traction(shape, amp)
        again = run_load_step(model, _amplitude_step(model, recipe))
        step = replace(again, solve=combine(step.solve, again.solve))
    failed = step.solve._replace(status=StageStatus.MAX_ITERATIONS)
    return replace(step, solve=failed), AMPLITUDE_SOLVES + 1


def _audit(model: WoundModel) -> dict[str, float]:
    """The independent interpenetration audit of the state (`woundsweep.contact.audit`): flank
    nodes inside the other side's deformed tissue deeper than `OVERLAP_PER_W` of w."""
    line = model.closure_line
    if line is None:
        return {}
    found = audit_model(model, OVERLAP_PER_W * line.width_mm)
    return {"audit_inside_nodes": found.n_inside, "audit_max_depth_mm": found.max_depth_mm}


def _closed_by_dirichlet(model: WoundModel) -> dict[str, float]:
    """Stage 2: the reactions, the pins, the load scale; the closing load of stages 3-6
    (`_closing_load`)."""
    d = model.domain
    r = model.problem.residual_array()
    _closing_load(model, r)
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
            "contact_fade_points": summ.n_fade_points,
            "contact_fade_force_share": summ.fade_force_share,
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
        lr = model.problem.low_rank()
        if lr is not None:  # the threads' tangent, kept out of A
            K = (K + lr[0] @ scipy.sparse.diags(lr[1]) @ lr[0].T).tocsr()
        try:
            eig = float(lowest_eigenvalues(K, free)[0])
        except ArithmeticError:
            eig = float("nan")
    finally:
        c.k_V_kPa = saved
    return {"stability_min_eig_mN_per_mm": eig, "stability_penalty_kPa": k_V_kPa}

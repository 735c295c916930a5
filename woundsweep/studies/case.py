"""One clinical case solved (`woundsweep case`): the sutured closure at the case's angle, the
load after closure and the same load along the scan's other directions, a placement that
evens the suture forces (found by re-solving), the site's band of skin types (its ends solved
again on the same mesh), the same wound along the Langer line and the sutured closure on a
mesh with elements half the size (docs/model.md, "Sutures"; docs/design.md, "case").
Each part's solves and wall time are kept (`Cost`) for the report.

Evening the forces: a suture's force is about the closing load of the stretch of wound it
holds, the part of the wound nearer to it than to its neighbours. From a solve, the load per
length of each suture's stretch is its force over the stretch's length; the sutures are moved
to the quantiles (i + 1/2) / n of that piecewise-constant load along the wound, and the
wound is solved again, `EVEN_ROUNDS` times; the placement with the smallest ratio of the
largest to the smallest force is kept.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from ..config.case import (
    MESH_CHECK_FACTOR,
    ClinicalCase,
    OPEN_GAP_mm,
    SCAN_TO_WOUND_deg,
    line_angle,
)
from ..config.geometry import FINEST_FACTOR
from ..config.solver import SolverSettings
from ..config.sutures import ItchLoad
from ..core.errors import SolverError
from ..core.schema import ExitCode, StageStatus
from ..physics.materials import JobMaterials
from ..physics.suture_measures import SurfacePatch, SutureState
from ..physics.sutures import SolveStep, SuturedClosure
from .case_view import CaseView, ViewState, capture_state, case_view

__all__ = [
    "CONVERGE_RATIO",
    "EVEN_ROUNDS",
    "ITCH_STEPS",
    "SCAN_STEPS",
    "BandEnd",
    "CaseResult",
    "Cost",
    "LoadRun",
    "MeshLevel",
    "ThreadRun",
    "even_positions",
    "run_case",
    "run_threads",
]

EVEN_ROUNDS = 2
ITCH_STEPS = 4
# The direction scan's and the band ends' loads in two steps each (each of the case's four
# converges in about 3 Newton steps; the end state, not the path, is reported).
SCAN_STEPS = 2
# `--converge`: two more meshes, each this much finer (mesh size factor) than the last:
# element sizes 1.31 times smaller per level.
CONVERGE_RATIO = 2.25
# The mesh check's meshes tried at most until the element size at the wound is halved.
CHECK_MESHES = 4


class MeshLevel(NamedTuple):
    """The sutured closure on one mesh of a convergence check."""

    mesh_size_factor: float
    dofs: int
    suture_force_mN: np.ndarray
    dog_ear_height_mm: float
    gap_max_mm: float = float("nan")  # the largest surface gap after suturing
    h_ratio: float = float("nan")  # the case mesh's element size at the wound over this one's


class CaseNotSolved(SolverError):
    """A solve of the case did not converge (exit 3)."""

    exit_code = ExitCode.NOT_CONVERGED


class LoadRun(NamedTuple):
    """The load after closure along one direction, step by step."""

    load: ItchLoad
    to_wound_deg: float  # [0, 180) from the wound's long axis (`ClinicalCase.to_wound_deg`)
    steps: list[SolveStep]

    @property
    def last(self) -> SutureState | None:
        """The last converged step's state."""
        return next((s.state for s in reversed(self.steps) if s.state is not None), None)


class BandEnd(NamedTuple):
    """The case solved with another skin type of the site's band."""

    skin_type: str
    sutured: SutureState
    loaded: LoadRun | None


class Cost(NamedTuple):
    """The solves of one part of a case and their wall time."""

    solves: int
    time_s: float


class ThreadRun(NamedTuple):
    """The case closed by threads (`SuturedClosure.thread`), every knot drawn with one
    tension until the walls meet under every suture, and the case's load after closure."""

    status: str  # "converged", or `NOT_APPOSED` if no trial's tension landed on the aim
    sutured: SutureState  # suture_force_mN: each thread's tension
    pull_mN: np.ndarray  # each thread's pull on a flank toward the wound (about 2 T)
    apposition_mN: np.ndarray  # the stage-2 Dirichlet pull over each suture's stretch
    shortening_mm: np.ndarray  # how much shorter than at apposition each loop is tied
    gap_at_suture_mm: np.ndarray  # the surface gap under each suture
    approach_mm: np.ndarray  # the walls' closest approach under each (the tying rule's)
    bite_pressure_kPa: np.ndarray  # the largest compressive stress under each one's bites
    loaded_bite_pressure_kPa: np.ndarray | None  # the same at the load's end (None: not reached)
    loaded: LoadRun
    solves: int
    view_state: ViewState | None = None  # the closed state for view.html (`run_case(view=True)`)


class CaseResult(NamedTuple):
    case: ClinicalCase
    dofs: int
    closing_force_mN: float  # the stage-2 Dirichlet closure's pull on the left flank
    closed: SutureState  # stage 2
    sutured: SutureState
    itch: list[SolveStep]
    evened: list[SutureState]  # each re-solved placement
    along: SutureState | None  # the same wound along the Langer line (None at angle 0)
    along_closing_force_mN: float | None
    time_s: float
    levels: list[MeshLevel]  # the mesh convergence check (empty without it)
    surface: SurfacePatch  # the sutured skin surface around the wound
    band: list[BandEnd] = []  # the band's ends other than the case's skin type
    scan: list[LoadRun] = []  # the other directions of the load (empty without the scan)
    mesh_check: MeshLevel | None = None  # h at least halved (None: skipped)
    costs: dict[str, Cost] = {}
    view: CaseView | None = None  # the fields of view.html (`run_case(view=True)`)
    threads: ThreadRun | None = None  # the closure by threads (`run_case(threads=True)`)

    @property
    def loaded(self) -> LoadRun:
        """The case's load after closure."""
        load = self.case.load
        return LoadRun(load, self.case.to_wound_deg(load), self.itch)


def even_positions(
    ys: np.ndarray, forces: np.ndarray, half_length: float, end_margin: float
) -> np.ndarray:
    """Positions (module docstring) of len(ys) sutures carrying equal shares of the load
    per length that ``forces`` at ``ys`` imply, within ``half_length - end_margin`` of the
    centre."""
    ys = np.asarray(ys, dtype=float)
    n = len(ys)
    edges = np.concatenate([[-half_length], 0.5 * (ys[1:] + ys[:-1]), [half_length]])
    load = np.maximum(np.asarray(forces, dtype=float), 1e-9)
    cum = np.concatenate([[0.0], np.cumsum(load)])
    targets = (np.arange(n) + 0.5) / n * cum[-1]
    new = np.interp(targets, cum, edges)
    lim = half_length - end_margin
    return np.clip(new, -lim, lim)


def _spread(f: np.ndarray) -> float:
    return float(f.max() / max(f.min(), 1e-9))


def run_case(
    case: ClinicalCase,
    echo: Callable[[str], None] = print,
    compare: bool = True,
    even: bool = True,
    converge: bool = False,
    band: bool = True,
    scan: bool = True,
    mesh_check: bool = True,
    view: bool = False,
    threads: bool = False,
) -> CaseResult:
    """Solve ``case`` (module docstring); with ``band`` also the site's other skin types, with
    ``scan`` the load along `SCAN_TO_WOUND_deg`, with ``mesh_check`` the sutures on a mesh
    `MESH_CHECK_FACTOR` times finer, with ``converge`` on two finer meshes
    (`CONVERGE_RATIO`), with ``view`` the sutured state's fields (and the load's end's) for
    view.html (`case_view`), with ``threads`` the closure by threads (`run_threads`);
    CaseNotSolved if a solve does not converge."""
    from ..mesh.build import build_mesh, edge_length_near_mm

    t0 = time.perf_counter()
    costs: dict[str, Cost] = {}
    spec = case.geometry()
    echo(f"mesh: {spec.describe()}")
    mesh = build_mesh(spec)
    solver = SolverSettings(element_degree=case.element_degree)
    sc = SuturedClosure(mesh, spec.lens(), case.zone_depth_fraction, solver)
    echo(f"model: {sc.domain.n_dofs} dofs, P{case.element_degree}")

    def close(angle: float, skin: str) -> tuple[SutureState, float]:
        orientation = 90.0 - angle
        steps = sc.close(JobMaterials.table2(skin, orientation), orientation)
        for k, st in enumerate(steps, 1):
            echo(
                f"  stage {k}: {st.status} ({st.newton_iterations} Newton steps, {st.time_s:.1f} s)"
            )
        if steps[-1].status != StageStatus.CONVERGED or len(steps) < 2:
            raise CaseNotSolved(f"stage {len(steps)} {steps[-1].status} at {angle:g} degrees")
        assert steps[-1].state is not None
        force = float(sc.model.results[2].diagnostics["closure_force_left_mN"])
        return steps[-1].state, force

    def suture(ys: np.ndarray | None, what: str) -> SutureState:
        try:
            st = sc.suture(case.sutures, None if ys is None else tuple(ys))
        except ValueError as err:
            raise CaseNotSolved(f"{what}: {err}") from None
        echo(f"  {what}: {st.status} ({st.newton_iterations} Newton steps, {st.time_s:.1f} s)")
        if st.state is None:
            raise CaseNotSolved(f"{what}: {st.status}")
        return st.state

    def load(to_wound: float | None, steps: int) -> LoadRun:
        it = case.load_at(to_wound)
        to_w = case.to_wound_deg(it)
        echo(
            f"load after closure: {it.kind} {it.strain:g} at {to_w:g} degrees to the wound "
            f"({abs(line_angle(it.angle_to_langer_deg)):g} to the Langer line)"
        )
        done = sc.itch(it, steps)
        for j, st in enumerate(done, 1):
            echo(
                f"  {j}/{steps}: {st.status} ({st.newton_iterations} Newton steps, {st.time_s:.1f} s)"
            )
        return LoadRun(it, to_w, done)

    def timed(name: str, solves: int, since: float) -> float:
        now = time.perf_counter()
        costs[name] = Cost(solves, now - since)
        return now

    echo(f"closure at {case.angle_deg:g} degrees to the Langer line")
    closed, closing = close(case.angle_deg, case.skin_type)
    sutured = suture(None, "sutures")
    surface = sc.surface(case.sutures.bite_width_mm)
    seen: list[ViewState] = [capture_state(sc, "sutured")] if view else []
    itch = load(case.itch_to_wound_deg, ITCH_STEPS).steps
    if view and len(itch) == ITCH_STEPS and itch[-1].state is not None:
        seen.append(capture_state(sc, "at the end of the load after closure"))
    shown = case_view(sc, case.sutures.bite_width_mm, seen) if view else None
    t = timed("case", 3 + ITCH_STEPS, t0)
    scanned: list[LoadRun] = []
    if scan:
        main = case.to_wound_deg(case.load)
        for d in SCAN_TO_WOUND_deg:
            if abs(line_angle(d - main)) > 1e-6:  # the case's own load is solved already
                scanned.append(load(d, SCAN_STEPS))
        t = timed("scan", SCAN_STEPS * len(scanned), t)
    evened: list[SutureState] = []
    if even and len(sutured.suture_y_mm) > 1:
        state = sutured
        for r in range(EVEN_ROUNDS):
            ys = even_positions(
                state.suture_y_mm, state.suture_force_mN, case.length_mm / 2,
                0.5 * case.sutures.bite_width_mm,
            )  # fmt: skip
            try:
                state = suture(ys, f"evened placement {r + 1}")
            except CaseNotSolved as err:
                echo(f"  evened placement {r + 1} stopped: {err}")
                break
            evened.append(state)
        t = timed("even", len(evened), t)
    ends: list[BandEnd] = []
    for skin in case.band if band else ():
        if skin == case.skin_type:
            continue
        echo(f"{skin} skin (the band's end)")
        close(case.angle_deg, skin)
        ends.append(
            BandEnd(skin, suture(None, "sutures"), load(case.itch_to_wound_deg, SCAN_STEPS))
        )
    if ends:
        t = timed("band", len(ends) * (3 + SCAN_STEPS), t)
    along = along_force = None
    if compare and case.angle_deg != 0:
        echo("the same wound along the Langer line")
        _, along_force = close(0.0, case.skin_type)
        along = suture(None, "sutures")
        t = timed("compare", 3, t)
    threaded = None
    if threads:
        threaded = run_threads(case, mesh, spec.lens(), echo, view)
        if shown is not None and threaded.view_state is not None:
            shown = shown._replace(states=[*shown.states, threaded.view_state])
        t = timed("threads", threaded.solves, t)
    check = None
    if mesh_check:
        m_check, fine, ratio = _check_mesh(case, edge_length_near_mm(mesh, spec))
        check = _level(case, m_check, echo, fine, ratio)
        t = timed("mesh check", 3, t)
    levels = [
        MeshLevel(case.mesh_size_factor, sc.domain.n_dofs, sutured.suture_force_mN,
                  sutured.dog_ear_height_mm)
    ] if converge else []  # fmt: skip
    for k in (1, 2) if converge else ():
        m = case.mesh_size_factor * CONVERGE_RATIO**k
        if m > FINEST_FACTOR:
            break
        levels.append(_level(case, m, echo))
    if converge:
        timed("converge", 3 * (len(levels) - 1), t)
    return CaseResult(
        case, sc.domain.n_dofs, closing, closed, sutured, itch, evened, along, along_force,
        time.perf_counter() - t0, levels, surface, ends, scanned, check, costs, shown, threaded,
    )  # fmt: skip


def run_threads(
    case: ClinicalCase, mesh: Any, lens: Any, echo: Callable[[str], None], view: bool = False
) -> ThreadRun:
    """The case's wound closed by threads on ``mesh`` (a model of its own: the footprints'
    tie and the threads do not share one), every knot drawn with one tension until the walls
    meet under every suture (their widest closest approach just below `OPEN_GAP_mm`), then the
    case's load after closure; with ``view`` the closed state for view.html."""
    sc = SuturedClosure(
        mesh, lens, case.zone_depth_fraction, SolverSettings(element_degree=case.element_degree)
    )
    echo("threads: the wound closed again, by 4-0 nylon threads")
    steps = sc.close(
        JobMaterials.table2(case.skin_type, case.orientation_deg), case.orientation_deg
    )
    if steps[-1].status != StageStatus.CONVERGED or len(steps) < 2:
        raise CaseNotSolved(f"threads: stage {len(steps)} {steps[-1].status}")
    ys = case.sutures.positions(case.length_mm)
    appose = sc.apposition_forces(ys)
    st = sc.thread(case.sutures, apposed_gap_mm=OPEN_GAP_mm)
    echo(f"  tied and drawn: {st.status} ({st.newton_iterations} Newton steps, {st.time_s:.1f} s)")
    if st.state is None:
        raise CaseNotSolved(f"threads: {st.status}")
    pull, gaps, short = sc.thread_pull(), sc.gaps_at_sutures(), sc.shortening_mm.copy()
    approach, bites = sc.approach_at_sutures(), sc.bite_pressure()
    seen = capture_state(sc, "closed by threads") if view else None
    load = case.load_at(case.itch_to_wound_deg)
    done = sc.itch(load, ITCH_STEPS)
    for j, step in enumerate(done, 1):
        echo(f"  load {j}/{ITCH_STEPS}: {step.status} ({step.newton_iterations} Newton steps)")
    solves = 2 + len(done) + 1
    reached = len(done) == ITCH_STEPS and done[-1].status == StageStatus.CONVERGED
    return ThreadRun(
        st.status, st.state, pull, appose, short, gaps, approach, bites,
        sc.bite_pressure() if reached else None, LoadRun(load, case.to_wound_deg(load), done),
        solves, seen,
    )  # fmt: skip


def _check_mesh(case: ClinicalCase, h_mm: float) -> tuple[float, Any, float]:
    """The mesh check's factor, mesh and element-size ratio at the wound (``h_mm``: the case
    mesh's, `edge_length_near_mm`): from `MESH_CHECK_FACTOR` times the case's factor, which
    halves the size law's field, raised until the realised size is halved too (gmsh keeps a
    coarse mesh finer than its field where the layers are thin), up to `FINEST_FACTOR`."""
    from ..mesh.build import build_mesh, edge_length_near_mm

    m = min(MESH_CHECK_FACTOR * case.mesh_size_factor, FINEST_FACTOR)
    for _ in range(CHECK_MESHES):
        spec = case.geometry(m)
        mesh = build_mesh(spec)
        ratio = h_mm / edge_length_near_mm(mesh, spec)
        if ratio >= 2.0 or m >= FINEST_FACTOR:
            break
        # h ~ m^(-1/3) in the law; aim a little past the halving.
        m = min(FINEST_FACTOR, m * (1.05 * 2.0 / ratio) ** 3)
    return m, mesh, ratio


def _level(
    case: ClinicalCase,
    m: float,
    echo: Callable[[str], None],
    mesh: Any = None,
    h_ratio: float = float("nan"),
) -> MeshLevel:
    """The sutured closure of ``case`` on the mesh of factor ``m`` (``mesh``: built already)."""
    from ..mesh.build import build_mesh

    spec = case.geometry(m)
    sc = SuturedClosure(
        build_mesh(spec) if mesh is None else mesh, spec.lens(), case.zone_depth_fraction,
        SolverSettings(element_degree=case.element_degree),
    )  # fmt: skip
    finer = f", elements {h_ratio:.2f} times smaller at the wound" if np.isfinite(h_ratio) else ""
    echo(f"mesh check: m = {m:.4g}, {sc.domain.n_dofs} dofs{finer}")
    steps = sc.close(
        JobMaterials.table2(case.skin_type, case.orientation_deg), case.orientation_deg
    )
    if steps[-1].status != StageStatus.CONVERGED or len(steps) < 2:
        raise CaseNotSolved(f"m = {m:.4g}: stage {len(steps)} {steps[-1].status}")
    st = sc.suture(case.sutures)
    echo(f"  sutures: {st.status} ({st.newton_iterations} Newton steps, {st.time_s:.1f} s)")
    if st.state is None:
        raise CaseNotSolved(f"m = {m:.4g}: sutures {st.status}")
    return MeshLevel(
        m, sc.domain.n_dofs, st.state.suture_force_mN, st.state.dog_ear_height_mm,
        float(st.state.gap_mm.max()), h_ratio,
    )  # fmt: skip


def best_evened(result: CaseResult) -> SutureState | None:
    """The evened placement with the smallest max/min force ratio, if it beats the plan's."""
    best = None
    for st in result.evened:
        if _spread(st.suture_force_mN) < _spread((best or result.sutured).suture_force_mN):
            best = st
    return best

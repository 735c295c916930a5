"""The closure in closed form: a slit of near-zero width through the whole patch, closed over
its whole length and depth, and the stage-3 identity of the `reactions` closure.

The patch is the two-layer skin (normal skin, paper moduli, orientation 0) with a slit of
width w = `SLIT_WIDTH_PER_L` L at x = 0 through its whole thickness and length, its walls the
closure zone (WOUND_ZONE). Stages 1-3 are the production ones (`physics.stages.run_stage` on
a `WoundModel`). Closed by stage 2 (healthy-skin traction P N on the lateral faces, the walls
moved onto x = 0), each half is in the homogeneous pre-stretched state F = diag(TSF, TSF,
lambda3) of its layer, translated by the half-width: exact in both elements (the field is
linear), but for the gauge pins on the walls' deep edge, which hold their stage-1 u_x, a
misfit of TSF w / 2 at two nodes (near-zero for a near-zero width). Equilibrium of a half
then gives the closing force per unit length along the wound in closed form:

    f = sum over the layers of P_xx t_layer,

P_xx of the layer's homogeneous state (`physics.materials.homogeneous_state`). The halves
are disjoint: the patch's mirror symmetries (the solver's symmetric subspace, so the slit
mesh is built as mirror images) hold the right half in y where the gauge pins hold the left.

The stage-3 identity of the `reactions` closure (stage 3 replaces the zone's condition by its
reactions as dead nodal forces: its state must be stage 2's, `docs/model.md`, "Closure
load") is checked on a wound (`stage3_identity`): on the slit, whose halves nothing but
the wall condition joins, stage 3's linear solves fail.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np

from ..config.solver import SolverSettings
from ..core.schema import DERMIS, SUBCUTIS, StageStatus
from ..physics.materials import JobMaterials
from .bvp import VerificationError
from .meshes import mirrored, slab, slit_walls

__all__ = ["SlitResult", "slit_closure", "stage3_identity"]

T_DERMIS, T_SUBCUTIS = 1.0, 1.0  # mm
HALF_X, HALF_Y = 2.0, 1.5  # each half's length across the slit, the patch's half-length (mm)
SLIT_WIDTH_PER_L = 1e-6  # the slit's width over HALF_X


class SlitResult(NamedTuple):
    """What the slit closure measured (stage 2)."""

    force_per_length: float  # mN/mm: the closure's reactions on one wall over the wound length
    expected_per_length: float  # mN/mm: sum of P_xx t over the layers
    misfit: float  # max |u - u_homogeneous| over the nodes, over (TSF - 1) HALF_X
    misfit_off_pins: float  # the same over the nodes not beside a gauge pin
    dofs: int
    time_s: float


def slit_mesh(degree: int, n: int = 2) -> Any:
    """The slit patch: two halves [-HALF_X, -w/2] and [w/2, HALF_X] (x), [-HALF_Y, HALF_Y]
    (y), [-T, 0] (z), each layer ``n`` grid boxes thick; walls tagged WOUND_ZONE."""
    del degree  # the same vertices for both elements
    w = SLIT_WIDTH_PER_L * HALF_X
    T = T_DERMIS + T_SUBCUTIS
    zs = np.r_[np.linspace(-T, -T_DERMIS, n + 1)[:-1], np.linspace(-T_DERMIS, 0.0, n + 1)]
    ys = np.linspace(-HALF_Y, HALF_Y, 2 * n + 1)

    def tag(mid: np.ndarray) -> np.ndarray:
        return np.where(mid[:, 2] > -T_DERMIS, DERMIS, SUBCUTIS)

    quarter = slab(np.linspace(-HALF_X, -w / 2, 2 * n + 1), ys[ys <= 0.0], zs, tag)
    half = mirrored(quarter, 1, 0.0, merge=True)
    return slit_walls(mirrored(half, 0, 0.0, merge=False), (-w / 2, w / 2))


def _expected(materials: JobMaterials) -> float:
    from ..physics.materials import homogeneous_state

    P_d = homogeneous_state(materials.dermis, materials.tsf).P[0, 0]
    P_s = homogeneous_state(materials.subcutis, materials.tsf).P[0, 0]
    return float(P_d * T_DERMIS + P_s * T_SUBCUTIS)


def _homogeneous(model: Any) -> np.ndarray:
    """Each half's homogeneous pre-stretched state with its wall on x = 0 (n, 3)."""
    X = model.domain.X
    s = model.materials.tsf
    w = SLIT_WIDTH_PER_L * HALF_X
    u = model.pretension_state()  # y and z: the unwounded patch's
    half = np.where(X[:, 0] > 0.0, w / 2, -w / 2)
    u[:, 0] = s * (X[:, 0] - half) - X[:, 0]
    return u


def _run(model: Any, stages: tuple[int, ...]) -> None:
    from ..physics.stages import run_stage

    for k in stages:
        out = run_stage(model, k)
        if out.solve.status != StageStatus.CONVERGED:
            raise VerificationError(f"stage {k}: {out.solve.status}")


def slit_closure(degree: int = 2, skin: str = "normal") -> SlitResult:
    """Stages 1-2 on the slit patch: the closing force per length and the state's misfit
    with the homogeneous state."""
    from ..physics.model import WoundModel

    t0 = time.perf_counter()
    model = WoundModel(slit_mesh(degree), SolverSettings(element_degree=degree))
    materials = JobMaterials.table2(skin, 0.0)
    model.set_materials(materials)
    _run(model, (1, 2))
    u2 = model.u.copy()
    d = model.domain
    force = abs(model.results[2].diagnostics["closure_force_left_mN"]) / (2.0 * HALF_Y)
    err = np.abs(u2.reshape(-1, 3) - _homogeneous(model)).max(axis=1)
    scale = (materials.tsf - 1.0) * HALF_X
    pins = d.X[[d.pin_a, d.pin_b, d.pin_c]]
    near = np.min(np.linalg.norm(d.X[:, None, :] - pins[None], axis=2), axis=1)
    spacing = HALF_X / 4
    return SlitResult(
        force, _expected(materials), float(err.max() / scale),
        float(err[near > 1.01 * spacing].max() / scale), len(u2), time.perf_counter() - t0,
    )  # fmt: skip


def stage3_identity(degree: int = 2) -> tuple[float, int]:
    """Stages 1-3 on a wounded patch (the demo's coarsest cylinder, normal skin, 0 degrees):
    max |u3 - u2| / max |u2| and the dofs."""
    from ..config.geometry import GeometrySpec
    from ..mesh.build import build_mesh
    from ..physics.model import WoundModel

    mesh = build_mesh(GeometrySpec.cylindrical(1.0, 1.0, 4.0, 1.2, 0.0, 0.3, element_degree=degree))
    model = WoundModel(mesh, SolverSettings(element_degree=degree))
    model.set_materials(JobMaterials.table2("normal", 0.0))
    _run(model, (1, 2))
    u2 = model.u.copy()
    _run(model, (3,))
    return float(np.abs(model.u - u2).max() / np.abs(u2).max()), len(u2)

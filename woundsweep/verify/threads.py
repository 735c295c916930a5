"""The sutures' threads in closed form: the slit of `woundsweep.verify.slit` closed by threads.

The slit patch (two-layer skin, normal skin, orientation 0, a slit of near-zero width through
its whole thickness and length) is closed by stages 1-2 (the walls held on x = 0: each half in
its homogeneous pre-stretched state). Then ``n`` sutures evenly spaced along the slit, each a
thread through the tissue around the points where it turns (`woundsweep.physics.thread`), are tied
at that state and the walls' condition is released: the threads alone join the halves.

Equilibrium of a half in x: the healthy-skin traction on its outer face pulls with f L (f =
sum over the layers of P_xx t, L the slit's length; the deep face is free in x and the pins
carry no load once the patch is balanced), and only the threads hold it, so

    sum over the sutures of 2 T_i = f L        (two strands cross the slit),

up to what the gauge pins on the slit's deep edge pass between the halves when they fall on
both walls (``pin_transfer_mN``, reported; a few per cent at most),

and, the sutures being evenly spaced on a translation-invariant slit, 2 T_i = f L / n for
every suture up to the patch's ends. Away from the slit the halves keep the homogeneous state,
and the more sutures, the closer to it (the slit between them opens less).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from ..config.solver import SolverSettings
from ..contact import Cables
from ..core.schema import StageStatus
from ..physics.materials import JobMaterials
from ..physics.thread import NYLON_4_0, SutureThread, needle_track, suture_loop
from ..solver.dirichlet import Dirichlet
from .bvp import VerificationError
from .slit import HALF_X, HALF_Y, T_DERMIS, _expected, _homogeneous, _run, slit_mesh

__all__ = ["BITE_WIDTH_mm", "RADIUS_mm", "SlitThreads", "slit_threads"]

BITE_WIDTH_mm = 0.75
RADIUS_mm = 0.3
# Away from the slit: the nodes at least this far from it (mm) measure the homogeneous state.
FAR_mm = 1.25


class SlitThreads(NamedTuple):
    """What the slit closed by threads measured."""

    sutures: int
    tension_mN: np.ndarray  # (n,) each thread's tension
    expected_pull_mN: float  # f L / n: each suture's share of the closed form
    total_pull_mN: float  # sum of 2 T
    expected_total_mN: float  # f L
    pin_transfer_mN: float  # what the gauge pins pass between the halves in x
    misfit_far: (
        float  # max |u - u_hom - its mean| per half, FAR_mm from the slit, / (TSF - 1) HALF_X
    )
    newton_iterations: int
    dofs: int
    time_s: float


def slit_threads(
    n: int, degree: int = 1, material: SutureThread = NYLON_4_0, grid: int = 2
) -> SlitThreads:
    """The slit closed by ``n`` threads (module docstring); ``grid``: grid boxes per layer
    thickness (`slit_mesh`)."""
    from ..physics.loadpath import LoadStep, Solve, run_load_step
    from ..physics.model import WoundModel

    t0 = time.perf_counter()
    model = WoundModel(slit_mesh(degree, grid), SolverSettings(element_degree=degree))
    materials = JobMaterials.table2("normal", 0.0)
    model.set_materials(materials)
    _run(model, (1, 2))
    u2 = model.u.copy()
    d = model.domain
    spacing = 2 * HALF_Y / n
    ys = -HALF_Y + spacing * (np.arange(n) + 0.5)
    tracks = [needle_track(d, 0.0, float(y), BITE_WIDTH_mm, T_DERMIS) for y in ys]
    cables = Cables(d.X, [suture_loop(d, t, RADIUS_mm) for t in tracks], material.EA_mN)
    model.attach_cables(cables)
    # Joined by the threads, the halves need the symmetric subspace no more (stage 2 used it
    # to hold the right half in y); the full space checks the threads' symmetry instead of
    # assuming it.
    model.use_symmetry = False
    model.set_newton_settings(model.settings)
    cables.tie(u2, 1e-3)
    step = LoadStep("thread-tie", (Dirichlet(d.gauge_rows()),), u2, solve=Solve.DEAD_LOADS)
    res = run_load_step(model, step).solve
    if res.status != StageStatus.CONVERGED:
        raise VerificationError(f"the slit's threads: {res.status}")
    T = cables.tensions(model.u)
    f_L = _expected(materials) * 2 * HALF_Y
    # The gauge pins sit on the slit's deep edge, on either wall: what they pass between the
    # halves, the x-reactions of those on the right one.
    r = model.problem.residual_array().reshape(-1, 3)
    pins = np.array([d.pin_a, d.pin_b, d.pin_c])
    right_pins = pins[d.X[pins, 0] > 0.0]
    # Away from the slit each half is in the homogeneous state up to its own translation (the
    # slit opens between and beneath the threads, which moves the halves apart).
    diff = model.u.reshape(-1, 3) - _homogeneous(model)
    far = np.abs(d.X[:, 0]) >= FAR_mm
    misfit = 0.0
    for half in (d.X[:, 0] < 0.0, d.X[:, 0] > 0.0):
        sel = far & half
        misfit = max(misfit, float(np.abs(diff[sel] - diff[sel].mean(axis=0)).max()))
    return SlitThreads(
        n, T, f_L / n, float(2 * T.sum()), f_L, float(-r[right_pins, 0].sum()),
        misfit / ((materials.tsf - 1.0) * HALF_X), int(res.iterations), len(model.u),
        time.perf_counter() - t0,
    )  # fmt: skip

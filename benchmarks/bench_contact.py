"""Cost of the contact terms against the finite-element assembly (woundsweep.contact).

Usage::

    python benchmarks/bench_contact.py     # about a minute

Solves stages 1-4 of the solver benchmark's mid-size paper wedge (soft skin, 90 degrees), then
times, at the converged stage-4 state, one contact force evaluation (neighbour search, gaps
and gradients; the cache is dropped before each), one contact tangent (with its Hessians),
one assembly of the finite-element residual and of its Jacobian, and one Jacobian with the
contact on as Newton assembles it (form, contact and tie in the preallocated matrix). A
Newton step evaluates each once, so the ratios say what share of a step the contact costs.
It also prints the PETSc mallocs of stage 4 and of the timed Jacobians (0 while the matrix's
pattern holds the contact's couplings), the growths of the contact's coupling pattern in
stage 4, and the matrix's nonzeros with and without the contact. Compare figures within one
run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from timing import median_ms  # noqa: E402

from woundsweep.config.geometry import GeometrySpec  # noqa: E402
from woundsweep.config.solver import SolverSettings  # noqa: E402
from woundsweep.mesh.build import build_mesh  # noqa: E402

__all__ = ["main"]


def main() -> int:
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    # Same geometry as bench_solver.py's "mid-size" job.
    T = 2.0
    mesh = build_mesh(
        GeometrySpec.wedge(1.0, 1.0, 2 * T, 0.3 * 2 * T, 0.5 * T, 0.5, element_degree=1)
    )
    model = WoundModel(mesh, SolverSettings(element_degree=1))  # P1
    model.set_materials(JobMaterials.table2("soft", 90.0))
    A = model.problem.A
    for k in range(1, 5):
        mallocs = A.getInfo()["mallocs"]
        out = run_stage(model, k)
        if out.solve.status != "converged":
            print(f"stage {k} did not converge ({out.solve.status}): no state to time")
            return 1
    stage4_mallocs = A.getInfo()["mallocs"] - mallocs
    c = model.contact
    assert c is not None
    u = model.u.copy()
    growths = c.pattern_growths

    def forces() -> None:
        c._cache_x = None  # drop the cached state: search, gaps and gradients again
        c.force_vector(u)

    def tangent() -> None:
        c._cache_x = None
        c.tangent_csr(u)

    engaged = int(np.sum(c.gaps(u) <= 0.0))
    t_f, t_k = median_ms(forces), median_ms(tangent)
    t_res = median_ms(lambda: model.problem.residual(model.newton.rvec))
    nnz_contact = int(A.getInfo()["nz_used"])
    mallocs = A.getInfo()["mallocs"]

    def jacobian() -> None:
        c._cache_x = None  # as in a Newton step: a new state's tangent
        model.problem.jacobian(A)

    t_jac_c = median_ms(jacobian, repeat=5)
    jac_mallocs = A.getInfo()["mallocs"] - mallocs
    saved = c.k_V_kPa
    c.k_V_kPa = 0.0  # the finite-element Jacobian alone (the contact's pattern is dropped)
    t_jac = median_ms(lambda: model.problem.jacobian(A), repeat=5)
    nnz_form = int(A.getInfo()["nz_used"])
    c.k_V_kPa = saved
    n_points = sum(len(p.nodes) for p in c.passes)
    print(f"mid-size wedge: {len(model.domain.cells)} cells; {n_points} contact points "
          f"({[len(p.facets) for p in c.passes]} master facets per pass), {engaged} engaged")  # fmt: skip
    print(f"contact forces (search, gaps)  {t_f:7.1f} ms")
    print(f"contact tangent                {t_k:7.1f} ms")
    print(f"residual assembly (FEM)        {t_res:7.1f} ms")
    print(f"Jacobian assembly (FEM)        {t_jac:7.1f} ms")
    print(f"Jacobian with contact and tie  {t_jac_c:7.1f} ms  ({jac_mallocs:.0f} mallocs)")
    print(f"contact / FEM, one Newton step {(t_f + t_k) / (t_res + t_jac):7.2f}")
    print(f"stage 4: {stage4_mallocs:.0f} mallocs, {growths} growths of the coupling pattern")
    print(f"matrix nonzeros: {nnz_form} (form), {nnz_contact} (form, contact and tie)")

    return 0


if __name__ == "__main__":
    sys.exit(main())

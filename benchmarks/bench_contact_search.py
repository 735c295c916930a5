"""Cost of one contact search against one residual assembly (woundsweep.contact).

Usage::

    python benchmarks/bench_contact_search.py     # about a minute

Solves stages 1-4 of the solver benchmark's mid-size paper wedge (soft skin, 90 degrees), then
times, at the converged stage-4 state, a full pair search of both passes (forced: the cache is
dropped before each), one contact evaluation of a frozen pairing (gaps, fades, forces), and
one assembly of the finite-element residual. Prints the contact points, the candidates found
and the ratio search / residual: the contact stages search once per load increment and once
per refresh, so this ratio and the number of searches set the detection share of a stage
(target < 20 %, reported per stage by bench_solver.py). Compare figures within one run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from woundsweep.mesh.build import build_mesh  # noqa: E402
from woundsweep.mesh.spec import GeometrySpec  # noqa: E402

__all__ = ["main"]


def _median_ms(fn, repeat: int = 15) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def main() -> int:
    from woundsweep.model.materials import JobMaterials
    from woundsweep.model.stages import WoundModel

    # Same geometry as bench_solver.py's "mid-size" job.
    T = 2.0
    mesh = build_mesh(GeometrySpec.wedge(1.0, 1.0, 2 * T, 0.3 * 2 * T, 0.5 * T, 0.5))
    model = WoundModel(mesh)
    model.set_materials(JobMaterials.table2("soft", 90.0))
    for k in range(1, 5):
        out = model.run_stage(k)
        if out.solve.status != "converged":
            print(f"stage {k} did not converge ({out.solve.status}): no state to time")
            return 1
    c = model.contact
    assert c is not None
    u = model.u.copy()

    def search() -> None:
        c._found = None  # force a new search at the same state
        c._search_x = None
        c._search(u)

    def evaluate() -> None:
        c._cache = None  # pairing kept, gaps and forces recomputed
        c.force_vector(u)

    c.freeze(u)
    assert c._found is not None
    n_points = sum(len(p.carrier) for p in c.points)
    n_found = len(c._found.carrier)
    t_search = _median_ms(search)
    c.freeze(u)
    t_eval = _median_ms(evaluate)
    t_res = _median_ms(lambda: model.problem.residual(model.newton.rvec))
    c.unfreeze()
    print(f"mid-size wedge: {len(model.domain.cells)} cells; {n_points} contact points "
          f"({[len(s.facets) for s in c.surfaces]} facets per flank), {n_found} candidates")  # fmt: skip
    print(f"pair search (both passes)      {t_search:7.1f} ms")
    print(f"contact forces, frozen pairing {t_eval:7.1f} ms")
    print(f"residual assembly (FEM)        {t_res:7.1f} ms")
    print(f"search / residual              {t_search / t_res:7.1f}")

    return 0


if __name__ == "__main__":
    sys.exit(main())

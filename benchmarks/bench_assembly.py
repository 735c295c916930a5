"""Assembly time of the solver's forms under DOLFINx's default C flags and `KERNEL_CFLAGS`.

Usage::

    python benchmarks/bench_assembly.py     # about three minutes (two cold compiles)

Compiles the wound model's forms for the solver benchmark's mid-size paper wedge twice, each
into its own empty cache: once with the flags DOLFINx uses by default, once with
`woundsweep.physics.compat.KERNEL_CFLAGS` (what the solver uses). At the stage-1 state of the same
job it times the residual and Jacobian assemblies (median of 15 and 7) and prints the ratios
and the largest relative difference of the assembled residual and matrix entries between the
two builds. Then, on the same wedge with P2 elements, it compiles the tangent of the
dermis and the subcutis twice, each into an empty cache with `KERNEL_CFLAGS`: with
P = dW/dF (UFL's derivative of the strain energies) and with the solver's closed form
P = F S (`woundsweep.physics.materials.second_piola`), and prints the generated C's size, the
assembly times and the largest relative difference of the two tangents and residuals.
Compare figures within one run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import dataclasses  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from timing import median_ms  # noqa: E402

from woundsweep.config.geometry import GeometrySpec  # noqa: E402
from woundsweep.config.solver import SolverSettings  # noqa: E402
from woundsweep.mesh.build import build_mesh  # noqa: E402

__all__ = ["main"]


def _measure(mesh, flags: list[str] | None, cache: str) -> dict[str, object]:  # type: ignore[no-untyped-def]
    from woundsweep.physics import compat
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    jit = compat.jit_options(cache_dir=cache)
    if flags is None:
        jit.pop("cffi_extra_compile_args", None)  # DOLFINx's own default
    else:
        jit["cffi_extra_compile_args"] = flags
    t0 = time.perf_counter()
    model = WoundModel(mesh, SolverSettings(element_degree=1), jit=jit)
    compile_s = time.perf_counter() - t0
    model.set_materials(JobMaterials.table2("normal", 45.0))
    run_stage(model, 1)
    p = model.problem
    b = model.newton.rvec
    t_res = median_ms(lambda: p.residual(b), 15)
    t_jac = median_ms(lambda: p.jacobian(p.A), 7)
    p.residual(b)
    p.jacobian(p.A)
    ai, aj, av = p.A.getValuesCSR()
    return {
        "compile_s": compile_s,
        "residual_ms": t_res,
        "jacobian_ms": t_jac,
        "r": b.getArray(readonly=True).copy(),
        "a": (ai.copy(), aj.copy(), av.copy()),
    }


def _stress_forms(mesh) -> None:  # type: ignore[no-untyped-def]
    """P = dW/dF against P = F S (closed form) on P2: kernel size, assembly, difference."""
    import dataclasses
    import glob

    import dolfinx.fem
    import ufl

    from woundsweep.core.schema import DERMIS, SUBCUTIS
    from woundsweep.physics import compat
    from woundsweep.physics.domain import WoundDomain
    from woundsweep.physics.materials import JobMaterials, first_piola

    d = WoundDomain(mesh, None, 2)
    u = dolfinx.fem.Function(d.V)
    x = d.X
    u.x.array[:] = (0.1 * x * np.array([1.0, 0.5, -0.3]) + 0.02 * np.sin(x[:, [1, 2, 0]])).ravel()
    mats = JobMaterials.table2("stiff", 30.0)
    dermis = dataclasses.replace(mats.dermis, a1=ufl.as_vector([float(c) for c in mats.dermis.a1]))
    v, du = ufl.TestFunction(d.V), ufl.TrialFunction(d.V)
    md = {"quadrature_degree": 2}
    dx = ufl.Measure("dx", domain=d.mesh, subdomain_data=d.cell_mt, metadata=md)
    layers = ((DERMIS, dermis), (SUBCUTIS, mats.subcutis))
    F = ufl.variable(ufl.Identity(3) + ufl.grad(u))
    variants = {
        "P = dW/dF": [ufl.diff(W.strain_energy(F), F) for _, W in layers],
        "P = F S (solver)": [first_piola(W, F) for _, W in layers],
    }
    out = {}
    print(
        f"P2 tangent of the stress forms ({len(mesh.cells)} cells, {d.n_dofs} dofs, stiff 30 deg)"
    )
    print(f"  {'':18s} {'C kB':>8s} {'compile s':>10s} {'residual ms':>12s} {'Jacobian ms':>12s}")
    for label, stresses in variants.items():
        R = sum(ufl.inner(P, ufl.grad(v)) * dx(t) for P, (t, _) in zip(stresses, layers))
        with tempfile.TemporaryDirectory() as cache:
            jit = compat.jit_options(cache_dir=cache)
            t0 = time.perf_counter()
            R_form = compat.compile_form(R, jit)
            a_form = compat.compile_form(ufl.derivative(R, u, du), jit)
            compile_s = time.perf_counter() - t0
            kb = sum(Path(f).stat().st_size for f in glob.glob(f"{cache}/**/*.c", recursive=True))
        b, A = compat.create_vector(R_form), compat.create_matrix(a_form)
        t_res = median_ms(lambda b=b, L=R_form: compat.assemble_vector(b, L), 15)
        t_jac = median_ms(lambda A=A, a=a_form: compat.assemble_matrix(A, a), 7)
        out[label] = (b.getArray(readonly=True).copy(), A)
        print(f"  {label:18s} {kb / 1e3:8.0f} {compile_s:10.1f} {t_res:12.2f} {t_jac:12.2f}")
    (r0, A0), (r1, A1) = out.values()
    D = A0.copy()
    D.axpy(-1.0, A1)
    dr = float(np.max(np.abs(r1 - r0)) / np.max(np.abs(r0)))
    print(f"  largest relative difference: residual {dr:.1e}, Jacobian (Frobenius) "
          f"{D.norm() / A0.norm():.1e}")  # fmt: skip


def main() -> int:
    import dolfinx.jit

    from woundsweep.physics import compat

    logging.getLogger().setLevel(logging.WARNING)  # no compiler command lines
    T = 2.0  # bench_solver.py's "mid-size" job
    mesh = build_mesh(
        GeometrySpec.wedge(1.0, 1.0, 2 * T, 0.3 * 2 * T, 0.5 * T, 0.5, element_degree=1)
    )
    defaults = compat.jit_defaults().get("cffi_extra_compile_args")
    default_flags = list(defaults[0]) if defaults else None
    out = {}
    for label, flags in (("DOLFINx default", None), ("KERNEL_CFLAGS", list(compat.KERNEL_CFLAGS))):
        with tempfile.TemporaryDirectory() as cache:
            out[label] = _measure(mesh, flags, cache)
    base, fast = out["DOLFINx default"], out["KERNEL_CFLAGS"]
    print(f"mid-size paper wedge, DOLFINx {dolfinx.__version__}, stage-1 state, normal skin 45 deg")
    print(f"  default flags {default_flags}; KERNEL_CFLAGS {list(compat.KERNEL_CFLAGS)}")
    print(f"  {'':18s} {'compile s':>10s} {'residual ms':>12s} {'Jacobian ms':>12s}")
    for label, m in out.items():
        print(
            f"  {label:18s} {m['compile_s']:10.1f} {m['residual_ms']:12.2f} {m['jacobian_ms']:12.2f}"
        )
    print(
        f"  speed-up: residual {base['residual_ms'] / fast['residual_ms']:.2f}x, "
        f"Jacobian {base['jacobian_ms'] / fast['jacobian_ms']:.2f}x"
    )
    r0, r1 = base["r"], fast["r"]
    dr = float(np.max(np.abs(r1 - r0)) / max(np.max(np.abs(r0)), 1e-300))
    a0, a1 = base["a"], fast["a"]
    same_pattern = np.array_equal(a0[0], a1[0]) and np.array_equal(a0[1], a1[1])
    da = float(np.max(np.abs(a1[2] - a0[2])) / np.max(np.abs(a0[2]))) if same_pattern else np.nan
    print(f"  largest relative difference: residual {dr:.1e}, Jacobian entries {da:.1e}\n")
    spec = GeometrySpec.wedge(1.0, 1.0, 2 * T, 0.3 * 2 * T, 0.5 * T, 0.5)
    _stress_forms(build_mesh(dataclasses.replace(spec, element_degree=2)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

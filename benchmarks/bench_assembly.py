"""Assembly time of the solver's forms under DOLFINx's default C flags and `KERNEL_CFLAGS`.

Usage::

    python benchmarks/bench_assembly.py     # about three minutes (two cold compiles)

Compiles the wound model's forms for the solver benchmark's mid-size paper wedge twice, each
into its own empty cache: once with the flags DOLFINx uses by default, once with
`woundsweep.physics.compat.KERNEL_CFLAGS` (what the solver uses). At the stage-1 state of the same
job it times the residual and Jacobian assemblies (median of 15 and 7) and prints the ratios
and the largest relative difference of the assembled residual and matrix entries between the
two builds. Compare figures within one run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

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
from woundsweep.mesh.build import build_mesh  # noqa: E402

__all__ = ["main"]


def _measure(mesh, flags: list[str] | None, cache: str) -> dict[str, object]:  # type: ignore[no-untyped-def]
    from woundsweep.physics import compat
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.stages import WoundModel

    jit = compat.jit_options(cache_dir=cache)
    if flags is None:
        jit.pop("cffi_extra_compile_args", None)  # DOLFINx's own default
    else:
        jit["cffi_extra_compile_args"] = flags
    t0 = time.perf_counter()
    model = WoundModel(mesh, jit=jit)
    compile_s = time.perf_counter() - t0
    model.set_materials(JobMaterials.table2("normal", 45.0))
    model.run_stage(1)
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


def main() -> int:
    import dolfinx.jit

    from woundsweep.physics import compat

    logging.getLogger().setLevel(logging.WARNING)  # no compiler command lines
    T = 2.0  # bench_solver.py's "mid-size" job
    mesh = build_mesh(GeometrySpec.wedge(1.0, 1.0, 2 * T, 0.3 * 2 * T, 0.5 * T, 0.5))
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
    print(f"  largest relative difference: residual {dr:.1e}, Jacobian entries {da:.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

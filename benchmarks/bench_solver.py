"""Solver benchmark: stages 1-6 on paper geometries (smallest, mid-size, largest mesh).

Usage::

    python benchmarks/bench_solver.py            # warm JIT cache + one cold-cache compile
    python benchmarks/bench_solver.py --no-cold  # skip the cold-cache JIT measurement
    python benchmarks/bench_solver.py --degree 1  # P1 (default: P2, the paper sweep's)

Prints, per geometry: cells, dofs, and per stage the Newton steps, the numeric
factorisations (one per Newton step: every step factorises its fresh tangent), load
increments, and the stage's time split into tangent assembly, factorisation, linear solves,
residual evaluations, the rest (relaxation checks, stage set-up, stress statistics) and, for
the contact stages 4-6, the contact terms (gaps, forces, tangent and pair search; part of the
assembly and residual columns), with the maximal penetration relative to the element size. A fourth mesh is the large wedge
at mesh size factor 0.92, beyond the paper grid's factors. The cold-cache JIT time compiles
the solver's three forms into an empty temporary cache; then every job is checked to compile
nothing (a spy on FFCx's compile step). Run it on an otherwise idle machine and compare
figures within one run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy/PETSc load BLAS
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import logging  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from woundsweep.config.geometry import GeometrySpec  # noqa: E402
from woundsweep.config.solver import SolverSettings  # noqa: E402
from woundsweep.mesh.build import build_mesh  # noqa: E402

__all__ = ["main"]


def geometries() -> list[tuple[str, GeometrySpec]]:
    """(name, spec): paper geometries across the cell-count range (the large one is near the
    grid's largest, per benchmarks/bench_geometry.py), plus one finer mesh."""

    def cyl(t_d: float, f_s: float, f_p: float, f_w: float, a: float, m: float) -> GeometrySpec:
        T = t_d * (1 + f_s)
        return GeometrySpec.cylindrical(t_d, f_s * t_d, f_p * T, f_w * f_p * T, a, m)

    def wedge(t_d: float, f_s: float, f_p: float, f_w: float, d: float, m: float) -> GeometrySpec:
        T = t_d * (1 + f_s)
        return GeometrySpec.wedge(t_d, f_s * t_d, f_p * T, f_w * f_p * T, d * T, m)

    return [
        ("small: cyl f_s=0.5 f_p=1 f_w=0.5 m=0.3", cyl(1.0, 0.5, 1, 0.5, 0.0, 0.3)),
        ("mid-size: wedge f_s=1 f_p=2 f_w=0.3 m=0.5", wedge(1.0, 1.0, 2, 0.3, 0.5, 0.5)),
        ("large: wedge f_s=2 f_p=3 f_w=0.3 m=0.7", wedge(1.0, 2.0, 3, 0.3, 0.7, 0.7)),
        ("finer: the large wedge at m=0.92 (off-grid)", wedge(1.0, 2.0, 3, 0.3, 0.7, 0.92)),
    ]


def blas() -> str:
    try:
        out = subprocess.run(
            ["update-alternatives", "--query", "libblas.so.3-x86_64-linux-gnu"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    for line in out.splitlines():
        if line.startswith("Value:"):
            return line.split(":", 1)[1].strip()
    return "unknown"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-cold", action="store_true", help="skip the cold-cache JIT run")
    parser.add_argument("--skin", default="soft", help="skin type [soft: the largest TSF]")
    parser.add_argument("--orientation", type=float, default=90.0)
    parser.add_argument("--last-stage", type=int, default=6, choices=range(1, 7))
    parser.add_argument("--degree", type=int, default=2, choices=(1, 2), help="element [P2]")
    args = parser.parse_args(argv)
    logging.getLogger().setLevel(logging.WARNING)

    import ffcx.codegeneration.jit as ffcx_jit

    from woundsweep.physics import compat
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    compiled: list[str] = []
    real = ffcx_jit._compile_objects

    def spy(decl, ufl_objects, names, module_name, *a, **k):  # type: ignore[no-untyped-def]
        compiled.append(module_name)
        return real(decl, ufl_objects, names, module_name, *a, **k)

    ffcx_jit._compile_objects = spy
    print(f"DOLFINx {compat.DOLFINX_VERSION}; BLAS {blas()}; "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}")  # fmt: skip
    last = args.last_stage
    print(
        f"job: P{args.degree}, skin {args.skin}, orientation {args.orientation:g} deg, stages 1-{last}\n"
    )

    solver = SolverSettings(element_degree=args.degree)
    meshes = []
    for name, spec in geometries():
        t0 = time.perf_counter()
        spec = dataclasses.replace(spec, element_degree=args.degree)
        meshes.append((name, build_mesh(spec), time.perf_counter() - t0))

    if not args.no_cold:
        with tempfile.TemporaryDirectory() as cache:
            t0 = time.perf_counter()
            model = WoundModel(meshes[0][1], solver, jit=compat.jit_options(cache))
            print(
                f"JIT, cold cache: {model.jit_time_s:.1f} s for the residual, Jacobian and "
                f"von Mises forms ({len(compiled)} compiles; model {time.perf_counter() - t0:.1f} s)"
            )
    compiled.clear()
    WoundModel(meshes[0][1], solver)  # warm the default cache if it is cold (not timed)
    warm_compiles = len(compiled)
    compiled.clear()

    head = (
        f"{'stage':>5} {'status':<12}{'newton':>7}{'fact':>5}{'incr':>5}{'time s':>8}"
        f"{'asm s':>7}{'fact s':>7}{'solve s':>8}{'resid s':>8}{'rest s':>7}{'contact s':>10}"
        f"{'pen/h':>9}"
    )
    materials = JobMaterials.table2(args.skin, args.orientation)
    for name, mesh, t_mesh in meshes:
        t0 = time.perf_counter()
        model = WoundModel(mesh, solver)
        t_model = time.perf_counter() - t0
        dofs = model.domain.n_dofs
        print(f"== {name}: {len(mesh.cells)} cells, {dofs} dofs "
              f"(mesh {t_mesh:.2f} s, model+forms {t_model:.2f} s)")  # fmt: skip
        print(head)
        model.set_materials(materials)
        total = 0.0
        for k in range(1, last + 1):
            out = run_stage(model, k)
            s = out.solve
            total += out.time_s
            d = out.diagnostics
            contact = ""
            if "contact_detect_time_s" in d:
                pen = d["max_penetration_rel"]
                contact = f"{d['contact_assembly_time_s']:>10.2f}{pen:>9.1e}"
            split = (s.assembly_time_s, s.factor_time_s, s.solve_time_s, s.residual_time_s)
            rest = out.time_s - sum(split)
            print(
                f"{k:>5} {s.status:<12}{s.iterations:>7}{s.iterations:>5}{s.increments:>5}"
                f"{out.time_s:>8.2f}{split[0]:>7.2f}{split[1]:>7.2f}{split[2]:>8.2f}"
                f"{split[3]:>8.2f}{rest:>7.2f}{contact}"
            )
            if s.status != "converged":
                break
        print(f"stages 1-{last}: {total:.2f} s\n")
    print(f"forms compiled while solving the jobs above: {len(compiled)} "
          f"(warm-up before them: {warm_compiles})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Probe the petsc4py calls of woundsweep's Newton solver (PETSc 3.18 on the host, 3.25 in sid).

Run: /work/main/.venv/bin/python scripts/probes/probe_petsc.py
     scripts/dolfinx-latest.sh --run python3 scripts/probes/probe_petsc.py

Needs no DOLFINx: a 1-D Laplacian (tridiagonal AIJ) stands in for the tangent. Checks the MUMPS
setup (preonly + LU, setFactorSetUpSolverType, ICNTL(14)), row elimination with a kept
nonzero pattern, refactorisation after new values, and how a SINGULAR matrix is reported
(exception vs negative converged reason), which decides the `linear-solver-failed` status.
"""

from __future__ import annotations

import sys

import numpy as np
from petsc4py import PETSc

__all__ = ["main"]


def laplacian(n: int) -> PETSc.Mat:
    A = PETSc.Mat().createAIJ([n, n], nnz=3, comm=PETSc.COMM_SELF)
    for i in range(n):
        A.setValue(i, i, 2.0)
        if i > 0:
            A.setValue(i, i - 1, -1.0)
        if i < n - 1:
            A.setValue(i, i + 1, -1.0)
    A.assemble()
    return A


def make_ksp(A: PETSc.Mat, icntl: bool = True) -> PETSc.KSP:
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    ksp.setErrorIfNotConverged(False)
    if icntl:
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(14, 100)
    return ksp


def line(label: str, fn) -> None:  # type: ignore[no-untyped-def]
    try:
        print(f"OK   {label}: {fn()}")
    except Exception as err:  # noqa: BLE001 - a probe records every kind of failure
        print(f"FAIL {label}: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}")


def main() -> int:
    print(
        f"PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}  petsc4py {__import__('petsc4py').__version__}"
    )
    n = 50
    A = laplacian(n)
    line(
        "Mat.setOption(KEEP_NONZERO_PATTERN, True)",
        lambda: A.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True) or "ok",
    )
    x, b = A.createVecs()
    line("A.createVecs() -> (right, left)", lambda: f"{x.getSize()}, {b.getSize()}")
    b.set(1.0)
    ksp = make_ksp(A)
    line("pc.getFactorSolverType()", lambda: ksp.getPC().getFactorSolverType())
    # PETSc 3.18 stores ICNTL set before the first factorisation and only reports it after it.
    line(
        "F.getMumpsIcntl(14) before the first factorisation",
        lambda: ksp.getPC().getFactorMatrix().getMumpsIcntl(14),
    )

    def solve_rows() -> str:
        rows = np.array([0, n - 1], dtype=np.int32)
        A.zeroRows(rows, diag=1.0)
        ksp.setUp()
        b.getArray()[:] = 1.0
        b.getArray()[rows] = 0.0
        ksp.solve(b, x)
        # Exact: u'' = -1 with u(0)=u(n-1)=0 on unit spacing -> u_i = i (n-1-i) / 2
        i = np.arange(n)
        err = np.abs(x.getArray(readonly=True) - i * (n - 1 - i) / 2).max()
        return f"reason {ksp.getConvergedReason()}, max error vs exact {err:.2e}, nnz kept {A.getInfo()['nz_used']:.0f}"

    line("A.zeroRows(rows, diag=1.0); ksp.setUp(); ksp.solve", solve_rows)
    line(
        "F.getMumpsIcntl(14) after the factorisation",
        lambda: ksp.getPC().getFactorMatrix().getMumpsIcntl(14),
    )

    def refactor() -> str:
        # New values in the same pattern (Newton's next Jacobian) must be refactorised.
        A.zeroEntries()
        B = laplacian(n)
        B.scale(2.0)
        A.axpy(1.0, B, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        A.zeroRows(np.array([0, n - 1], dtype=np.int32), diag=1.0)
        ksp.setUp()
        b.getArray()[:] = 1.0
        b.getArray()[[0, n - 1]] = 0.0
        ksp.solve(b, x)
        i = np.arange(n)
        err = np.abs(x.getArray(readonly=True) - i * (n - 1 - i) / 4).max()
        return f"reason {ksp.getConvergedReason()}, max error {err:.2e} (stale factors would give ~{(n * n / 8):.0f})"

    line("refactorise after new values (setOperators not repeated)", refactor)

    def singular() -> str:
        # Exactly singular: one explicit zero on the diagonal of an otherwise diagonal matrix.
        S = PETSc.Mat().createAIJ([n, n], nnz=1, comm=PETSc.COMM_SELF)
        for i in range(n):
            S.setValue(i, i, 0.0 if i == n // 2 else 1.0)
        S.assemble()
        k = make_ksp(S)
        y, c = S.createVecs()
        c.set(1.0)
        try:
            k.setUp()
            k.solve(c, y)
        except PETSc.Error as err:
            return f"raises PETSc.Error (ierr {err.ierr})"
        arr = y.getArray(readonly=True)
        info = k.getPC().getFactorMatrix().getMumpsInfog(1)
        return f"no exception; reason {k.getConvergedReason()}, INFOG(1) {info}, finite {bool(np.isfinite(arr).all())}"

    line("singular matrix with MUMPS LU", singular)
    line(
        "PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED",
        lambda: PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED,
    )
    line(
        "Vec.getArray()[:] = ... writes through",
        lambda: (b.getArray().__setitem__(slice(None), 3.0), b.sum())[1],
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

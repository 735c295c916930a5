"""Solve one small hyperelastic problem on any DOLFINx (0.5.2 host, 0.11 sid) and print
physics quantities and fingerprints of raw arrays, to see what agrees across versions.

Run: /work/main/.venv/bin/python scripts/probes/probe_numerics.py
     scripts/dolfinx-latest.sh --run python3 scripts/probes/probe_numerics.py

Problem (mm, kPa): unit cube, 6x6x6 Kuhn-split tetrahedra built from numpy, compressible
neo-Hookean (mu 10, lambda 40), x=0 clamped, x=1 pulled by 0.1 mm in x (lateral faces free),
4 load steps of full Newton with the assembled-forms pattern (lifting + set_bc). Printed:
reaction force, max / volume-weighted p99 Cauchy von Mises, displacement at a point, and
sha256 fingerprints of the per-cell stress array in DOLFINx order and in INPUT cell order.
The portable call forms used here are the ones docs/dolfinx-compat.md recommends.
"""

from __future__ import annotations

import hashlib
import inspect
import sys
from typing import Any

import numpy as np

__all__ = ["main"]


def kuhn_cube(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(points, cells) of [0,1]^3 split into n^3 cubes of 6 tetrahedra (consistent orientation)."""
    g = np.linspace(0.0, 1.0, n + 1)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    cells = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                v = [idx[i + a, j + b, k + c] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
                for p in (
                    (0, 1, 3, 7),
                    (0, 1, 5, 7),
                    (0, 2, 3, 7),
                    (0, 2, 6, 7),
                    (0, 4, 5, 7),
                    (0, 4, 6, 7),
                ):
                    cells.append([v[q] for q in p])
    return points, np.asarray(cells, dtype=np.int64)


def fingerprint(a: np.ndarray, digits: int = 8) -> str:
    """sha256 of an array rounded to `digits` significant digits (first 12 hex)."""
    s = np.array([float(f"{x:.{digits - 1}e}") for x in np.asarray(a, dtype=float).ravel()])
    return hashlib.sha256(s.tobytes()).hexdigest()[:12]


def main() -> int:
    import logging

    import dolfinx
    import dolfinx.fem.petsc as fpetsc
    import ufl
    from dolfinx import fem, geometry
    from dolfinx import mesh as dmesh
    from mpi4py import MPI
    from petsc4py import PETSc

    logging.getLogger().setLevel(logging.WARNING)
    comm = MPI.COMM_SELF

    # -- portable helpers (feature detection, as recommended in docs/dolfinx-compat.md)
    def coord_domain() -> Any:
        try:
            import basix.ufl

            return ufl.Mesh(basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,)))
        except ImportError:
            return ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))

    def create_mesh(cells: np.ndarray, points: np.ndarray) -> Any:
        key = "e" if "e" in inspect.signature(dmesh.create_mesh).parameters else "domain"
        return dmesh.create_mesh(comm, cells, x=points, **{key: coord_domain()})

    def space(msh: Any, family: str, degree: int, shape: tuple[int, ...] = ()) -> Any:
        if hasattr(fem, "functionspace"):
            return fem.functionspace(msh, (family, degree, shape) if shape else (family, degree))
        if shape:
            return fem.VectorFunctionSpace(msh, (family, degree))
        return fem.FunctionSpace(msh, (family, degree))

    def form(f: Any) -> Any:
        p = inspect.signature(fem.form).parameters
        kw = (
            ("jit_options", "form_compiler_options")
            if "jit_options" in p
            else ("jit_params", "form_compiler_params")
        )
        return fem.form(f, **{kw[0]: {"cache_dir": "/tmp/probe-numerics-cache"}, kw[1]: {}})

    def vec(u: Any) -> Any:
        x = getattr(u.x, "petsc_vec", None)
        return x if x is not None else u.vector

    def interp_points(V: Any) -> np.ndarray:
        X = V.element.interpolation_points
        return X() if callable(X) else X

    def scale_kw(fn: Any) -> str:
        return "alpha" if "alpha" in inspect.signature(fn).parameters else "scale"

    points, cells = kuhn_cube(6)
    msh = create_mesh(cells, points)
    tdim = msh.topology.dim
    ncell = msh.topology.index_map(tdim).size_local
    orig = np.asarray(msh.topology.original_cell_index, dtype=np.int64)[:ncell]
    V = space(msh, "Lagrange", 1, (3,))
    Q = space(msh, "DG", 0)
    u = fem.Function(V)
    v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
    mu = fem.Constant(msh, PETSc.ScalarType(10.0))
    lam = fem.Constant(msh, PETSc.ScalarType(40.0))
    Id = ufl.Identity(3)
    F = ufl.variable(Id + ufl.grad(u))
    J = ufl.det(F)
    psi = mu / 2 * (ufl.tr(F.T * F) - 3) - mu * ufl.ln(J) + lam / 2 * ufl.ln(J) ** 2
    dx = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": 1})
    R_ufl = ufl.derivative(psi * dx, u, v)
    R, Jf = form(R_ufl), form(ufl.derivative(R_ufl, u, du))

    left = dmesh.locate_entities_boundary(msh, tdim - 1, lambda x: np.isclose(x[0], 0.0))
    right = dmesh.locate_entities_boundary(msh, tdim - 1, lambda x: np.isclose(x[0], 1.0))
    dl = fem.locate_dofs_topological(V, tdim - 1, left)
    V0, _ = V.sub(0).collapse()
    dr = fem.locate_dofs_topological((V.sub(0), V0), tdim - 1, right)
    g = fem.Function(V0)
    bcs = [
        fem.dirichletbc(np.zeros(3, dtype=PETSc.ScalarType), dl, V),
        fem.dirichletbc(g, dr, V.sub(0)),
    ]

    A = fpetsc.create_matrix(Jf)
    uvec = vec(u)
    b = vec(u).duplicate()  # NOT vec(fem.Function(V)): on 0.9+ that Vec dies with the temporary
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    dxv = uvec.duplicate()
    its = []
    for step in range(1, 5):
        g.x.array[:] = 0.1 * step / 4
        n_it = 0
        for _ in range(30):
            n_it += 1
            A.zeroEntries()
            fpetsc.assemble_matrix(A, Jf, bcs=bcs)
            A.assemble()
            with b.localForm() as bl:
                bl.set(0.0)
            fpetsc.assemble_vector(b, R)
            fpetsc.apply_lifting(
                b, [Jf], [bcs], x0=[uvec], **{scale_kw(fpetsc.apply_lifting): -1.0}
            )
            b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            fpetsc.set_bc(b, bcs, uvec, -1.0)
            ksp.solve(b, dxv)
            uvec.axpy(-1.0, dxv)
            u.x.scatter_forward()
            if dxv.norm() < 1e-11:
                break
        its.append(n_it)

    # Reaction: x-component of the residual without BCs, summed over the pulled face.
    with b.localForm() as bl:
        bl.set(0.0)
    fpetsc.assemble_vector(b, R)
    bs = V.dofmap.index_map_bs
    dr_v = fem.locate_dofs_topological(V, tdim - 1, right)
    reaction = float(b.getArray(readonly=True)[dr_v * bs + 0].sum())

    P = ufl.diff(psi, F)
    sigma = P * F.T / J
    s_dev = sigma - ufl.tr(sigma) / 3 * Id
    vm_expr = fem.Expression(ufl.sqrt(1.5 * ufl.inner(s_dev, s_dev)), interp_points(Q))
    vm = fem.Function(Q)
    vm.interpolate(vm_expr)
    vmv = vm.x.array[:ncell].copy()
    vol_form = form(ufl.TestFunction(Q) * dx)
    vol = fpetsc.assemble_vector(vol_form).getArray(readonly=True)[:ncell]
    order = np.argsort(vmv)
    cw = np.cumsum(vol[order]) / vol.sum()
    p99 = float(vmv[order][np.searchsorted(cw, 0.99)])
    imax = int(np.argmax(vmv))
    mid = dmesh.compute_midpoints(msh, tdim, np.array([imax], dtype=np.int32))[0]

    pt = np.array([[0.55, 0.45, 0.5]])
    tree = (
        geometry.bb_tree(msh, tdim)
        if hasattr(geometry, "bb_tree")
        else geometry.BoundingBoxTree(msh, tdim)
    )
    coll = (getattr(geometry, "compute_collisions_points", None) or geometry.compute_collisions)(
        tree, pt
    )
    cc = geometry.compute_colliding_cells(msh, coll, pt)
    upt = u.eval(pt, np.array([cc.links(0)[0]], dtype=np.int32))

    vm_input = np.empty_like(vmv)
    vm_input[orig] = vmv  # per-cell stress in the INPUT cell order
    print(f"DOLFINx {dolfinx.__version__}: {ncell} cells, Newton iterations per step {its}")
    print(f"reaction_x_mN          {reaction:.10e}")
    print(f"max_von_mises_kPa      {vmv.max():.10e}  at cell midpoint {np.round(mid, 6).tolist()}")
    print(f"p99_von_mises_kPa      {p99:.10e}  (volume-weighted)")
    print(f"u(0.55,0.45,0.5)_mm    {np.array2string(upt, precision=10)}")
    print(
        f"original_cell_index    first 8 {orig[:8].tolist()}  identity {bool(np.array_equal(orig, np.arange(ncell)))}"
    )
    print(f"vm per cell, DOLFINx order  sha {fingerprint(vmv)}")
    print(f"vm per cell, INPUT order    sha {fingerprint(vm_input)}")
    print(f"u per dof, DOLFINx order    sha {fingerprint(u.x.array)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

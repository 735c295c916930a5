"""Probe which DOLFINx call forms work on this installation (0.5.2 on the host, 0.11 in sid).

Run: /work/main/.venv/bin/python scripts/probes/probe_api.py              (host, 0.5.2)
     scripts/dolfinx-latest.sh --run python3 scripts/probes/probe_api.py  (sid root, 0.11)

Every item tries the candidate call forms in order on a tiny tetrahedral mesh built from numpy
arrays and prints one line per form: OK (with a short fact) or the exception. The first OK form
of each item is what a portable code path should detect (hasattr / try), never a version string.
"""

from __future__ import annotations

import inspect
import sys
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["main"]

RESULTS: list[tuple[str, str, bool, str]] = []
STATE: dict[str, Any] = {}


def attempt(item: str, forms: list[tuple[str, Callable[[], Any]]]) -> Any:
    """Run each (label, thunk) of an item; record OK/failure; return the first OK result."""
    first = None
    found = False
    for label, thunk in forms:
        try:
            value = thunk()
        except Exception as err:  # noqa: BLE001 - a probe records every kind of failure
            msg = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            RESULTS.append((item, label, False, msg[:150]))
            continue
        pair = isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], str)
        note = value[1] if pair else (value if isinstance(value, str) else "")
        RESULTS.append((item, label, True, note))
        if not found:
            first, found = (value[0] if pair else value), True
    return first


def sig(obj: Any) -> str:
    try:
        return str(inspect.signature(obj))
    except (TypeError, ValueError):
        return "(signature unavailable)"


def unit_cube_arrays() -> tuple[np.ndarray, np.ndarray]:
    """2x2x2 block of unit cubes, 6 tets each (Kuhn split, consistently oriented): 48 cells."""
    n = 2
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    g = np.linspace(0.0, 1.0, n + 1)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    cells = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                v = [idx[i + a, j + b, k + c] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
                # v index = 4a + 2b + c; the 6 Kuhn tets share the diagonal v0-v7.
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


def main() -> int:
    import logging

    import dolfinx
    import dolfinx.fem.petsc as fpetsc
    import ufl
    from dolfinx import fem, geometry, io
    from dolfinx import mesh as dmesh
    from mpi4py import MPI
    from petsc4py import PETSc

    comm = MPI.COMM_WORLD
    logging.getLogger().setLevel(logging.WARNING)  # FFCx/setuptools compile chatter
    print(
        f"DOLFINx {dolfinx.__version__}  UFL {getattr(ufl, '__version__', '?')}  "
        f"PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}  numpy {np.__version__}  "
        f"python {sys.version.split()[0]}"
    )
    try:
        import basix

        print(f"basix {basix.__version__}")
    except ImportError:
        basix = None
    try:
        import ffcx

        print(f"ffcx {ffcx.__version__}")
    except ImportError:
        pass

    points, cells = unit_cube_arrays()

    # ---- coordinate element and create_mesh
    print(f"create_mesh signature: {sig(dmesh.create_mesh)}")

    def coord_basix() -> Any:
        import basix.ufl

        return ufl.Mesh(
            basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,))
        ), "ufl.Mesh(basix.ufl.element(...))"

    def coord_ufl() -> Any:
        return ufl.Mesh(
            ufl.VectorElement("Lagrange", ufl.tetrahedron, 1)
        ), "ufl.Mesh(ufl.VectorElement)"

    def coord_basix_plain() -> Any:
        import basix.ufl

        return basix.ufl.element(
            "Lagrange", "tetrahedron", 1, shape=(3,)
        ), "basix.ufl element (no ufl.Mesh)"

    # A fresh coordinate element per create_mesh call: on 0.5 create_mesh stores the new mesh in
    # the ufl.Mesh ("cargo"), so reusing one ufl.Mesh for two meshes makes forms on the first
    # fail with "RuntimeError: Incompatible mesh".
    factories = []
    for label, fn in (
        ("ufl.Mesh(basix.ufl.element('Lagrange','tetrahedron',1,shape=(3,)))", coord_basix),
        ("ufl.Mesh(ufl.VectorElement('Lagrange', ufl.tetrahedron, 1))", coord_ufl),
        ("basix.ufl.element(...) passed directly", coord_basix_plain),
    ):
        if attempt("coordinate element", [(label, fn)]) is not None:
            factories.append((label, fn))

    msh = None
    for dlabel, fn in factories:
        short = dlabel.split("(")[0] + "(...)"
        m = attempt(
            "create_mesh",
            [
                (
                    f"create_mesh(comm, cells, points, {short})  [0.5-0.9 order]",
                    lambda fn=fn: dmesh.create_mesh(comm, cells, points, fn()[0]),
                ),
                (
                    f"create_mesh(comm, cells, {short}, points)  [0.10+ order]",
                    lambda fn=fn: dmesh.create_mesh(comm, cells, fn()[0], points),
                ),
                (
                    "create_mesh(comm, cells=, x=, e=/domain=)  [keywords]",
                    lambda fn=fn: _create_kw(dmesh.create_mesh, comm, cells, points, fn()[0]),
                ),
            ],
        )
        if m is not None and msh is None:
            msh = m
    if msh is None:
        report()
        return 1
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    ncell = msh.topology.index_map(tdim).size_local
    print(
        f"mesh: {ncell} cells, {msh.geometry.x.shape[0]} geometry nodes, geometry.x shape {msh.geometry.x.shape}"
    )

    # ---- cell / node ordering relative to the input arrays
    attempt(
        "original cell index",
        [
            (
                "msh.topology.original_cell_index  (ndarray)",
                lambda: _oci(msh.topology.original_cell_index, ncell),
            ),
            (
                "msh.topology.original_cell_index[0]  (list per cell type)",
                lambda: _oci(msh.topology.original_cell_index[0], ncell),
            ),
        ],
    )
    attempt(
        "input global indices of nodes",
        [
            ("msh.geometry.input_global_indices", lambda: _igi(msh, points)),
        ],
    )
    attempt(
        "geometry dofmap",
        [
            ("msh.geometry.dofmap", lambda: _dofmap_kind(msh.geometry.dofmap)),
            (
                "msh.geometry.dofmaps[0]  (0.10+; plain .dofmap warns DeprecationWarning on 0.11)",
                lambda: _dofmap_kind(msh.geometry.dofmaps[0]),
            ),
            (
                "msh.geometry.dofmap.links(c)  (AdjacencyList)",
                lambda: _dofmap_kind(msh.geometry.dofmap.links(0)),
            ),
        ],
    )

    # ---- meshtags
    mt = attempt(
        "meshtags (cells)",
        [
            (
                "dolfinx.mesh.meshtags(msh, tdim, np.arange(n, dtype=np.int32), values_int32)",
                lambda: (
                    dmesh.meshtags(
                        msh,
                        tdim,
                        np.arange(ncell, dtype=np.int32),
                        np.where(
                            msh.geometry.x[_cell_nodes(msh)].mean(axis=1)[:, 2] > 0.5, 1, 2
                        ).astype(np.int32),
                    ),
                    "ok",
                ),
            ),
            (
                "dolfinx.mesh.meshtags(... int64 entities)",
                lambda: (
                    dmesh.meshtags(
                        msh, tdim, np.arange(ncell, dtype=np.int64), np.ones(ncell, dtype=np.int32)
                    ),
                    "ok",
                ),
            ),
        ],
    )
    attempt(
        "meshtags attributes",
        [
            (
                "mt.indices, mt.values, mt.find(v)",
                lambda: f"{len(mt.indices)} tagged; find(1) -> {len(mt.find(1))}",
            ),
        ],
    )
    facets = dmesh.locate_entities_boundary(msh, tdim - 1, lambda x: np.isclose(x[2], 0.0))
    attempt(
        "locate_entities_boundary",
        [
            (
                "dolfinx.mesh.locate_entities_boundary(msh, tdim-1, marker)",
                lambda: f"{len(facets)} facets on z=0 (expect 8)",
            ),
        ],
    )
    attempt(
        "exterior_facet_indices",
        [
            (
                "dolfinx.mesh.exterior_facet_indices(msh.topology)",
                lambda: f"{len(dmesh.exterior_facet_indices(msh.topology))} (expect 48)",
            ),
        ],
    )
    attempt(
        "entities_to_geometry",
        [
            (
                "dolfinx.mesh.entities_to_geometry(msh, dim, entities, orient=False)",
                lambda: str(dmesh.entities_to_geometry(msh, tdim - 1, facets, False).shape),
            ),
            (
                "dolfinx.mesh.entities_to_geometry(msh, dim, entities)",
                lambda: str(dmesh.entities_to_geometry(msh, tdim - 1, facets).shape),
            ),
            (
                "dolfinx.cpp.mesh.entities_to_geometry(msh, dim, entities, False)  [0.5: Mesh is the C++ object]",
                lambda: str(
                    dolfinx.cpp.mesh.entities_to_geometry(msh, tdim - 1, facets, False).shape
                ),
            ),
            (
                "dolfinx.cpp.mesh.entities_to_geometry(msh._cpp_object, dim, entities, False)",
                lambda: str(
                    dolfinx.cpp.mesh.entities_to_geometry(
                        msh._cpp_object, tdim - 1, facets, False
                    ).shape
                ),
            ),
        ],
    )

    # ---- function spaces
    V = attempt(
        "vector P1 space",
        [
            (
                "fem.functionspace(msh, ('Lagrange', 1, (3,)))",
                lambda: fem.functionspace(msh, ("Lagrange", 1, (3,))),
            ),
            (
                "fem.VectorFunctionSpace(msh, ('Lagrange', 1))",
                lambda: fem.VectorFunctionSpace(msh, ("Lagrange", 1)),
            ),
        ],
    )
    Q = attempt(
        "scalar DG0 space",
        [
            ("fem.functionspace(msh, ('DG', 0))", lambda: fem.functionspace(msh, ("DG", 0))),
            ("fem.FunctionSpace(msh, ('DG', 0))", lambda: fem.FunctionSpace(msh, ("DG", 0))),
        ],
    )
    attempt(
        "tensor DG0 space",
        [
            (
                "fem.functionspace(msh, ('DG', 0, (3, 3)))",
                lambda: fem.functionspace(msh, ("DG", 0, (3, 3))),
            ),
            (
                "fem.TensorFunctionSpace(msh, ('DG', 0))",
                lambda: fem.TensorFunctionSpace(msh, ("DG", 0)),
            ),
        ],
    )
    attempt(
        "sub-space collapse",
        [
            (
                "V.sub(0).collapse() -> (V0, map)",
                lambda: (
                    f"returns {type(V.sub(0).collapse()).__name__} of len {len(V.sub(0).collapse())}"
                ),
            ),
        ],
    )
    attempt(
        "dofmap",
        [
            (
                "V.dofmap.index_map.size_local, V.dofmap.index_map_bs",
                lambda: f"{V.dofmap.index_map.size_local} x bs {V.dofmap.index_map_bs}",
            ),
            ("V.dofmap.list", lambda: _dofmap_kind(V.dofmap.list)),
            ("V.dofmap.cell_dofs(c)", lambda: str(V.dofmap.cell_dofs(0))),
        ],
    )

    u = fem.Function(V, name="u")
    v = ufl.TestFunction(V)
    du = ufl.TrialFunction(V)

    # ---- Constant
    mu = attempt(
        "Constant",
        [
            (
                "fem.Constant(msh, PETSc.ScalarType(1.0))",
                lambda: fem.Constant(msh, PETSc.ScalarType(1.0)),
            ),
            (
                "fem.Constant(msh, dolfinx.default_scalar_type(1.0))",
                lambda: fem.Constant(msh, dolfinx.default_scalar_type(1.0)),
            ),
        ],
    )
    attempt("Constant update", [("c.value = 2.0 (in place)", lambda: _set_const(mu))])

    # ---- forms, quadrature metadata, subdomain measure
    dx = ufl.Measure("dx", domain=msh, subdomain_data=mt, metadata={"quadrature_degree": 1})
    eps = ufl.sym(ufl.grad(du))
    a_ufl = 2 * mu * ufl.inner(eps, ufl.sym(ufl.grad(v))) * dx(1) + 2 * mu * ufl.inner(
        eps, ufl.sym(ufl.grad(v))
    ) * dx(2)
    L_ufl = ufl.inner(fem.Constant(msh, PETSc.ScalarType((0.0, 0.0, -1.0))), v) * dx
    opts = {"cache_dir": "/tmp/probe-ffcx-cache"}
    a = attempt(
        "fem.form options",
        [
            (
                "fem.form(a, form_compiler_options={...}, jit_options={...})",
                lambda: fem.form(
                    a_ufl,
                    form_compiler_options={"scalar_type": PETSc.ScalarType}
                    if _has_scalar_type_opt()
                    else {},
                    jit_options=opts,
                ),
            ),
            (
                "fem.form(a, form_compiler_params={...}, jit_params={...})",
                lambda: fem.form(a_ufl, form_compiler_params={}, jit_params=opts),
            ),
        ],
    )
    L = fem.form(L_ufl)
    print(f"fem.form signature: {sig(fem.form)}")

    # ---- boundary conditions
    fixed = dmesh.locate_entities_boundary(msh, tdim - 1, lambda x: np.isclose(x[2], 0.0))
    dofs = attempt(
        "locate_dofs_topological",
        [
            (
                "fem.locate_dofs_topological(V, tdim-1, facets)",
                lambda: fem.locate_dofs_topological(V, tdim - 1, fixed),
            ),
        ],
    )
    attempt(
        "locate_dofs_topological on a sub-space",
        [
            (
                "fem.locate_dofs_topological((V.sub(0), V0), tdim-1, facets)",
                lambda: (
                    f"{len(fem.locate_dofs_topological((V.sub(0), V.sub(0).collapse()[0]), tdim - 1, fixed)[0])} dofs"
                ),
            ),
            (
                "fem.locate_dofs_topological(V.sub(0), tdim-1, facets)",
                lambda: f"{len(fem.locate_dofs_topological(V.sub(0), tdim - 1, fixed))} dofs",
            ),
        ],
    )
    attempt(
        "locate_dofs_geometrical",
        [
            (
                "fem.locate_dofs_geometrical(V, marker)",
                lambda: (
                    f"{len(fem.locate_dofs_geometrical(V, lambda x: np.isclose(x[2], 0.0)))} (blocked) dofs"
                ),
            ),
            (
                "fem.locate_dofs_geometrical((V.sub(0), V0), marker)",
                lambda: (
                    f"{len(fem.locate_dofs_geometrical((V.sub(0), V.sub(0).collapse()[0]), lambda x: np.isclose(x[2], 0.0))[0])} dofs"
                ),
            ),
        ],
    )
    zero = np.zeros(3, dtype=PETSc.ScalarType)
    bc = attempt(
        "dirichletbc",
        [
            ("fem.dirichletbc(np.zeros(3), dofs, V)", lambda: fem.dirichletbc(zero, dofs, V)),
            (
                "fem.dirichletbc(Constant, dofs, V)",
                lambda: fem.dirichletbc(fem.Constant(msh, zero), dofs, V),
            ),
            ("fem.dirichletbc(Function, dofs)", lambda: fem.dirichletbc(fem.Function(V), dofs)),
        ],
    )
    bcs = [bc]

    # ---- assembly
    print(f"apply_lifting signature: {sig(fpetsc.apply_lifting)}")
    print(f"set_bc signature: {sig(fpetsc.set_bc)}")
    print(f"create_vector signature: {sig(fpetsc.create_vector)}")
    A = attempt(
        "create_matrix + assemble_matrix",
        [
            (
                "A = fem.petsc.create_matrix(a); fem.petsc.assemble_matrix(A, a, bcs=bcs); A.assemble()",
                lambda: _asm_mat(fpetsc, a, bcs, create_first=True),
            ),
            (
                "A = fem.petsc.assemble_matrix(a, bcs=bcs); A.assemble()",
                lambda: _asm_mat(fpetsc, a, bcs, create_first=False),
            ),
        ],
    )
    b = attempt(
        "create_vector",
        [
            ("fem.petsc.create_vector(L)", lambda: fpetsc.create_vector(L)),
            ("fem.petsc.create_vector(V)", lambda: fpetsc.create_vector(V)),
            ("fem.petsc.create_vector([L])", lambda: fpetsc.create_vector([L])),
        ],
    )
    attempt(
        "assemble_vector into existing",
        [
            (
                "with b.localForm() as bl: bl.set(0); fem.petsc.assemble_vector(b, L)",
                lambda: _asm_vec(fpetsc, b, L),
            ),
        ],
    )
    uvec = attempt(
        "PETSc Vec of a Function",
        [
            ("u.x.petsc_vec", lambda: u.x.petsc_vec),
            ("u.vector", lambda: u.vector),
        ],
    )
    attempt(
        "apply_lifting",
        [
            (
                "fem.petsc.apply_lifting(b, [a], [bcs], x0=[uvec], alpha=-1.0)",
                lambda: fpetsc.apply_lifting(b, [a], [bcs], x0=[uvec], alpha=-1.0) or "ok",
            ),
            (
                "fem.petsc.apply_lifting(b, [a], bcs=[bcs], x0=[uvec], scale=-1.0)",
                lambda: fpetsc.apply_lifting(b, [a], bcs=[bcs], x0=[uvec], scale=-1.0) or "ok",
            ),
            (
                "fem.petsc.apply_lifting(b, [a], [bcs], [uvec], -1.0)  [positional]",
                lambda: fpetsc.apply_lifting(b, [a], [bcs], [uvec], -1.0) or "ok",
            ),
        ],
    )
    attempt(
        "ghostUpdate",
        [
            (
                "b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)",
                lambda: (
                    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE) or "ok"
                ),
            ),
        ],
    )
    attempt(
        "set_bc",
        [
            (
                "fem.petsc.set_bc(b, bcs, x0=uvec, alpha=-1.0)",
                lambda: fpetsc.set_bc(b, bcs, x0=uvec, alpha=-1.0) or "ok",
            ),
            (
                "fem.petsc.set_bc(b, bcs, x0=uvec, scale=-1.0)",
                lambda: fpetsc.set_bc(b, bcs, x0=uvec, scale=-1.0) or "ok",
            ),
            (
                "fem.petsc.set_bc(b, bcs, uvec, -1.0)  [positional]",
                lambda: fpetsc.set_bc(b, bcs, uvec, -1.0) or "ok",
            ),
            (
                "bc.set(b.array_w, x0=uvec.array_r, alpha=-1.0)  [0.10+ DirichletBC.set]",
                lambda: bc.set(b.array_w, x0=uvec.array_r, alpha=-1.0) or "ok",
            ),
        ],
    )

    # ---- linear solve with MUMPS
    x = attempt(
        "KSP preonly + LU/MUMPS",
        [
            (
                "ksp.setType('preonly'); pc.setType('lu'); pc.setFactorSolverType('mumps')",
                lambda: _solve(A, b, "lu", "mumps", comm),
            ),
            (
                "pc.setType('cholesky') + mumps (LDL^T)",
                lambda: _solve(A, b, "cholesky", "mumps", comm),
            ),
            (
                "pc.setFactorSolverType('petsc') (native LU)",
                lambda: _solve(A, b, "lu", "petsc", comm),
            ),
        ],
    )
    attempt(
        "lifetime of Function.x.petsc_vec",
        [
            (
                "vec(fem.Function(V)).duplicate()  [temporary Function; run in a subprocess]",
                lambda: _temporary_vec_subprocess(),
            ),
        ],
    )
    attempt(
        "copy solution into Function",
        [
            (
                "x.copy(uvec); u.x.scatter_forward()",
                lambda: (x.copy(uvec), u.x.scatter_forward(), "ok")[-1],
            ),
            (
                "u.x.array[:] = x.array_r; u.x.scatter_forward()",
                lambda: (
                    u.x.array.__setitem__(slice(None), x.array_r),
                    u.x.scatter_forward(),
                    "ok",
                )[-1],
            ),
        ],
    )
    attempt(
        "solution sanity",
        [
            (
                "max |u_z| (clamped top, body force down)",
                lambda: f"{np.abs(u.x.array[2::3]).max():.6e}",
            )
        ],
    )

    # ---- interpolation
    w = fem.Function(V)
    attempt(
        "Function.interpolate(callable)",
        [
            (
                "w.interpolate(lambda x: np.vstack((x[0], 2*x[1], 0*x[2])))",
                lambda: (
                    w.interpolate(lambda x: np.vstack((x[0], 2 * x[1], 0 * x[2]))),
                    f"max {w.x.array.max():.3f} (expect 2)",
                )[1],
            ),
        ],
    )
    ip = attempt(
        "interpolation points",
        [
            (
                "Q.element.interpolation_points  (property)",
                lambda: _ip(Q.element.interpolation_points, False),
            ),
            (
                "Q.element.interpolation_points()  (method)",
                lambda: _ip(Q.element.interpolation_points, True),
            ),
        ],
    )
    vm = fem.Function(Q)
    expr_ufl = ufl.sqrt(ufl.inner(ufl.grad(w), ufl.grad(w)))
    expr = attempt(
        "fem.Expression",
        [
            (
                "fem.Expression(ufl_expr, Q.element.interpolation_points[()])",
                lambda: fem.Expression(expr_ufl, ip),
            ),
            (
                "fem.Expression(ufl_expr, X, comm=msh.comm)",
                lambda: fem.Expression(expr_ufl, ip, comm=msh.comm),
            ),
        ],
    )
    attempt(
        "Function.interpolate(Expression)",
        [
            (
                "vm.interpolate(expr)",
                lambda: (
                    vm.interpolate(expr),
                    f"value {vm.x.array[0]:.6f} (expect sqrt(5)=2.236068)",
                )[1],
            ),
        ],
    )

    # ---- point location
    pts = np.array([[0.3, 0.4, 0.5], [0.9, 0.1, 0.2], [2.0, 2.0, 2.0]], dtype=np.float64)
    tree = attempt(
        "bounding box tree",
        [
            ("geometry.bb_tree(msh, tdim)", lambda: geometry.bb_tree(msh, tdim)),
            ("geometry.BoundingBoxTree(msh, tdim)", lambda: geometry.BoundingBoxTree(msh, tdim)),
        ],
    )
    cand = attempt(
        "compute_collisions (points)",
        [
            (
                "geometry.compute_collisions_points(tree, pts)",
                lambda: geometry.compute_collisions_points(tree, pts),
            ),
            (
                "geometry.compute_collisions(tree, pts)",
                lambda: geometry.compute_collisions(tree, pts),
            ),
        ],
    )
    attempt(
        "compute_colliding_cells",
        [
            (
                "geometry.compute_colliding_cells(msh, cand, pts)",
                lambda: _colliding(geometry.compute_colliding_cells(msh, cand, pts)),
            ),
        ],
    )
    attempt(
        "Function.eval",
        [
            ("w.eval(pts[:2], cells[:2])", lambda: _eval(w, msh, tree, pts[:2], geometry)),
        ],
    )
    attempt(
        "compute_midpoints",
        [
            (
                "dolfinx.mesh.compute_midpoints(msh, tdim, np.arange(n, dtype=np.int32))",
                lambda: str(
                    dmesh.compute_midpoints(msh, tdim, np.arange(ncell, dtype=np.int32)).shape
                ),
            ),
        ],
    )

    # ---- scalar assembly (volumes, reaction forces)
    one = fem.Constant(msh, PETSc.ScalarType(1.0))
    attempt(
        "assemble_scalar + subdomain dx",
        [
            (
                "fem.assemble_scalar(fem.form(c*dx(1)))",
                lambda: (
                    f"{fem.assemble_scalar(fem.form(one * dx(1))):.6f} + {fem.assemble_scalar(fem.form(one * dx(2))):.6f} (expect total 1)"
                ),
            ),
        ],
    )

    # ---- XDMF
    attempt(
        "XDMFFile write",
        [
            (
                "io.XDMFFile(comm, path, 'w'); write_mesh; write_function(u, t)",
                lambda: _xdmf(io, comm, msh, u),
            ),
        ],
    )
    attempt(
        "VTXWriter",
        [
            (
                "io.VTXWriter(comm, path, [u], engine='BP4')",
                lambda: (io.VTXWriter(comm, "/tmp/probe.bp", [u], engine="BP4").close(), "ok")[1],
            ),
            (
                "io.VTXWriter(comm, path, [u])",
                lambda: (io.VTXWriter(comm, "/tmp/probe2.bp", [u]).close(), "ok")[1],
            ),
        ],
    )

    # ---- gmsh bridge (optional: woundsweep builds meshes as numpy arrays)
    attempt(
        "gmsh -> DOLFINx module",
        [
            (
                "dolfinx.io.gmsh.model_to_mesh (-> MeshData)",
                lambda: (dolfinx.io.gmsh.model_to_mesh, "exists"),
            ),
            (
                "dolfinx.io.gmshio.model_to_mesh (-> 3-tuple)",
                lambda: (__import__("dolfinx.io.gmshio", fromlist=["x"]).model_to_mesh, "exists"),
            ),
        ],
    )

    # ---- Newton helpers
    attempt(
        "Newton classes",
        [
            (
                "dolfinx.nls.petsc.NewtonSolver",
                lambda: (__import__("dolfinx.nls.petsc", fromlist=["x"]).NewtonSolver, "exists"),
            ),
            (
                "dolfinx.fem.petsc.NonlinearProblem",
                lambda: (fpetsc.NonlinearProblem, sig(fpetsc.NonlinearProblem.__init__)[:120]),
            ),
            (
                "dolfinx.fem.petsc.NewtonSolverNonlinearProblem",
                lambda: (fpetsc.NewtonSolverNonlinearProblem, "exists"),
            ),
        ],
    )
    attempt(
        "scalar type",
        [
            (
                "dolfinx.default_scalar_type",
                lambda: (dolfinx.default_scalar_type, str(dolfinx.default_scalar_type)),
            ),
            ("PETSc.ScalarType", lambda: (PETSc.ScalarType, str(PETSc.ScalarType))),
        ],
    )
    return report()


def _create_kw(
    create: Callable[..., Any], comm: Any, cells: np.ndarray, points: np.ndarray, domain: Any
) -> Any:
    params = inspect.signature(create).parameters
    key = "e" if "e" in params else "domain"
    return create(comm, cells=cells, x=points, **{key: domain})


def _cell_nodes(msh: Any) -> np.ndarray:
    dm = msh.geometry.dofmap
    return np.asarray(dm) if isinstance(dm, np.ndarray) else dm.array.reshape(-1, 4)


def _oci(arr: Any, n: int) -> tuple[Any, str]:
    arr = np.asarray(arr)
    return (
        arr,
        f"len {len(arr)} dtype {arr.dtype}; identity? {bool(np.array_equal(arr[:n], np.arange(n)))}",
    )


def _igi(msh: Any, points: np.ndarray) -> tuple[Any, str]:
    igi = np.asarray(msh.geometry.input_global_indices)
    same = np.allclose(msh.geometry.x[:, :3], points[igi])
    return (
        igi,
        f"len {len(igi)}; geometry.x == points[igi]: {same}; identity? {bool(np.array_equal(igi, np.arange(len(igi))))}",
    )


def _dofmap_kind(dm: Any) -> str:
    return f"{type(dm).__name__} shape {getattr(dm, 'shape', None)}"


def _set_const(c: Any) -> str:
    c.value = 2.0
    return f"value now {float(c.value)}"


def _has_scalar_type_opt() -> bool:
    return False


def _asm_mat(fpetsc: Any, a: Any, bcs: list[Any], create_first: bool) -> Any:
    if create_first:
        A = fpetsc.create_matrix(a)
        A.zeroEntries()
        fpetsc.assemble_matrix(A, a, bcs=bcs)
    else:
        A = fpetsc.assemble_matrix(a, bcs=bcs)
    A.assemble()
    return A, f"{A.getSize()} norm {A.norm():.6e}"


def _asm_vec(fpetsc: Any, b: Any, L: Any) -> str:
    with b.localForm() as bl:
        bl.set(0.0)
    fpetsc.assemble_vector(b, L)
    return f"sum {b.sum():.6f} (expect -1)"


def _solve(A: Any, b: Any, pc_type: str, solver: str, comm: Any) -> Any:
    from petsc4py import PETSc

    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType(pc_type)
    pc.setFactorSolverType(solver)
    ksp.setFromOptions()
    x = b.duplicate()
    ksp.solve(b, x)
    r = b.duplicate()
    A.mult(x, r)
    r.axpy(-1.0, b)
    return x, f"reason {ksp.getConvergedReason()} |Ax-b| {r.norm():.2e} |x| {x.norm():.6e}"


def _ip(attr: Any, call: bool) -> tuple[Any, str]:
    if call != callable(attr):
        raise TypeError("callable" if callable(attr) else "not callable")
    X = attr() if call else attr
    return X, f"shape {np.asarray(X).shape}"


def _colliding(cc: Any) -> str:
    return f"{[len(cc.links(i)) for i in range(cc.num_nodes)]} cells per point (last point outside)"


def _eval(w: Any, msh: Any, tree: Any, pts: np.ndarray, geometry: Any) -> str:
    f = getattr(geometry, "compute_collisions_points", None) or geometry.compute_collisions
    cc = geometry.compute_colliding_cells(msh, f(tree, pts), pts)
    cells = np.array([cc.links(i)[0] for i in range(len(pts))], dtype=np.int32)
    vals = w.eval(pts, cells)
    return f"{np.round(vals, 6).tolist()} (expect x, 2y, 0)"


_TEMP_VEC = """
import numpy as np, ufl, inspect
from mpi4py import MPI
from dolfinx import fem, mesh
try:
    import basix.ufl
    d = ufl.Mesh(basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,)))
except ImportError:
    d = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))
x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
c = np.array([[0, 1, 2, 3]], dtype=np.int64)
k = "e" if "e" in inspect.signature(mesh.create_mesh).parameters else "domain"
m = mesh.create_mesh(MPI.COMM_SELF, c, x=x, **{k: d})
V = fem.functionspace(m, ("Lagrange", 1, (3,))) if hasattr(fem, "functionspace") else fem.VectorFunctionSpace(m, ("Lagrange", 1))
def vec(u):
    return getattr(u.x, "petsc_vec", None) or u.vector
import gc
v = vec(fem.Function(V))
gc.collect()
print(v.duplicate().getSize())
"""


def _temporary_vec_subprocess() -> str:
    import subprocess

    env = dict(__import__("os").environ, PETSC_OPTIONS="-no_signal_handler")
    p = subprocess.run(
        [sys.executable, "-c", _TEMP_VEC], capture_output=True, text=True, env=env, timeout=300
    )
    if p.returncode != 0:
        raise RuntimeError(
            f"subprocess died with status {p.returncode} (the Vec died with its Function)"
        )
    return f"ok, size {p.stdout.strip()}"


def _xdmf(io: Any, comm: Any, msh: Any, u: Any) -> str:
    with io.XDMFFile(comm, "/tmp/probe.xdmf", "w") as f:
        f.write_mesh(msh)
        f.write_function(u, 0.0)
    return "ok"


def report() -> int:
    width = max(len(r[1]) for r in RESULTS)
    item = None
    for it, label, ok, note in RESULTS:
        if it != item:
            print(f"\n[{it}]")
            item = it
        print(f"  {'OK  ' if ok else 'FAIL'} {label.ljust(width)}  {note}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Exception:
        traceback.print_exc()
        report()
        sys.exit(1)

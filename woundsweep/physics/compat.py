"""The only module that touches version-dependent DOLFINx API (0.5.2 here; 0.9-0.11 elsewhere).

Differences are handled by feature detection (hasattr, signatures, try/except), never by
version strings. Everything else in woundsweep calls these helpers. Serial only: a job runs in
one process (the sweep is parallel over jobs, not within a job).

Mesh numbering: `mesh_from_arrays` builds a DOLFINx mesh from the numpy `MeshData` arrays of
`woundsweep.mesh`; DOLFINx reorders cells and nodes, so the helpers here translate between
its numbering and the input ("original") numbering of points and cells.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from ..contact.geometry import face_keys

__all__ = [
    "DOLFINX_VERSION",
    "assemble_matrix",
    "assemble_vector",
    "cell_dofs",
    "cell_input_index",
    "compile_expression",
    "compile_form",
    "create_block_matrix",
    "create_matrix",
    "create_vector",
    "dg0_space",
    "evaluate_expression",
    "facet_meshtags",
    "jit_defaults",
    "jit_options",
    "mesh_from_arrays",
    "node_input_index",
    "num_cells",
    "petsc_vec",
    "quadrature_rule",
    "vector_space",
    "node_coordinates",
    "vertex_input_index",
]

DOLFINX_VERSION: str = str(getattr(dolfinx, "__version__", "unknown"))


# -- meshes ---------------------------------------------------------------------------------


def _coordinate_domain() -> ufl.Mesh:
    """UFL domain of an affine (P1) tetrahedral mesh in 3D."""
    try:  # basix >= 0.7 (DOLFINx >= 0.7): elements come from basix.ufl
        import basix.ufl

        if callable(getattr(basix.ufl, "element", None)):
            return ufl.Mesh(basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,)))
    except ImportError:
        pass
    # FFCx 0.5 rewrites a coordinate element without a variant to "equispaced" in place while
    # compiling, which changes the signature of every later form on the mesh (a second JIT
    # compile under a new hash); declaring the variant up front leaves nothing to rewrite.
    sub = ufl.FiniteElement("Lagrange", ufl.tetrahedron, 1, variant="equispaced")
    return ufl.Mesh(ufl.VectorElement(sub))


def _adjacency_array(adj: Any, width: int) -> np.ndarray:
    """(n, width) array of an AdjacencyList (0.5) or 2-D ndarray (0.9+) with fixed row size."""
    arr = adj.array if hasattr(adj, "array") and not isinstance(adj, np.ndarray) else adj
    return np.asarray(arr).reshape(-1, width)


def num_cells(mesh: Any) -> int:
    """Number of cells owned by this process."""
    return int(mesh.topology.index_map(mesh.topology.dim).size_local)


def _geometry_dofmap(mesh: Any) -> np.ndarray:
    g = mesh.geometry
    dm = g.dofmaps[0] if hasattr(g, "dofmaps") else g.dofmap  # 0.10+: one per cell type
    return _adjacency_array(dm, 4)[: num_cells(mesh)]


def _connectivity(mesh: Any, d0: int, d1: int, width: int) -> np.ndarray:
    mesh.topology.create_connectivity(d0, d1)
    return _adjacency_array(mesh.topology.connectivity(d0, d1).array, width)


def vertex_input_index(mesh: Any) -> np.ndarray:
    """Input point index of every mesh vertex (P1 geometry: one node per vertex)."""
    tdim = mesh.topology.dim
    c2v = _connectivity(mesh, tdim, 0, 4)[: num_cells(mesh)]
    gdofs = _geometry_dofmap(mesh)
    n_vertices = mesh.topology.index_map(0).size_local + mesh.topology.index_map(0).num_ghosts
    node_of_vertex = np.full(n_vertices, -1, dtype=np.int64)
    # For P1 the local vertex order of a cell equals its local geometry-node order.
    node_of_vertex[c2v.ravel()] = gdofs.ravel()
    return np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)[node_of_vertex]


def cell_input_index(mesh: Any) -> np.ndarray:
    """Input cell index of every (owned) mesh cell."""
    return np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[: num_cells(mesh)]


def facet_meshtags(mesh: Any, facets: np.ndarray, values: np.ndarray) -> Any:
    """MeshTags on the facets given as triangles of input point indices (k, 3)."""
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 3)
    values = np.asarray(values, dtype=np.int32).ravel()
    if len(facets) != len(values):
        raise ValueError("facets and values differ in length")
    fdim = mesh.topology.dim - 1
    mesh.topology.create_entities(fdim)
    f2v = _connectivity(mesh, fdim, 0, 3)
    inp = vertex_input_index(mesh)
    n = int(max(inp.max(initial=0), facets.max(initial=0))) + 1
    mesh_keys = face_keys(inp[f2v], n)
    order = np.argsort(mesh_keys)
    want = face_keys(facets, n)
    pos = np.searchsorted(mesh_keys, want, sorter=order)
    pos = np.minimum(pos, len(order) - 1)
    found = mesh_keys[order[pos]] == want
    if not found.all():
        raise ValueError(f"{int((~found).sum())} tagged facets are not facets of the mesh")
    entities = order[pos].astype(np.int32)
    perm = np.argsort(entities, kind="stable")
    return dolfinx.mesh.meshtags(mesh, fdim, entities[perm], values[perm])


def mesh_from_arrays(
    points: np.ndarray,
    cells: np.ndarray,
    cell_tags: np.ndarray,
    facets: np.ndarray,
    facet_tags: np.ndarray,
) -> tuple[Any, Any, Any]:
    """Build a serial P1 tetrahedral DOLFINx mesh with its cell and facet tags.

    ``points`` (n, 3) mm, ``cells`` (m, 4) and ``facets`` (k, 3) index ``points``;
    ``cell_tags`` (m,) and ``facet_tags`` (k,) are integers. Returns
    ``(mesh, cell_meshtags, facet_meshtags)`` in DOLFINx numbering.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 4)
    comm = MPI.COMM_SELF
    domain = _coordinate_domain()
    params = list(inspect.signature(dolfinx.mesh.create_mesh).parameters)
    # 0.5-0.9: create_mesh(comm, cells, x, domain|e); 0.10+: create_mesh(comm, cells, e, x)
    ekw = "domain" if "domain" in params else "e"
    mesh = dolfinx.mesh.create_mesh(comm, cells, x=points, **{ekw: domain})
    tdim = mesh.topology.dim
    orig = cell_input_index(mesh)
    ctags = np.asarray(cell_tags, dtype=np.int32)[orig]
    cell_mt = dolfinx.mesh.meshtags(mesh, tdim, np.arange(len(orig), dtype=np.int32), ctags)
    facet_mt = facet_meshtags(mesh, facets, facet_tags)
    return mesh, cell_mt, facet_mt


# -- spaces, functions, forms ----------------------------------------------------------------


def vector_space(mesh: Any, degree: int) -> Any:
    """Continuous Lagrange vector (displacement) space of the given degree."""
    if hasattr(dolfinx.fem, "functionspace"):
        return dolfinx.fem.functionspace(mesh, ("Lagrange", degree, (mesh.geometry.dim,)))
    return dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", degree))


def node_coordinates(V: Any) -> np.ndarray:
    """(nodes, 3) coordinates of the (block) dofs of a vector Lagrange space."""
    return np.asarray(V.tabulate_dof_coordinates(), dtype=float)[:, :3].copy()


def dg0_space(mesh: Any) -> Any:
    """Cellwise-constant scalar space."""
    if hasattr(dolfinx.fem, "functionspace"):
        return dolfinx.fem.functionspace(mesh, ("DG", 0))
    return dolfinx.fem.FunctionSpace(mesh, ("DG", 0))


def cell_dofs(V: Any) -> np.ndarray:
    """(cells, dofs per cell) array of (block) dof indices of V, in mesh cell order."""
    lst = V.dofmap.list
    width = V.dofmap.dof_layout.num_dofs
    return _adjacency_array(lst, width)[: num_cells(V.mesh)]


def node_input_index(V: Any) -> np.ndarray:
    """Input point index of every (block) dof of a Lagrange space V: its vertex's for the
    vertex dofs (the first four of a cell), -1 for the others (edge midpoints of P2)."""
    mesh = V.mesh
    gdofs = _geometry_dofmap(mesh)
    dofs = cell_dofs(V)[:, : gdofs.shape[1]]
    n_nodes = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    out = np.full(n_nodes, -1, dtype=np.int64)
    out[dofs.ravel()] = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)[
        gdofs.ravel()
    ]
    return out


def petsc_vec(u: Any) -> PETSc.Vec:
    """The PETSc vector that wraps a Function's dof array.

    On 0.9+ the vector dies with its Function: keep ``u`` referenced while the vector is used.
    """
    x = getattr(u, "x", None)
    vec = getattr(x, "petsc_vec", None) if x is not None else None
    return vec if vec is not None else u.vector


# C flags of the generated kernels. The Fung tangent is ~1.5 MB of straight-line C; letting
# the compiler reassociate it (no -ffinite-math-only: NaN and inf keep their meaning, and no
# -march, as one JIT cache can serve a cluster's mixed nodes) makes matrix assembly 1.6x and
# residual assembly 3x faster than DOLFINx's -O2 (benchmarks/bench_assembly.py).
KERNEL_CFLAGS = ("-O3", "-g0", "-fno-math-errno", "-funsafe-math-optimizations")


def jit_defaults() -> dict[str, Any]:
    """DOLFINx's default JIT options ({} if this version has no such table)."""
    import dolfinx.jit

    for name in ("DOLFINX_DEFAULT_JIT_OPTIONS", "DOLFINX_DEFAULT_JIT_PARAMETERS"):
        table = getattr(dolfinx.jit, name, None)
        if isinstance(table, dict):
            return table
    return {}


def jit_options(cache_dir: str | Path | None = None, timeout_s: int = 900) -> dict[str, Any]:
    """JIT options: a long lock timeout so concurrent jobs wait for one compile, not fail, and
    `KERNEL_CFLAGS` where this DOLFINx takes compiler arguments."""
    opts: dict[str, Any] = {"timeout": int(timeout_s)}
    if "cffi_extra_compile_args" in jit_defaults():
        opts["cffi_extra_compile_args"] = list(KERNEL_CFLAGS)
    if cache_dir is not None:
        opts["cache_dir"] = str(cache_dir)
    return opts


def compile_form(
    form: ufl.Form, jit: dict[str, Any] | None = None, compiler: dict[str, Any] | None = None
) -> Any:
    """``fem.form`` with JIT and form-compiler options under either keyword spelling."""
    params = inspect.signature(dolfinx.fem.form).parameters
    kwargs: dict[str, Any] = {}
    jit_kw = "jit_options" if "jit_options" in params else "jit_params"
    fc_kw = "form_compiler_options" if "form_compiler_options" in params else "form_compiler_params"
    kwargs[jit_kw] = dict(jit or {})
    kwargs[fc_kw] = dict(compiler or {})
    # FFCx updates integral metadata dicts in place; measures share one dict, so compile a copy
    # whose integrals own their metadata, or later forms would hash differently.
    isolated = ufl.Form(
        [itg.reconstruct(metadata=dict(itg.metadata())) for itg in form.integrals()]
    )
    return dolfinx.fem.form(isolated, **kwargs)


def compile_expression(expr: Any, points: np.ndarray, jit: dict[str, Any] | None = None) -> Any:
    """``fem.Expression`` of a scalar UFL expression at reference ``points`` (k, 3), with JIT
    options under either keyword spelling."""
    params = inspect.signature(dolfinx.fem.Expression.__init__).parameters
    jit_kw = "jit_options" if "jit_options" in params else "jit_params"
    return dolfinx.fem.Expression(
        expr, np.asarray(points, dtype=float), **{jit_kw: dict(jit or {})}
    )


def evaluate_expression(expr: Any, mesh: Any, cells: np.ndarray) -> np.ndarray:
    """A compiled scalar expression's values at its points in ``cells``: (len(cells), k).
    (0.9+ take the mesh as the first argument of ``eval``.)"""
    cells = np.ascontiguousarray(cells, dtype=np.int32)
    if "mesh" in inspect.signature(expr.eval).parameters:
        values = expr.eval(mesh, cells)
    else:
        values = expr.eval(cells)
    return np.asarray(values, dtype=float).reshape(len(cells), -1)


def quadrature_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Basix's default rule of ``degree`` on the reference tetrahedron: points (k, 3) and
    weights (k,) (summing to the reference volume, 1/6)."""
    import basix

    points, weights = basix.make_quadrature(basix.CellType.tetrahedron, int(degree))
    return np.asarray(points, dtype=float), np.asarray(weights, dtype=float)


def create_matrix(a: Any) -> PETSc.Mat:
    """PETSc AIJ matrix with the sparsity of the bilinear form ``a``."""
    return dolfinx.fem.petsc.create_matrix(a)


def create_block_matrix(a: Any) -> PETSc.Mat | None:
    """PETSc block AIJ (BAIJ) matrix with the sparsity of the bilinear form ``a`` over a
    vector space, or None where this DOLFINx cannot make one. DOLFINx inserts a cell's 3x3
    node blocks into BAIJ with one search per block instead of one per entry."""
    try:
        M = dolfinx.fem.petsc.create_matrix(a, "baij")  # 0.5-0.9: mat_type; 0.10+: kind
    except (TypeError, RuntimeError, ValueError, PETSc.Error):
        return None
    if "baij" not in M.getType() or M.getBlockSize() < 2:
        return None
    return M


def create_vector(L: Any) -> PETSc.Vec:
    """PETSc vector for the linear form ``L`` (0.11 takes the test space, not the form)."""
    try:
        return dolfinx.fem.petsc.create_vector(L)
    except TypeError:
        return dolfinx.fem.petsc.create_vector(L.function_spaces[0])


def assemble_matrix(A: PETSc.Mat, a: Any, *, finalize: bool = True) -> PETSc.Mat:
    """Zero ``A`` and assemble ``a`` into it without boundary conditions; finalised unless
    ``finalize`` is False (more values are added before one ``A.assemble()``)."""
    A.zeroEntries()
    dolfinx.fem.petsc.assemble_matrix(A, a)
    if finalize:
        A.assemble()
    return A


def assemble_scalar(M: Any) -> float:
    """Value of the compiled functional ``M`` (serial)."""
    return float(dolfinx.fem.assemble_scalar(M))


def assemble_vector(b: PETSc.Vec, L: Any) -> PETSc.Vec:
    """Zero ``b`` and assemble ``L`` into it (ghost contributions summed)."""
    with b.localForm() as loc:
        loc.set(0.0)
    dolfinx.fem.petsc.assemble_vector(b, L)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return b

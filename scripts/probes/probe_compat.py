"""Exercise woundsweep.physics.compat on this DOLFINx and check its invariants independently.

Run: /work/main/.venv/bin/python scripts/probes/probe_compat.py
     scripts/dolfinx-latest.sh --run python3 scripts/probes/probe_compat.py

Each helper of woundsweep.physics.compat that exists is called on a small two-layer block (Kuhn-split
cubes, top half tagged 1, bottom half 2, the six sides tagged 11-16) and its result is checked
against geometry (coordinates, centroids), not against the helper's own output. Helpers that do
not exist (yet) are reported as absent. Exit status: number of failed checks.
"""

from __future__ import annotations

import sys
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["main"]

FAILED: list[str] = []


def check(label: str, fn: Callable[[], Any]) -> Any:
    try:
        value = fn()
    except AttributeError as err:
        if "compat" in str(err):
            print(f"ABSENT {label}: {err}")
            return None
        FAILED.append(label)
        print(f"FAIL {label}: {type(err).__name__}: {err}")
        return None
    except Exception as err:  # noqa: BLE001 - a probe records every kind of failure
        FAILED.append(label)
        print(f"FAIL {label}: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}")
        traceback.print_exc(limit=3)
        return None
    pair = isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], str)
    note = value[1] if pair else (value if isinstance(value, str) else "")
    print(f"OK   {label} {note}")
    return value[0] if pair else value


def block(n: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points, cells, cell tags (1 top / 2 bottom), boundary triangles and their side tags."""
    g = np.linspace(0.0, 1.0, n + 1)
    X, Y, Z = np.meshgrid(g, g, -g[::-1], indexing="ij")  # z in [-1, 0]
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
    cells = np.asarray(cells, dtype=np.int64)
    ctags = np.where(points[cells].mean(axis=1)[:, 2] > -0.5, 1, 2).astype(np.int32)
    # Boundary triangles: faces of cells that occur once.
    faces = np.sort(
        np.concatenate(
            [cells[:, [1, 2, 3]], cells[:, [0, 2, 3]], cells[:, [0, 1, 3]], cells[:, [0, 1, 2]]]
        ),
        axis=1,
    )
    uniq, counts = np.unique(faces, axis=0, return_counts=True)
    tri = uniq[counts == 1]
    c = points[tri].mean(axis=1)
    tags = np.select(
        [
            np.isclose(c[:, 0], 0),
            np.isclose(c[:, 0], 1),
            np.isclose(c[:, 1], 0),
            np.isclose(c[:, 1], 1),
            np.isclose(c[:, 2], -1),
            np.isclose(c[:, 2], 0),
        ],
        [11, 12, 13, 14, 15, 16],
    ).astype(np.int32)
    return points, cells, ctags, tri, tags


def main() -> int:
    import logging

    import dolfinx

    from woundsweep.physics import compat

    logging.getLogger().setLevel(logging.WARNING)
    print(
        f"DOLFINx {dolfinx.__version__}; compat exports: {', '.join(getattr(compat, '__all__', []))}"
    )
    points, cells, ctags, tri, ftags = block()
    res = check(
        "mesh_from_arrays", lambda: compat.mesh_from_arrays(points, cells, ctags, tri, ftags)
    )
    if res is None:
        return len(FAILED) or 1
    msh, cell_mt, facet_mt = res
    tdim = msh.topology.dim
    n = compat.num_cells(msh)
    check("num_cells == input cells", lambda: (None, f"{n}") if n == len(cells) else 1 / 0)

    def vertex_index() -> tuple[Any, str]:
        vi = compat.vertex_input_index(msh)
        # Vertex coordinates from the mesh's own geometry of each vertex (via cells).
        msh.topology.create_connectivity(tdim, 0)
        c2v = msh.topology.connectivity(tdim, 0)
        gdm = msh.geometry.dofmaps[0] if hasattr(msh.geometry, "dofmaps") else msh.geometry.dofmap
        x = np.zeros((len(vi), 3))
        for c in range(n):
            verts = c2v.links(c)
            nodes = gdm[c] if isinstance(gdm, np.ndarray) else gdm.links(c)
            x[verts] = msh.geometry.x[nodes]
        err = np.abs(x - points[vi]).max()
        assert err < 1e-12, err
        return vi, f"max coordinate mismatch {err:.1e}"

    check("vertex_input_index (coordinates match input points)", vertex_index)

    def cell_index() -> tuple[Any, str]:
        ci = compat.cell_input_index(msh)
        mid = dolfinx.mesh.compute_midpoints(msh, tdim, np.arange(n, dtype=np.int32))
        err = np.abs(mid - points[cells[ci]].mean(axis=1)).max()
        assert err < 1e-12, err
        return (
            ci,
            f"max centroid mismatch {err:.1e}; identity {bool(np.array_equal(ci, np.arange(n)))}",
        )

    check("cell_input_index (centroids match input cells)", cell_index)

    def cell_tags() -> str:
        mid = dolfinx.mesh.compute_midpoints(msh, tdim, cell_mt.indices.astype(np.int32))
        expect = np.where(mid[:, 2] > -0.5, 1, 2)
        assert np.array_equal(cell_mt.values, expect)
        return f"{len(cell_mt.indices)} cells, {int((cell_mt.values == 1).sum())} tagged 1"

    check("cell meshtags (tag 1 above z=-0.5)", cell_tags)

    def facet_tags() -> str:
        msh.topology.create_connectivity(tdim - 1, tdim)
        mid = dolfinx.mesh.compute_midpoints(msh, tdim - 1, facet_mt.indices.astype(np.int32))
        side = {11: (0, 0.0), 12: (0, 1.0), 13: (1, 0.0), 14: (1, 1.0), 15: (2, -1.0), 16: (2, 0.0)}
        ok = all(np.isclose(mid[i, side[t][0]], side[t][1]) for i, t in enumerate(facet_mt.values))
        assert ok and len(facet_mt.indices) == len(tri)
        assert np.all(np.diff(facet_mt.indices) > 0), "indices not sorted"
        return f"{len(tri)} facets, all on their side"

    check("facet meshtags (midpoints on the tagged side)", facet_tags)
    V = check("vector_space", lambda: compat.vector_space(msh, 1))
    Q = check("dg0_space", lambda: compat.dg0_space(msh))

    def node_index() -> str:
        ni = compat.node_input_index(V)
        X = V.tabulate_dof_coordinates()[: len(ni)]
        err = np.abs(X - points[ni]).max()
        assert err < 1e-12, err
        return f"max mismatch {err:.1e}"

    if Q is not None:
        check(
            "cell_dofs of DG0 = one dof per cell",
            lambda: str(np.unique(compat.cell_dofs(Q)).size == n),
        )
    if V is not None:
        check("node_input_index (dof coordinates match input points)", node_index)
        check("cell_dofs shape", lambda: str(compat.cell_dofs(V).shape))

    def forms() -> str:
        import ufl
        from petsc4py import PETSc

        u = dolfinx.fem.Function(V)
        v = ufl.TestFunction(V)
        du = ufl.TrialFunction(V)
        dx = ufl.Measure(
            "dx", domain=msh, subdomain_data=cell_mt, metadata={"quadrature_degree": 1}
        )
        a = compat.compile_form(
            ufl.inner(ufl.grad(du), ufl.grad(v)) * dx(1), jit=compat.jit_options()
        )
        L = compat.compile_form(ufl.inner(ufl.as_vector((0.0, 0.0, 1.0)), v) * dx(2))
        A = compat.create_matrix(a)
        compat.assemble_matrix(A, a)
        b = compat.petsc_vec(u).duplicate()
        compat.assemble_vector(b, L)
        total = b.sum()
        assert abs(total - 0.5) < 1e-12, total  # volume of layer 2 times f_z = 1
        ones = A.createVecs()[0]
        ones.set(1.0)
        y = ones.duplicate()
        A.mult(ones, y)  # rigid translation: zero stiffness
        assert y.norm() < 1e-10, y.norm()
        return f"sum(L) {total:.12f} (expect 0.5); |A 1| {y.norm():.1e}; PETSc {PETSc.Sys.getVersion()}"

    if V is not None:
        check("compile_form / create_matrix / assemble_* / petsc_vec", forms)
    print(f"{len(FAILED)} failed: {FAILED}" if FAILED else "all compat checks passed")
    return len(FAILED)


if __name__ == "__main__":
    sys.exit(main())

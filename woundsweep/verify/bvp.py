"""A boundary value problem on the project's own assembly: `WoundDomain`, `WoundForms`,
`WoundProblem` and Newton with load continuation, with the displacement prescribed on the
whole boundary and a dead nodal load (the manufactured body force, or none).

The residual and tangent are the production forms (the Fung dermis on DERMIS cells, the
Mooney-Rivlin subcutis on SUBCUTIS cells, compiled once per degree); the dead nodal load goes
through the same path as the closure load of stages 3-6 (`WoundProblem.closure_load`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from ..config.solver import NewtonSettings, SolverSettings
from ..core.schema import StageStatus
from ..physics import compat
from ..physics.domain import WoundDomain
from ..physics.forms import WoundForms
from ..physics.materials import JobMaterials, Material
from ..physics.problem import WoundProblem
from ..solver.continuation import LoadState, continuation
from ..solver.dirichlet import Dirichlet
from ..solver.newton import NewtonSolver, Policy

__all__ = ["TIGHT", "BoundaryValueProblem", "VerificationError", "symbolic"]

# Newton's tolerances for the verification solves: far below the discretisation errors they
# measure (the production rtol 1e-6 of the force scale would show in P2's finest L2 errors).
TIGHT = NewtonSettings(rtol=1e-11, stol=1e-12, atol=1e-13)


class VerificationError(RuntimeError):
    """A verification solve did not converge (the case fails with this message)."""


def symbolic(mesh: Any, material: Material) -> Material:
    """A copy of ``material`` whose fields are `fem.Constant`s on ``mesh``: a form built with
    it compiles once for every value of the parameters."""
    import dolfinx.fem
    from petsc4py import PETSc

    consts = {
        f.name: dolfinx.fem.Constant(
            mesh, PETSc.ScalarType(0) + np.asarray(getattr(material, f.name), dtype=float)
        )
        for f in dataclasses.fields(material)
    }
    return dataclasses.replace(material, **consts)


class BoundaryValueProblem:
    """The model's forms on ``mesh_data`` (`MeshData`), degree ``degree``, materials
    ``materials``; u prescribed on every boundary node (`solve`)."""

    def __init__(
        self,
        mesh_data: Any,
        degree: int,
        materials: JobMaterials,
        *,
        quadrature_degree: int | None = None,
        newton: NewtonSettings = TIGHT,
    ) -> None:
        settings = SolverSettings(element_degree=degree)
        q = settings.form_quadrature_degree if quadrature_degree is None else quadrature_degree
        self.domain = d = WoundDomain(mesh_data, None, degree)
        self.forms = WoundForms(d, q)
        self.forms.set_materials(materials)
        self.problem = WoundProblem(d, self.forms, None)
        self.newton = NewtonSolver(self.problem, self.problem.A, newton)
        self.materials = materials
        self.boundary_nodes = d.element.triangle_nodes(d.input_node[np.asarray(mesh_data.facets)])
        rows = 3 * self.boundary_nodes[:, None] + np.arange(3)
        self.boundary_rows = rows.ravel().astype(np.int32)

    @property
    def u(self) -> np.ndarray:
        """The displacement dofs (flat, node-major; a writable view)."""
        return self.forms.u.x.array

    @property
    def X(self) -> np.ndarray:
        """Reference coordinates of the nodes (n, 3)."""
        return self.domain.X

    def load_vector(self, integrand: Callable[[Any, Any], Any], degree: int) -> np.ndarray:
        """The nodal load (flat dofs) of the linear form ``integrand(x, v) dx``, integrated at
        quadrature degree ``degree`` (x the spatial coordinate, v the test function)."""
        import ufl

        mesh = self.domain.mesh
        v = ufl.TestFunction(self.domain.V)
        dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": int(degree)})
        form = compat.compile_form(integrand(ufl.SpatialCoordinate(mesh), v) * dx)
        b = compat.create_vector(form)
        compat.assemble_vector(b, form)
        return b.getArray(readonly=True).copy()

    def functional(self, integrand: Callable[[Any, Any], Any], degree: int) -> float:
        """The value of ``integrand(x, u) dx`` at the current state (quadrature ``degree``)."""
        import ufl

        mesh = self.domain.mesh
        dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": int(degree)})
        form = compat.compile_form(integrand(ufl.SpatialCoordinate(mesh), self.forms.u) * dx)
        return compat.assemble_scalar(form)

    def residual(self) -> np.ndarray:
        """R(u) at the current state (flat dofs, mN; the nodal load subtracted)."""
        return self.problem.residual_array()

    def solve(
        self, boundary: np.ndarray, load: np.ndarray | None = None, first_step: float = 1.0
    ) -> int:
        """Solve R(u) = ``load`` with u = ``boundary`` ((n, 3), every node; its boundary
        nodes' values are used) on the boundary, from u = 0, both ramped linearly by load
        continuation. Returns the Newton steps; raises `VerificationError` if it fails."""
        values = np.asarray(boundary, dtype=float).reshape(-1)[self.boundary_rows]
        rows = self.boundary_rows
        self.u[:] = 0.0
        f = None if load is None else np.asarray(load, dtype=float)
        scale = float(np.linalg.norm(f)) if f is not None else 0.0

        def state(s: float) -> LoadState:
            return LoadState(Dirichlet(rows, s * values), None if f is None else s * f)

        res = continuation(
            self.newton, state, scale, first_step, Policy(self.newton.settings, symmetric=True)
        )
        if res.status != StageStatus.CONVERGED:
            raise VerificationError(f"Newton: {res.status} at load {res.load_reached:.3g}")
        return int(res.iterations)

"""The compiled forms of the wound model: residual, Jacobian, potential energy and von Mises.

All material parameters and tractions are ``fem.Constant``s, so the
forms compile once per machine and quadrature degree (FFCx bakes Python floats into the
form signature; constants it does not). Units: mm, kPa, mN.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from typing import Any, NamedTuple

import dolfinx.fem
import numpy as np
import ufl
from petsc4py import PETSc

from ..core.schema import DERMIS, SUBCUTIS
from . import compat
from .domain import LATERAL_DERMIS, LATERAL_SUBCUTIS, WoundDomain
from .materials import Fung, JobMaterials, Material, MooneyRivlin, first_piola, von_mises

__all__ = ["STRESS_RULE_DEGREE", "StressSamples", "WoundForms"]

# The stress statistics sample von Mises at the points of this rule in each P2 cell: a P2
# cell's stress varies within it, and a cell mean blurs the upper tail p99 measures
# (docs/model.md, "Stress statistics"). Degree 4: 14 points, positive weights.
STRESS_RULE_DEGREE = 4


class StressSamples(NamedTuple):
    """Von Mises (kPa) at reference points of every cell, mesh cell order.

    ``values`` (cells, k); ``weights`` (k,), summing to 1 (a point's share of its cell's
    volume); ``points`` (k, 3) on the reference tetrahedron; ``det_F`` (cells, k), det F at
    the points (None: not known, every sample counts).
    """

    values: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    det_F: np.ndarray | None = None


def _constant(mesh: Any, value: Any) -> dolfinx.fem.Constant:
    return dolfinx.fem.Constant(mesh, PETSc.ScalarType(0) + np.asarray(value, dtype=float))


def _symbolic(mesh: Any, material: Material) -> tuple[Material, dict[str, Any]]:
    """A copy of ``material`` whose fields are fem.Constants; returns it and the constants."""
    consts = {
        f.name: _constant(mesh, getattr(material, f.name)) for f in dataclasses.fields(material)
    }
    return dataclasses.replace(material, **consts), consts


def _assign(consts: Mapping[str, Any], material: Material) -> None:
    for name, c in consts.items():
        c.value = np.asarray(getattr(material, name), dtype=float)


class WoundForms:
    """The unknown ``u``, the load constants and the four compiled forms on a `WoundDomain`.

    Loads: ``T_dermis`` and ``T_subcutis`` (3x3, the first Piola-Kirchhoff stress of each
    layer's healthy-skin state, applied as P N on the lateral faces, a dead load). The
    closure load of stages 3-6 is a nodal force vector the problem adds
    (`woundsweep.physics.problem`). ``Pi_form`` is the potential whose derivative is the
    residual.
    """

    def __init__(
        self, domain: WoundDomain, quadrature_degree: int, jit: dict[str, Any] | None = None
    ) -> None:
        mesh, V = domain.mesh, domain.V
        self.u = dolfinx.fem.Function(V)
        self.u_vec = compat.petsc_vec(self.u)
        u = self.u
        v, du = ufl.TestFunction(V), ufl.TrialFunction(V)
        d = len(u)
        F = ufl.Identity(d) + ufl.grad(u)
        dermis_sym, self._dermis_c = _symbolic(mesh, Fung.normal())
        sub_sym, self._sub_c = _symbolic(mesh, MooneyRivlin.subcutis())
        self.T_dermis = _constant(mesh, np.zeros((3, 3)))
        self.T_subcutis = _constant(mesh, np.zeros((3, 3)))
        md = {"quadrature_degree": int(quadrature_degree)}
        dx = ufl.Measure("dx", domain=mesh, subdomain_data=domain.cell_mt, metadata=md)
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=domain.solver_facet_mt, metadata=md)
        N = ufl.FacetNormal(mesh)
        psi_d, psi_s = dermis_sym.strain_energy(F), sub_sym.strain_energy(F)
        P_d, P_s = first_piola(dermis_sym, F), first_piola(sub_sym, F)
        R = (
            ufl.inner(P_d, ufl.grad(v)) * dx(DERMIS)
            + ufl.inner(P_s, ufl.grad(v)) * dx(SUBCUTIS)
            - ufl.dot(ufl.dot(self.T_dermis, N), v) * ds(LATERAL_DERMIS)
            - ufl.dot(ufl.dot(self.T_subcutis, N), v) * ds(LATERAL_SUBCUTIS)
        )
        a = ufl.derivative(R, u, du)
        # The same terms with u for v: every load is dead, so this is the potential.
        Pi = (
            psi_d * dx(DERMIS)
            + psi_s * dx(SUBCUTIS)
            - ufl.dot(ufl.dot(self.T_dermis, N), u) * ds(LATERAL_DERMIS)
            - ufl.dot(ufl.dot(self.T_subcutis, N), u) * ds(LATERAL_SUBCUTIS)
        )
        Q = compat.dg0_space(mesh)
        q = ufl.TestFunction(Q)
        vm_d, vm_s = von_mises(P_d, F), von_mises(P_s, F)
        vm = vm_d * q * dx(DERMIS) + vm_s * q * dx(SUBCUTIS)
        jit_opts = compat.jit_options() if jit is None else jit
        t0 = time.perf_counter()
        self.R_form = compat.compile_form(R, jit_opts)
        self.a_form = compat.compile_form(a, jit_opts)
        self.vm_form = compat.compile_form(vm, jit_opts)
        self.Pi_form = compat.compile_form(Pi, jit_opts)
        # P1's stress is constant per cell: the cell values are its samples.
        self._vm_points: dict[int, Any] = {}
        if domain.degree > 1:
            self._sample_points, weights = compat.quadrature_rule(STRESS_RULE_DEGREE)
            self._sample_weights = weights / weights.sum()
            self._det_points = compat.compile_expression(ufl.det(F), self._sample_points, jit_opts)
            for tag, expr in ((DERMIS, vm_d), (SUBCUTIS, vm_s)):
                self._vm_points[tag] = (
                    domain.cell_mt.indices[domain.cell_mt.values == tag],
                    compat.compile_expression(expr, self._sample_points, jit_opts),
                )
        self.jit_time_s = time.perf_counter() - t0
        self._vm_vec = compat.create_vector(self.vm_form)
        self._dg0_cell = compat.cell_dofs(Q)[:, 0]
        self._volumes = domain.volumes

    def set_materials(self, materials: JobMaterials) -> None:
        """Assign a job's material constants (no recompilation)."""
        _assign(self._dermis_c, materials.dermis)
        _assign(self._sub_c, materials.subcutis)

    def set_loads(self, T_dermis: Any, T_subcutis: Any) -> None:
        """Set the lateral tractions' stresses (3x3 each, kPa)."""
        self.T_dermis.value[:] = T_dermis
        self.T_subcutis.value[:] = T_subcutis

    def loads(self) -> tuple[np.ndarray, np.ndarray]:
        """The current (T_dermis, T_subcutis), copied."""
        return self.T_dermis.value.copy(), self.T_subcutis.value.copy()

    def von_mises_cells(self) -> np.ndarray:
        """Cellwise von Mises stress (kPa) in mesh cell order (F is constant per P1 cell)."""
        compat.assemble_vector(self._vm_vec, self.vm_form)
        integ = self._vm_vec.getArray(readonly=True)[self._dg0_cell]
        return integ / self._volumes

    def von_mises_samples(self) -> StressSamples | None:
        """Von Mises at the stress rule's points of every P2 cell; None for P1, whose
        `von_mises_cells` are its samples."""
        if not self._vm_points:
            return None
        values = np.empty((len(self._volumes), len(self._sample_weights)))
        mesh = self.u.function_space.mesh
        for cells, expr in self._vm_points.values():
            values[cells] = compat.evaluate_expression(expr, mesh, cells)
        every = np.arange(len(self._volumes), dtype=np.int32)
        det_F = compat.evaluate_expression(self._det_points, mesh, every)
        return StressSamples(values, self._sample_weights, self._sample_points, det_F)

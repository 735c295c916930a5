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

__all__ = ["STRESS_RULE_DEGREE", "StressSamples", "TensorSamples", "WoundForms", "cell_means"]

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


class TensorSamples(NamedTuple):
    """The Cauchy stress (kPa) and F at reference points of every cell, mesh cell order:
    ``cauchy`` and ``F`` (cells, k, 3, 3), ``weights`` (k,) summing to 1 (the stress rule's on
    P2; one point, the centroid, on P1, where F is constant per cell)."""

    cauchy: np.ndarray
    F: np.ndarray
    weights: np.ndarray


def cell_means(samples: TensorSamples) -> dict[str, np.ndarray]:
    """Per cell the weighted means over its samples with det F > 0 and a finite stress:
    ``cauchy_stress_kPa`` and ``green_lagrange_strain`` (cells, 3, 3), ``det_F`` (cells,);
    NaN for a cell with no such sample (inverted throughout)."""
    J = np.linalg.det(samples.F)
    ok = (J > 0) & np.isfinite(samples.cauchy).all(axis=(2, 3))
    w = np.where(ok, np.asarray(samples.weights)[None, :], 0.0)
    total = w.sum(axis=1)
    w = w / np.where(total > 0, total, 1.0)[:, None]
    E = 0.5 * (np.swapaxes(samples.F, -1, -2) @ samples.F - np.eye(3))
    with np.errstate(invalid="ignore"):
        out = {
            "cauchy_stress_kPa": np.einsum(
                "ck,ckij->cij", w, np.where(ok[..., None, None], samples.cauchy, 0.0)
            ),
            "green_lagrange_strain": np.einsum(
                "ck,ckij->cij", w, np.where(ok[..., None, None], E, 0.0)
            ),
            "det_F": np.einsum("ck,ck->c", w, np.where(ok, J, 0.0)),
        }
    for a in out.values():
        a[total == 0] = np.nan
    return out


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
        # The Cauchy stress per layer and F, compiled at the sample points on first use
        # (`stress_tensor_samples`).
        self._tensor_ufl = (F, {DERMIS: P_d, SUBCUTIS: P_s})
        self._tensor_exprs: dict[str, Any] = {}
        vm = vm_d * q * dx(DERMIS) + vm_s * q * dx(SUBCUTIS)
        jit_opts = compat.jit_options() if jit is None else jit
        self._jit_opts = jit_opts
        t0 = time.perf_counter()
        self.R_form = compat.compile_form(R, jit_opts)
        self.a_form = compat.compile_form(a, jit_opts)
        self.vm_form = compat.compile_form(vm, jit_opts)
        self.Pi_form = compat.compile_form(Pi, jit_opts)
        # P1's stress is constant per cell: the cell values are its samples.
        self._vm_points: dict[int, Any] = {}
        self._vm_corners: dict[int, Any] = {}
        if domain.degree > 1:
            self._sample_points, weights = compat.quadrature_rule(STRESS_RULE_DEGREE)
            self._sample_weights = weights / weights.sum()
            self._det_points = compat.compile_expression(ufl.det(F), self._sample_points, jit_opts)
            corners = np.vstack([np.zeros(3), np.eye(3)])  # the reference cell's vertices
            for tag, expr in ((DERMIS, vm_d), (SUBCUTIS, vm_s)):
                cells = domain.cell_mt.indices[domain.cell_mt.values == tag]
                self._vm_points[tag] = (
                    cells,
                    compat.compile_expression(expr, self._sample_points, jit_opts),
                )
                self._vm_corners[tag] = (cells, compat.compile_expression(expr, corners, jit_opts))
        self.jit_time_s = time.perf_counter() - t0
        self._vm_vec = compat.create_vector(self.vm_form)
        self._cell_tags = np.zeros(len(domain.volumes), dtype=np.int32)
        self._cell_tags[domain.cell_mt.indices] = domain.cell_mt.values
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

    def von_mises_vertices(self) -> np.ndarray:
        """Von Mises (kPa) of every cell at its four vertices, (cells, 4) in mesh cell order
        (a P1 cell's constant value at each)."""
        if not self._vm_corners:
            return np.repeat(self.von_mises_cells()[:, None], 4, axis=1)
        values = np.empty((len(self._volumes), 4))
        mesh = self.u.function_space.mesh
        for cells, expr in self._vm_corners.values():
            values[cells] = compat.evaluate_expression(expr, mesh, cells)
        return values

    def stress_tensor_samples(self) -> TensorSamples:
        """The Cauchy stress sigma = J^-1 P F^T and F at the stress rule's points of every P2
        cell (at the centroid of a P1 cell), as the solver's von Mises samples are taken:
        the von Mises of each sample tensor is that sample's `von_mises_samples` value. The
        expressions compile on the first call."""
        if self._vm_points:
            points, weights = self._sample_points, self._sample_weights
        else:
            points, weights = np.full((1, 3), 0.25), np.ones(1)
        F, P = self._tensor_ufl
        if not self._tensor_exprs:
            self._tensor_exprs["F"] = compat.compile_expression(F, points, self._jit_opts)
            for tag, P_tag in P.items():
                sigma = ufl.dot(P_tag, F.T) / ufl.det(F)
                self._tensor_exprs[f"sigma_{tag}"] = compat.compile_expression(
                    sigma, points, self._jit_opts
                )
        mesh = self.u.function_space.mesh
        n, k = len(self._volumes), len(weights)
        every = np.arange(n, dtype=np.int32)
        Fs = compat.evaluate_expression(self._tensor_exprs["F"], mesh, every).reshape(n, k, 3, 3)
        cauchy = np.full((n, k, 3, 3), np.nan)
        tags = self._cell_tags
        for tag in P:
            cells = every[tags == tag]
            if len(cells):
                values = compat.evaluate_expression(self._tensor_exprs[f"sigma_{tag}"], mesh, cells)
                cauchy[cells] = values.reshape(len(cells), k, 3, 3)
        return TensorSamples(cauchy, Fs, np.asarray(weights, dtype=float))

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

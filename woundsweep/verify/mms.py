"""Method of manufactured solutions on the assembled residual.

A smooth displacement u* on the unit cube (strains up to about 0.25) is made the exact
solution by the body force f = -Div P(I + grad u*), written in UFL from the project's own
first Piola stress (`physics.materials.first_piola`, the closed form the forms use) with the
material's parameters as constants. The discrete problem is the production residual and
tangent (`WoundForms`, at the element's own quadrature degree) with u = u* on the boundary
and f as a dead nodal load (`bvp.BoundaryValueProblem`); it is solved on the Kuhn-split unit
cube at n = 1/h grid boxes per edge, and the L2 and H1-seminorm errors against u* (at a
quadrature degree well above the element's) are fitted by least squares, log e against log h
(as scikit-fem's convergence tests do). Optimal rates: L2 p + 1, H1 p for Lagrange degree p.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, NamedTuple

import numpy as np

from ..core.schema import DERMIS, SUBCUTIS
from ..physics.materials import Fung, JobMaterials, Material, MooneyRivlin, first_piola
from .bvp import BoundaryValueProblem, symbolic
from .meshes import unit_cube

__all__ = ["AMPLITUDE", "MmsSeries", "MmsSpec", "exact_displacement", "fit_rate", "run_series"]

AMPLITUDE = 0.06  # mm on the unit cube: |grad u*| reaches about 0.25
ERROR_DEGREE = 8  # quadrature degree of the errors and of the body force


def exact_displacement(x: Any, sin: Any, cos: Any) -> list[Any]:
    """u*(x) on the unit cube (mm): every component of its gradient varies, none vanishes
    identically; ``sin``/``cos`` are numpy's or UFL's."""
    a, pi = AMPLITUDE, math.pi
    return [
        a * (sin(pi * x[0]) * cos(pi * x[1] / 2) + 0.5 * sin(pi * x[2])),
        a * (sin(pi * x[1]) * cos(pi * x[2] / 2) + 0.5 * sin(pi * x[0])),
        a * (sin(pi * x[2]) * cos(pi * x[0] / 2) + 0.5 * sin(pi * x[1])),
    ]


@dataclasses.dataclass(frozen=True)
class MmsSpec:
    """One study: the material (``fung`` at ``angle_deg``, or ``mooney-rivlin``), its bulk
    modulus K (kPa; None: the paper's), the element degree and the meshes (grid boxes per
    edge)."""

    material: str
    degree: int
    levels: tuple[int, ...]
    angle_deg: float = 0.0
    K_kPa: float | None = None

    def job_materials(self) -> JobMaterials:
        dermis, sub = Fung.normal(self.angle_deg), MooneyRivlin.subcutis()
        if self.K_kPa is not None:
            if self.material == "fung":
                dermis = dataclasses.replace(dermis, K=float(self.K_kPa))
            else:
                sub = dataclasses.replace(sub, K=float(self.K_kPa))
        return JobMaterials(dermis, sub, 1.0)

    def material_law(self) -> Material:
        m = self.job_materials()
        return m.dermis if self.material == "fung" else m.subcutis

    @property
    def cell_tag(self) -> int:
        return DERMIS if self.material == "fung" else SUBCUTIS

    def bulk_to_shear(self) -> float:
        """K over the small-strain shear modulus (Fung: the smallest mu_a; Mooney-Rivlin:
        2 C10)."""
        m = self.material_law()
        mu = min(m.mu) if isinstance(m, Fung) else 2.0 * float(m.C10)  # type: ignore[attr-defined]
        return float(m.K) / float(mu)


class MmsSeries(NamedTuple):
    """A study's errors per mesh and their fitted rates."""

    spec: MmsSpec
    h: list[float]
    dofs: list[int]
    l2: list[float]
    h1: list[float]
    newton_steps: list[int]
    l2_rate: float
    h1_rate: float
    time_s: float


def fit_rate(h: list[float], e: list[float]) -> float:
    """The least-squares slope of log e against log h."""
    return float(np.polyfit(np.log(h), np.log(e), 1)[0])


def _body_force(spec: MmsSpec, prob: BoundaryValueProblem) -> np.ndarray:
    import ufl

    law = symbolic(prob.domain.mesh, spec.material_law())

    def integrand(x: Any, v: Any) -> Any:
        u = ufl.as_vector(exact_displacement(x, ufl.sin, ufl.cos))
        P = first_piola(law, ufl.Identity(3) + ufl.grad(u))
        return ufl.dot(-ufl.div(P), v)

    return prob.load_vector(integrand, ERROR_DEGREE)


def _errors(prob: BoundaryValueProblem) -> tuple[float, float]:
    import ufl

    def diff(x: Any, u: Any) -> Any:
        return u - ufl.as_vector(exact_displacement(x, ufl.sin, ufl.cos))

    l2 = prob.functional(lambda x, u: ufl.inner(diff(x, u), diff(x, u)), ERROR_DEGREE)
    h1 = prob.functional(
        lambda x, u: ufl.inner(ufl.grad(diff(x, u)), ufl.grad(diff(x, u))), ERROR_DEGREE
    )
    return math.sqrt(max(l2, 0.0)), math.sqrt(max(h1, 0.0))


def solve_level(spec: MmsSpec, n: int) -> tuple[BoundaryValueProblem, int]:
    """The manufactured problem of ``spec`` solved on the n^3 cube."""
    prob = BoundaryValueProblem(unit_cube(n, spec.cell_tag), spec.degree, spec.job_materials())
    exact = np.stack(exact_displacement(prob.X.T, np.sin, np.cos), axis=1)
    steps = prob.solve(exact, _body_force(spec, prob))
    return prob, steps


def run_series(spec: MmsSpec) -> MmsSeries:
    """Solve ``spec`` on each of its meshes and fit the rates."""
    t0 = time.perf_counter()
    h, dofs, l2, h1, steps = [], [], [], [], []
    for n in spec.levels:
        prob, its = solve_level(spec, n)
        e0, e1 = _errors(prob)
        h.append(1.0 / n)
        dofs.append(len(prob.u))
        l2.append(e0)
        h1.append(e1)
        steps.append(its)
    return MmsSeries(
        spec, h, dofs, l2, h1, steps, fit_rate(h, l2), fit_rate(h, h1), time.perf_counter() - t0
    )

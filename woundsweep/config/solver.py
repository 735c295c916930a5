"""The sweep's ``solver`` section: the element, the quadrature and Newton's settings."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

__all__ = ["DEGREES", "NewtonSettings", "SolverSettings", "element_name"]

# The displacement element: Lagrange tetrahedra of degree 1 (P1) or 2 (P2).
DEGREES = (1, 2)


@dataclasses.dataclass(frozen=True)
class NewtonSettings:
    """Newton's numerical settings (keys of the sweep's ``solver`` section)."""

    max_iterations: int = 60  # Newton steps per load increment
    max_stage_iterations: int = 1000  # Newton steps per stage (all increments): bounds the cost
    rtol: float = 1e-6  # residual, relative to the force scale
    path_rtol: float = 1e-2  # residual of an intermediate increment of a ramp (load < 1)
    atol: float = 1e-10  # residual floor, mN
    stol: float = 1e-5  # increment and Dirichlet mismatch, relative to the length scale
    load_steps: int = 1  # first load increment = 1 / load_steps of the stage's change
    max_load_cuts: int = 6  # consecutive halvings of the load increment before giving up
    max_strain_step: float = 0.5  # largest |grad du| (Frobenius, per cell) of one update
    gamma_min: float = 1.0 / 64.0  # smallest relaxation factor tried
    residual_growth: float = 4.0  # accept an update while ||R|| grows by at most this factor
    divergence_factor: float = 1e6  # ||R|| above this times the force scale: diverged


@dataclasses.dataclass(frozen=True)
class SolverSettings:
    """The element's degree (2: P2, the default; 1: P1, the paper's, a preview), the
    quadrature degree of the energy and residual, `NewtonSettings` (flat in the sweep file, beside the other
    keys) and whether Newton's linear solves use the job's symmetry."""

    # P2, not the paper's P1: P1 locks at the subcutis' bulk modulus, and its closure force and
    # stresses move with the mesh (docs/model.md, "Element").
    element_degree: int = 2
    quadrature_degree: int = 1
    newton: NewtonSettings = NewtonSettings()
    # Newton's linear solves in the symmetric subspace of a job whose mesh, materials and
    # loads share the patch's mirror (or half-turn) symmetry (`woundsweep.solver.symmetry`):
    # the same steps on a quarter (half) of the unknowns.
    symmetry: bool = True

    @property
    def form_quadrature_degree(self) -> int:
        """The degree the forms use: the larger of ``quadrature_degree`` and
        2 * (element_degree - 1), the degree that integrates the element's linear stiffness
        exactly (a P2 run with ``quadrature_degree`` 1 uses 2)."""
        return max(self.quadrature_degree, 2 * (self.element_degree - 1))

    def to_dict(self) -> dict[str, Any]:
        return {
            "element_degree": self.element_degree,
            "quadrature_degree": self.quadrature_degree,
            "symmetry": self.symmetry,
            **dataclasses.asdict(self.newton),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SolverSettings:
        newton = {f.name: d[f.name] for f in dataclasses.fields(NewtonSettings) if f.name in d}
        return cls(
            int(d.get("element_degree", cls.element_degree)),
            int(d.get("quadrature_degree", cls.quadrature_degree)),
            NewtonSettings(**newton),
            bool(d.get("symmetry", cls.symmetry)),
        )


def element_name(degree: int) -> str:
    """The element as reports name it: ``P1 (linear tetrahedra)``, ``P2 (quadratic ...)``;
    P1 is marked a preview (docs/model.md: its p99 moves with the mesh)."""
    kind = {1: "linear tetrahedra, a preview", 2: "quadratic tetrahedra"}.get(int(degree), "")
    return f"P{int(degree)} ({kind})" if kind else f"P{int(degree)}"

"""What the wound model needs from a contact formulation: the `ContactModel` protocol.

Units: lengths mm, penalty k_V kPa (1 GPa = 1e6 kPa), forces mN, energy mN mm. Displacements
are flat dof arrays (node i has dofs 3 i, 3 i + 1, 3 i + 2).
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import numpy as np

__all__ = ["GPA_TO_KPA", "ContactModel", "ContactSummary", "add_csr"]

GPA_TO_KPA = 1.0e6  # stiffness in GPa -> kPa


class ContactSummary(NamedTuple):
    """Scalars of a contact state (the StageResult contact fields plus diagnostics)."""

    n_penetrating: int  # contact points with g < 0
    max_penetration_mm: float  # max -g (0 if none)
    max_penetration_rel: float  # max -g / h_s
    contact_force_mN: float  # total normal contact force, sum of c (-g)


class ContactModel(Protocol):
    """A penalty contact term of the potential: energy, forces and tangent at a state.

    ``k_V_kPa`` is the penalty (0 switches the contact terms off). The energy is C1 in ``u``
    and its residual and tangent are exact derivatives; ``mult`` and the two multiplier
    methods serve the semi-smooth step (`woundsweep.contact.multipliers`).
    """

    k_V_kPa: float
    mult: np.ndarray | None  # multipliers of the semi-smooth step (contact.multipliers)
    detect_time_s: float  # cumulative, since `reset_timers`
    assembly_time_s: float
    searches: int

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        ...

    def add_residual(self, b: Any, u: np.ndarray) -> None:
        """Add the contact forces at ``u`` to an assembled PETSc vector."""
        ...

    def add_jacobian(self, A: Any, u: np.ndarray) -> None:
        """Add the contact tangent at ``u`` to an assembled PETSc matrix and re-finalise it."""
        ...

    def penalty_multipliers(self, u: np.ndarray) -> np.ndarray:
        """mu = c psi(u) of every contact point (0 where not engaged)."""
        ...

    def linearization(self, u0: np.ndarray, du: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(c psi(u0), c dpsi . du) of every contact point (0 where not engaged at u0)."""
        ...

    def summary(self, u: np.ndarray) -> ContactSummary:
        """Penetration and contact force at ``u``."""
        ...

    def reset_timers(self) -> None:
        """Zero the time and search counters."""
        ...


def add_csr(A: Any, K: Any) -> None:
    """Add the scipy CSR matrix ``K`` to the assembled PETSc matrix ``A`` and re-finalise it.

    Contact terms couple nodes across the wound that the finite-element pattern does not, so
    new nonzeros are allowed."""
    from petsc4py import PETSc

    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    A.setValuesCSR(
        K.indptr.astype(PETSc.IntType),
        K.indices.astype(PETSc.IntType),
        K.data.astype(PETSc.ScalarType),
        addv=PETSc.InsertMode.ADD_VALUES,
    )
    A.assemble()

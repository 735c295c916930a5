"""What the wound model needs from a contact formulation: the `ContactModel` protocol.

Units: lengths mm, penalty k_V kPa (1 GPa = 1e6 kPa), forces mN, energy mN mm. Displacements
are flat dof arrays (node i has dofs 3 i, 3 i + 1, 3 i + 2).
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import numpy as np

__all__ = ["GPA_TO_KPA", "ContactModel", "ContactSummary", "add_csr", "structure"]

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

    The coupling pattern is what lets the wound problem preallocate its matrix once per
    contact episode: after `plan_pattern`, `coupling_pattern` holds every entry the tangent
    has at states near the planned one, and a tangent that reaches past it grows the pattern
    (``pattern_version`` changes) before it is returned.
    """

    k_V_kPa: float
    mult: np.ndarray | None  # multipliers of the semi-smooth step (contact.multipliers)
    detect_time_s: float  # cumulative, since `reset_timers`
    assembly_time_s: float
    searches: int
    pattern_version: int  # changes with the coupling pattern (planned, grown or cleared)

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        ...

    def add_residual(self, b: Any, u: np.ndarray) -> None:
        """Add the contact forces at ``u`` to an assembled PETSc vector."""
        ...

    def tangent_csr(self, u: np.ndarray) -> Any:
        """Contact tangent at ``u``, a scipy CSR matrix (grows the coupling pattern if needed)."""
        ...

    def add_jacobian(self, A: Any, u: np.ndarray) -> None:
        """Add the contact tangent at ``u`` to an assembled PETSc matrix and re-finalise it."""
        ...

    def plan_pattern(self, u: np.ndarray) -> None:
        """Set the coupling pattern to the couplings of the states near ``u``."""
        ...

    def clear_pattern(self) -> None:
        """Drop the coupling pattern (tangents are no longer checked against it)."""
        ...

    def coupling_pattern(self) -> Any:
        """The coupling pattern's structure (scipy CSR of ones, n_dofs square), or None if
        none is planned."""
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


def add_csr(A: Any, K: Any, *, finalize: bool = True) -> None:
    """Add the scipy CSR matrix ``K`` to the PETSc matrix ``A``; re-finalise it unless
    ``finalize`` is False.

    An entry outside the preallocated pattern is inserted (a malloc and a new nonzero state,
    so MUMPS redoes its analysis), never refused: the contact terms couple nodes across the
    wound that the finite-element pattern does not."""
    from petsc4py import PETSc

    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    A.setValuesCSR(
        K.indptr.astype(PETSc.IntType),
        K.indices.astype(PETSc.IntType),
        K.data.astype(PETSc.ScalarType),
        addv=PETSc.InsertMode.ADD_VALUES,
    )
    if finalize:
        A.assemble()


def structure(*mats: Any) -> Any:
    """The union of the sparsity structures of scipy sparse matrices of one shape: a CSR
    matrix of ones with sorted indices (explicit zeros count as entries)."""
    import scipy.sparse

    parts = []
    for M in mats:
        S = scipy.sparse.csr_matrix(M, copy=True)
        S.data = np.ones(len(S.data), dtype=np.int32)  # positive: a sum cannot cancel an entry
        parts.append(S)
    out = parts[0]
    for S in parts[1:]:
        out = out + S
    out = scipy.sparse.csr_matrix(out)
    out.sum_duplicates()
    out.data[:] = 1
    return out

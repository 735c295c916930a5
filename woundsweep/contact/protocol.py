"""What the wound model needs from a contact formulation: the `ContactModel` protocol.

Units: lengths mm, penalty k_V kPa (1 GPa = 1e6 kPa), forces mN, energy mN mm. Displacements
are flat dof arrays (node i has dofs 3 i, 3 i + 1, 3 i + 2).
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import numpy as np

__all__ = ["GPA_TO_KPA", "ContactModel", "ContactSummary", "Linearization"]

GPA_TO_KPA = 1.0e6  # stiffness in GPa -> kPa


class ContactSummary(NamedTuple):
    """Scalars of a contact state (the StageResult contact fields plus diagnostics)."""

    n_penetrating: int  # contact points with g < 0
    max_penetration_mm: float  # max -g (0 if none)
    max_penetration_rel: float  # max -g / h_s
    contact_force_mN: float  # total normal contact force, sum of c (-g)
    # Engaged points (g <= 0) in the support's fade (0 < s < 1, past the master's rim) and
    # their share of contact_force_mN (a ratio independent of k_V; 0 if no point penetrates).
    # Defaults keep the four-field constructions valid.
    n_fade_points: int = 0
    fade_force_share: float = 0.0


class Linearization(NamedTuple):
    """The contact points' forces at a state and their rate along a step du (mN, 0 where
    not engaged at the state): the Newton model's forces at u + gamma du are
    min(0, forces + gamma rate)."""

    forces: np.ndarray  # (n_points,) c psi(u)
    rate: np.ndarray  # (n_points,) c dpsi . du


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

    @property
    def pattern_version(self) -> int:
        """Changes with the coupling pattern (planned, grown or cleared); read-only."""
        ...

    def energy(self, u: np.ndarray) -> float:
        """Penalty energy (mN mm) at ``u``."""
        ...

    def force_vector(self, u: np.ndarray) -> np.ndarray:
        """Contact forces (mN) at ``u`` as flat dofs."""
        ...

    def tangent_csr(self, u: np.ndarray) -> Any:
        """Contact tangent at ``u``, a scipy CSR matrix (grows the coupling pattern if needed)."""
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

    def linearization(self, u0: np.ndarray, du: np.ndarray) -> Linearization:
        """(c psi(u0), c dpsi . du) of every contact point (0 where not engaged at u0)."""
        ...

    def freeze_support(self, u: np.ndarray | None) -> None:
        """Hold the contact points' weights at their values at ``u`` (None: let them follow
        the state)."""
        ...

    def support_change(self, u: np.ndarray) -> float:
        """How far the held weights of the engaged points are from their values at ``u``."""
        ...

    def summary(self, u: np.ndarray) -> ContactSummary:
        """Penetration and contact force at ``u``."""
        ...

    def reset_timers(self) -> None:
        """Zero the time and search counters."""
        ...

"""The nonlinear problem Newton solves: the wound model's residual, tangent and potential.

`WoundProblem` joins the compiled forms (`WoundForms`), the flank contact (a
`woundsweep.contact.ContactModel`, or None for an unwounded patch) and the closure zone's
tangential tie (`woundsweep.contact.ZoneTie`) into the `woundsweep.solver.NonlinearProblem`
protocol. The contact and tie terms are added while the penalty is on
(``contact.k_V_kPa > 0``; the tie only once set); ``multipliers`` are the contact multipliers Newton
carries there. The potential is not used by Newton: that it exists (every load of stages 4-6
is dead) makes their tangent symmetric, and `tests/test_stages_contact.py` checks R = dPi/du.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .. import compat
from ..contact import ContactModel, ContactMultipliers, ZoneTie
from .domain import WoundDomain
from .forms import WoundForms

__all__ = ["WoundProblem"]


class WoundProblem:
    """Residual R(u), tangent dR/du and potential of the wound model at the state ``forms.u``."""

    def __init__(
        self,
        domain: WoundDomain,
        forms: WoundForms,
        contact: ContactModel | None,
        tie: ZoneTie | None = None,
    ) -> None:
        self.domain, self.forms, self.contact, self.tie = domain, forms, contact, tie
        self.A = compat.create_matrix(forms.a_form)
        # Carried by Newton in the contact stages (woundsweep.contact.multipliers).
        self.multipliers = (
            ContactMultipliers(contact, self.solution) if contact is not None else None
        )

    def _contact_on(self) -> ContactModel | None:
        c = self.contact
        return c if c is not None and c.k_V_kPa > 0.0 else None

    # -- NonlinearProblem -------------------------------------------------------------------

    def solution(self) -> np.ndarray:
        return self.forms.u.x.array

    def residual(self, b: PETSc.Vec) -> None:
        compat.assemble_vector(b, self.forms.R_form)
        c = self._contact_on()
        if c is not None:
            c.add_residual(b, self.solution())
            if self.tie is not None:
                self.tie.add_residual(b, self.solution(), c.k_V_kPa)

    def jacobian(self, A: PETSc.Mat) -> None:
        compat.assemble_matrix(A, self.forms.a_form)
        c = self._contact_on()
        if c is not None:
            c.add_jacobian(A, self.solution())
            if self.tie is not None:
                self.tie.add_jacobian(A, c.k_V_kPa)

    def energy(self) -> float | None:
        """Total potential (mN mm) at the current state, or None while a load follows the
        deformation (the stage-3 closure traction), when there is none."""
        if float(self.forms.follow.value) != 0.0:
            return None
        e = compat.assemble_scalar(self.forms.Pi_form)
        c = self._contact_on()
        if c is not None:
            e += c.energy(self.solution())
            if self.tie is not None:
                e += self.tie.energy(self.solution(), c.k_V_kPa)
        return e

    def min_det(self, u: np.ndarray) -> float:
        return self.domain.min_det(u)

    def max_strain(self, du: np.ndarray) -> float:
        return self.domain.max_strain(du)

    def length_scale(self) -> float:
        return self.domain.ell

    # -- helpers of the stages --------------------------------------------------------------

    def residual_array(self) -> np.ndarray:
        """R(u) at the current state as a flat array (reactions included)."""
        b = self.forms.u_vec.duplicate()
        self.residual(b)
        return b.getArray(readonly=True).copy()

    def internal_force(self) -> np.ndarray:
        """Nodal internal forces at the current state (external loads and contact off)."""
        saved = self.forms.loads()
        c = self.contact
        k_V = c.k_V_kPa if c is not None else 0.0
        self.forms.set_loads(0.0, 0.0, 0.0)
        if c is not None:
            c.k_V_kPa = 0.0
        r = self.residual_array()
        self.forms.set_loads(*saved)
        if c is not None:
            c.k_V_kPa = k_V
        return r

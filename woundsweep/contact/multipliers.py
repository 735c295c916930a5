"""Contact multipliers carried by Newton: the semi-smooth (primal-dual active set) contact step.

The penalty problem (`woundsweep.contact.smooth`) is solved in its mixed form: beside u, Newton
carries per contact point a multiplier mu = c psi (<= 0, the point's normal force over its
gap's gradient), with the penalty law psi - mu / c = 0 on the engaged points and mu = 0 on the
others. Eliminating d(mu) gives the penalty Newton step, except that

- the tangent's curvature term is mu d2psi (the force the last step predicted) instead of
  c psi(u) d2psi, which after an overshoot holds the overshoot's penalty force;
- a point stays engaged while its multiplier is compressive, even where the step opened its
  gap: the step's linearised contact holds it, and the point is released only when a step
  predicts tension (mu = c (psi + dpsi . du) >= 0). Without this a full step that opens the
  flanks by a few microns drops every point, and the next step, with no contact stiffness,
  drives the flanks through each other.

At a converged state mu = c psi exactly (the last step is a full step of size below the
tolerance), so the solution is the penalty solution. The methods are the optional multiplier
hooks of `woundsweep.solver.newton`; they act only while the penalty is on.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .protocol import ContactModel, Linearization

__all__ = ["ContactMultipliers"]


class ContactMultipliers:
    """The multipliers of ``contact`` over Newton's solves; ``solution()`` gives u."""

    def __init__(self, contact: ContactModel, solution: Callable[[], np.ndarray]) -> None:
        self.contact = contact
        self.solution = solution
        self._committed: np.ndarray | None = None

    def _on(self) -> bool:
        return self.contact.k_V_kPa > 0.0

    def reset(self) -> None:
        """Start of a stage: no multipliers from an earlier solve."""
        self._committed = None
        self.contact.mult = None
        self.contact.freeze_support(None)

    def begin(self) -> None:
        """Start of a solve: the last converged solve's multipliers (the contact forces,
        which change little over one increment), else the penalty's own at the state."""
        c = self.contact
        c.mult = None
        if not self._on():
            return
        c.freeze_support(self.solution())
        c.mult = (
            self._committed.copy()
            if self._committed is not None
            else c.penalty_multipliers(self.solution())
        )

    def predict(self, du: np.ndarray) -> Linearization | None:
        """At the current state: the multipliers after u += gamma du are
        min(0, forces + gamma rate)."""
        return self.contact.linearization(self.solution(), du) if self._on() else None

    def accept(self, pred: Linearization | None, gamma: float) -> None:
        if pred is not None:
            self.contact.mult = np.minimum(pred.forces + gamma * pred.rate, 0.0)

    def snapshot(self) -> np.ndarray | None:
        m = self.contact.mult
        return None if m is None else m.copy()

    def restore(self, saved: np.ndarray | None) -> None:
        if saved is not None:
            self.contact.mult = saved

    def commit(self) -> None:
        """A solve converged: its multipliers start the next one."""
        if self.contact.mult is not None:
            self._committed = self.contact.mult.copy()

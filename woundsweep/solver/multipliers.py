"""Variables a problem carries beside u that Newton updates with each step (the contact
stages' multipliers, `woundsweep.contact.ContactMultipliers`): the `Multipliers` protocol and
`NO_MULTIPLIERS`, the no-ops of a problem that carries none."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

__all__ = ["NO_MULTIPLIERS", "Multipliers"]


class Multipliers(Protocol):
    """Variables a problem carries beside u, updated by Newton with each step."""

    def reset(self) -> None:
        """Start of a stage: forget every earlier solve."""
        ...

    def begin(self) -> None:
        """Start of a solve."""
        ...

    def predict(self, du: np.ndarray) -> Any:
        """At the current state, what u += gamma du would make of them (for `accept`)."""
        ...

    def accept(self, prediction: Any, gamma: float) -> None:
        """Take the update u += gamma du that ``prediction`` was made for."""
        ...

    def snapshot(self) -> Any:
        """Their current values (to `restore` after a rejected relaxation)."""
        ...

    def restore(self, saved: Any) -> None:
        """Return to a `snapshot`."""
        ...

    def commit(self) -> None:
        """A solve converged."""
        ...


class _NoMultipliers:
    """The `Multipliers` of a problem that carries none."""

    def reset(self) -> None:
        pass

    def begin(self) -> None:
        pass

    def predict(self, du: np.ndarray) -> None:
        return None

    def accept(self, prediction: Any, gamma: float) -> None:
        pass

    def snapshot(self) -> None:
        return None

    def restore(self, saved: Any) -> None:
        pass

    def commit(self) -> None:
        pass


NO_MULTIPLIERS = _NoMultipliers()

"""Dirichlet conditions on flat dof indices: the rows a condition holds and its values there,
kept together from the recipe that states them to the Newton solve that imposes them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Dirichlet"]


@dataclass(frozen=True, eq=False)
class Dirichlet:
    """u[rows] = values. ``values`` None: the rows are held where a starting state has them
    (`resolve`)."""

    rows: np.ndarray
    values: np.ndarray | None = None

    def __post_init__(self) -> None:
        rows = np.asarray(self.rows, dtype=np.int32).ravel()
        object.__setattr__(self, "rows", rows)
        if self.values is not None:
            values = np.asarray(self.values, dtype=float).ravel()
            if values.shape != rows.shape:
                raise ValueError(f"{len(rows)} Dirichlet rows but {len(values)} values")
            object.__setattr__(self, "values", values)

    @classmethod
    def none(cls) -> Dirichlet:
        """No condition (every dof free)."""
        return cls(np.zeros(0, dtype=np.int32), np.zeros(0))

    def resolve(self, u: np.ndarray) -> Dirichlet:
        """This condition with its values: those given, else ``u``'s at its rows."""
        if self.values is not None:
            return self
        return Dirichlet(self.rows, u[self.rows].copy())

    @property
    def target(self) -> np.ndarray:
        """The values (ValueError while the condition is unresolved)."""
        if self.values is None:
            raise ValueError("an unresolved Dirichlet condition has no values")
        return self.values

    @classmethod
    def union(cls, parts: Sequence[Dirichlet], u: np.ndarray) -> Dirichlet:
        """The conditions of ``parts`` together, each resolved at ``u``, in their order; a row
        held twice keeps its first value (and the rows are then sorted)."""
        resolved = [p.resolve(u) for p in parts]
        if not resolved:
            return cls.none()
        rows = np.concatenate([p.rows for p in resolved])
        values = np.concatenate([p.target for p in resolved])
        if len(np.unique(rows)) < len(rows):
            rows, first = np.unique(rows, return_index=True)
            values = values[first]
        return cls(rows, values)

    def toward(self, target: Dirichlet, s: float) -> Dirichlet:
        """The condition a fraction ``s`` of the way from this one to ``target`` (same rows)."""
        return Dirichlet(self.rows, self.target + s * (target.target - self.target))

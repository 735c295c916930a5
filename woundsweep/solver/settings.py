"""Newton's numerical settings: the sweep's ``solver`` section (pure Python, no PETSc)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

__all__ = ["NewtonSettings"]


@dataclasses.dataclass(frozen=True)
class NewtonSettings:
    """Numerical settings (sweep section ``solver``; its other keys are the model's)."""

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

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any] | None) -> NewtonSettings:
        """Settings from a sweep's ``solver`` mapping; missing keys keep their defaults."""
        if not values:
            return cls()
        kwargs = {}
        for f in dataclasses.fields(cls):
            if f.name in values:
                cast = {"int": int, "bool": bool}.get(str(f.type), float)
                kwargs[f.name] = cast(values[f.name])
        return cls(**kwargs)

"""Nonlinear solution algorithms, apart from any model: Newton and load continuation.

`NewtonSettings` (`woundsweep.config.solver`) is pure Python; the solvers need petsc4py
and are loaded on first use. The function `continuation` is imported from its module,
`woundsweep.solver.continuation`.
"""

from __future__ import annotations

from ..config.solver import NewtonSettings
from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "continuation": ("ContinuationResult", "LoadState"),
        "dirichlet": ("Dirichlet",),
        "newton": ("NewtonResult", "NewtonSolver", "NonlinearProblem", "Policy"),
        "symmetry": ("Isometry", "Subspace", "SymmetryBasis", "mirror_node_map", "symmetry_basis"),
    },
)
__all__ += ["NewtonSettings"]

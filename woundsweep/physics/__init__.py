"""The wound model and the job function: materials, the element, the discretised domain,
the forms, the problem with its PETSc glue, the six stages, stress statistics, profiles and
the job (`job`, `entry`). `materials` needs UFL; the rest needs DOLFINx (through `compat`)
and is loaded on first use.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__ = [
    "Fung",
    "JobMaterials",
    "MooneyRivlin",
    "StageOutcome",
    "WoundDomain",
    "WoundForms",
    "WoundModel",
    "WoundProblem",
    "run_stages",
    "solve_job",
]

_LAZY = {
    "WoundDomain": "domain",
    "Fung": "materials",
    "JobMaterials": "materials",
    "MooneyRivlin": "materials",
    "WoundForms": "forms",
    "WoundProblem": "problem",
    "StageOutcome": "stages",
    "WoundModel": "stages",
    "run_stages": "job",
    "solve_job": "job",
}

__getattr__, __dir__ = lazy_exports(__name__, _LAZY)

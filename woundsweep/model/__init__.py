"""The wound model: materials, the discretised domain, the forms, the problem and the stages.

`woundsweep.model.parameters` (Table 2) is pure data; `materials` needs UFL; the rest needs
DOLFINx and is loaded on first use.
"""

from __future__ import annotations

from ..lazy import lazy_exports

__all__ = [
    "ClosureZone",
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
    "ClosureZone": "parameters",
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

"""The wound model and the job function: materials, the element, the discretised domain,
the forms, the problem with its PETSc glue, the six stages, stress statistics, profiles and
the job (`job`, `entry`). `materials` needs UFL; the rest needs DOLFINx (through `compat`)
and is loaded on first use.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "domain": ("WoundDomain",),
        "materials": ("Fung", "JobMaterials", "MooneyRivlin"),
        "forms": ("WoundForms",),
        "problem": ("WoundProblem",),
        "model": ("StageOutcome", "WoundModel"),
        "loadpath": ("LoadStep", "PenaltyRamp", "Solve", "run_load_step"),
        "stages": ("run_stage", "stage_recipe"),
        "job": ("run_stages", "solve_job"),
    },
)

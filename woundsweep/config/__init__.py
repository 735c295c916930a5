"""What a run is made of, as typed records: the sweep file (`sweep`), its settings with the
paper's values as defaults (`paper`: materials and stages; `solver`; `analysis`), a job's
geometry (`geometry`), exclusion rules (`rules`), and the manifest and run directory
(`manifest`). Pure Python (pandas for the manifest); names are re-exported lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "paper": (
            "ClosureZone",
            "FungParameters",
            "Materials",
            "MooneyRivlinParameters",
            "StageSettings",
        ),
        "solver": ("NewtonSettings", "SolverSettings"),
        "analysis": ("ModelSettings",),
        "geometry": ("GeometrySpec",),
        "sweep": ("Sweep", "load_sweep", "parse_sweep"),
        "manifest": ("Run", "expand", "load_run"),
    },
)

"""What a run is made of, as typed records: the sweep file (`sweep`), its settings with the
paper's values as defaults (`paper`: materials and stages; `solver`; `analysis`), a job's
geometry (`geometry`), exclusion rules (`rules`), and the manifest and run directory
(`manifest`). Pure Python (pandas for the manifest); names are re-exported lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__ = [
    "ClosureZone",
    "FungParameters",
    "GeometrySpec",
    "Materials",
    "ModelSettings",
    "MooneyRivlinParameters",
    "NewtonSettings",
    "Run",
    "SolverSettings",
    "StageSettings",
    "Sweep",
    "expand",
    "load_run",
    "load_sweep",
    "parse_sweep",
]

_HOME = {
    "ClosureZone": "paper",
    "FungParameters": "paper",
    "Materials": "paper",
    "MooneyRivlinParameters": "paper",
    "StageSettings": "paper",
    "NewtonSettings": "solver",
    "SolverSettings": "solver",
    "ModelSettings": "analysis",
    "GeometrySpec": "geometry",
    "Sweep": "sweep",
    "load_sweep": "sweep",
    "parse_sweep": "sweep",
    "Run": "manifest",
    "expand": "manifest",
    "load_run": "manifest",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

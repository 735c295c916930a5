"""Typed exceptions. Every user-facing failure is a `WoundsweepError` with a one-line message."""

from __future__ import annotations

__all__ = [
    "AnalysisError",
    "GeometryError",
    "SolverError",
    "StoreError",
    "SweepError",
    "WoundsweepError",
]


class WoundsweepError(Exception):
    """Base class: the CLI prints ``str(err)`` on one line and exits with ``exit_code``."""

    exit_code = 2


class SweepError(WoundsweepError):
    """A sweep file that cannot be read or does not validate."""

    def __init__(self, path: object, key: str, problem: str) -> None:
        self.path, self.key, self.problem = str(path), key, problem
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + problem)


class GeometryError(WoundsweepError):
    """A wound geometry that cannot be built or meshed."""

    exit_code = 4


class SolverError(WoundsweepError):
    """Invalid solver input (not a convergence failure: those are statuses)."""


class StoreError(WoundsweepError):
    """A run directory or result store that is missing, inconsistent or corrupt."""


class AnalysisError(WoundsweepError):
    """A store that cannot support the requested analysis."""

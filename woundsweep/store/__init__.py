"""The result store of a run directory: result identity (`identity`: fingerprints, file
checksums), the solver's HDF5 file (`solverfile`), reading and validating stored results
(`reader`) and writing them crash-safely (`writer`). No DOLFINx; names are re-exported
lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "identity": ("result_fingerprint",),
        "solverfile": ("read_solver_file", "write_solver_file"),
        "reader": ("check_result", "read_results", "scan_store"),
        "writer": ("Store",),
    },
)

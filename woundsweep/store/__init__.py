"""The result store of a run directory: result identity (`identity`: fingerprints, file
checksums), the solver's HDF5 file (`solverfile`), reading and validating stored results
(`reader`), the store's directories and temporaries (`paths`), resume triage (`triage`) and
writing results crash-safely (`writer`: `Store`, all three in one object). No DOLFINx; names
are re-exported lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "identity": ("result_fingerprint",),
        "solverfile": ("read_solver_file", "write_solver_file"),
        "reader": ("check_result", "read_results", "rows_element_degree", "scan_store"),
        "paths": ("StorePaths",),
        "triage": ("JobState", "StoreTriage"),
        "writer": ("AttemptOutcome", "FIELDS_CHOICES", "Store"),
    },
)

"""The result store of a run directory: result identity (`identity`: fingerprints, file
checksums), the solver's HDF5 file (`solverfile`), reading and validating stored results
(`reader`) and writing them crash-safely (`writer`). No DOLFINx; names are re-exported
lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__ = [
    "Store",
    "check_result",
    "read_results",
    "read_solver_file",
    "result_fingerprint",
    "scan_store",
    "write_solver_file",
]

_HOME = {
    "result_fingerprint": "identity",
    "read_solver_file": "solverfile",
    "write_solver_file": "solverfile",
    "check_result": "reader",
    "read_results": "reader",
    "scan_store": "reader",
    "Store": "writer",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

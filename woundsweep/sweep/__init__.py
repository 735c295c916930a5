"""The sweep layer: sweep files and the manifest, shards, the result store, the runner, SLURM.

Modules: `grid` (sweep loading, validation, expansion; `load_run`), `rules` (exclusion rules),
`shards` (the deterministic partition), `identity` (result fingerprints and file
checksums), `store` (the result store and its writes),
`results` (the result schema, validation, `read_results`), `runner` (``woundsweep run``) with
`process`, `classify` and `jitlock`, and `slurm` (batch scripts). Names are re-exported
lazily, so importing the package stays cheap.
"""

from __future__ import annotations

from ..lazy import lazy_exports

__all__ = [
    "DEFAULTS",
    "GEOMETRY_KEYS",
    "MANIFEST_COLUMNS",
    "Run",
    "RunOptions",
    "Shard",
    "Store",
    "Sweep",
    "estimate_cost",
    "expand",
    "load_run",
    "load_sweep",
    "parse_shard",
    "parse_sweep",
    "partition",
    "read_results",
    "run_shard",
    "shard_jobs",
    "summarize",
]

_HOME = {
    "DEFAULTS": "grid",
    "GEOMETRY_KEYS": "grid",
    "MANIFEST_COLUMNS": "grid",
    "Run": "grid",
    "Sweep": "grid",
    "expand": "grid",
    "load_run": "grid",
    "load_sweep": "grid",
    "parse_sweep": "grid",
    "Shard": "shards",
    "estimate_cost": "shards",
    "parse_shard": "shards",
    "partition": "shards",
    "shard_jobs": "shards",
    "Store": "store",
    "read_results": "results",
    "summarize": "results",
    "RunOptions": "runner",
    "run_shard": "runner",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

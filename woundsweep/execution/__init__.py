"""Running jobs: the deterministic shards (`shards`), the runner of ``woundsweep run``
(`runner`) with its processes (`process`), fork server (`forkserver`), failure classes
(`classify`) and JIT-lock handling (`jitlock`), the progress summary of ``status``
(`summary`), and SLURM batch scripts (`slurm`). Never imports DOLFINx: a job runs the job
function (`woundsweep.physics.entry`) in a process of its own. Names are re-exported lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__ = [
    "JobRequest",
    "RunOptions",
    "Shard",
    "estimate_cost",
    "parse_shard",
    "partition",
    "run_shard",
    "shard_jobs",
    "summarize",
]

_HOME = {
    "JobRequest": "forkserver",
    "RunOptions": "runner",
    "run_shard": "runner",
    "Shard": "shards",
    "estimate_cost": "shards",
    "parse_shard": "shards",
    "partition": "shards",
    "shard_jobs": "shards",
    "summarize": "summary",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

"""Running jobs: the deterministic shards (`shards`), the runner of ``woundsweep run``
(`runner`) with its job plan (`planning`), processes (`process`), fork server (`forkserver`),
failure classes (`classify`) and JIT-lock handling (`jitlock`), the progress summary of ``status``
(`summary`), and SLURM batch scripts (`slurm`). Never imports DOLFINx: a job runs the job
function (`woundsweep.physics.entry`) in a process of its own. Names are re-exported lazily."""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "forkserver": ("JobRequest",),
        "runner": ("RunOptions", "run_shard"),
        "shards": ("Shard", "estimate_cost", "parse_shard", "partition", "shard_jobs"),
        "summary": ("summarize",),
    },
)

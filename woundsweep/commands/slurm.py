"""``woundsweep slurm RUN_DIR --shards N [...] [--submit]``: the sweep as a SLURM job array."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import click

from ..config.manifest import load_run
from ..execution.slurm import (
    SlurmError,
    SlurmOptions,
    SubmitError,
    check_path,
    mem_bytes,
    parse_extra,
    parse_mem,
    parse_stages,
    parse_time,
    read_submissions,
    record_submission,
    submit,
    warmup_shard,
    write_scripts,
)

__all__ = ["cmd"]

# The range of `woundsweep run --max-memory` (commands/run.py), which the scripts pass on.
MIN_JOB_GB, MAX_JOB_GB = 0.05, 1e6


def _word(value: str | None, option: str) -> str | None:
    # Partition and account names go on an #SBATCH line: one word, no quotes.
    if value is not None and not re.fullmatch(r"[^\s'\"\\%]+", value):
        raise SlurmError(f"{option} {value!r}: expected a single name without spaces or quotes")
    return value


@click.command("slurm")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--shards", type=int, required=True, help="Array tasks: task i runs shard i/N.")
@click.option(
    "--cpus-per-task", type=int, default=1, show_default=True,
    help="CPUs per array task = workers of its `woundsweep run`.",
)  # fmt: skip
@click.option("--time", "time_", default=None, help="Time limit per job, HH:MM:SS or D-HH:MM:SS.")
@click.option("--mem", default=None, help="Memory per job (SLURM syntax: 4G, 3500M).")
@click.option("--partition", default=None, help="SLURM partition.")
@click.option("--account", default=None, help="SLURM account.")
@click.option(
    "--extra", multiple=True,
    help='Extra directive for every script, e.g. "#SBATCH --qos=long" (repeatable).',
)  # fmt: skip
@click.option(
    "--cache-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
    help="Shared XDG_CACHE_HOME for the JIT cache [RUN_DIR/slurm/cache].",
)  # fmt: skip
@click.option(
    "--stages", default=None, help="Stages A-B each job runs [the runner's default: 1-6]."
)
@click.option("--analyze", is_flag=True, help="The follow-up job also runs `woundsweep analyze`.")
@click.option("--submit", "do_submit", is_flag=True, help="Submit with sbatch and record the ids.")
def cmd(
    run_dir: Path,
    shards: int,
    cpus_per_task: int,
    time_: str | None,
    mem: str | None,
    partition: str | None,
    account: str | None,
    extra: tuple[str, ...],
    cache_dir: Path | None,
    stages: str | None,
    analyze: bool,
    do_submit: bool,
) -> None:
    """Write RUN_DIR/slurm/{warmup,sweep,followup}.sbatch and, with --submit, submit them.

    The warm-up job runs the cheapest job alone to fill the JIT cache; the array (task i:
    `woundsweep run RUN_DIR --shard i/N --workers $SLURM_CPUS_PER_TASK`) starts after it
    (afterok); the follow-up runs `woundsweep status` (and `analyze`) after the array
    (afterany). Logs go to RUN_DIR/slurm/logs/, job ids to RUN_DIR/slurm/jobs.json.
    Resubmitting after a partial run redoes only the jobs missing from the store.
    """
    if shards < 1:
        raise SlurmError(f"--shards {shards}: need at least 1")
    if cpus_per_task < 1:
        raise SlurmError(f"--cpus-per-task {cpus_per_task}: need at least 1")
    time_ = parse_time(time_) if time_ is not None else None
    mem = parse_mem(mem) if mem is not None else None
    per_job_gb = 0.9 * mem_bytes(mem) / cpus_per_task / 1e9 if mem is not None else None
    if per_job_gb is not None and not MIN_JOB_GB <= round(per_job_gb, 2) <= MAX_JOB_GB:
        raise SlurmError(
            f"--mem {mem}: 90% of it over {cpus_per_task} workers is {per_job_gb:.3g} GB per "
            f"job, outside the {MIN_JOB_GB}-{MAX_JOB_GB:g} GB that `woundsweep run --max-memory` "
            "accepts"
        )
    lines = tuple(parse_extra(e) for e in extra)
    stages = parse_stages(stages) if stages is not None else None
    rd = check_path(Path(os.path.abspath(run_dir)), "RUN_DIR")
    cache = check_path(Path(os.path.abspath(cache_dir)), "--cache-dir") if cache_dir else None
    run = load_run(rd)
    if shards > len(run.manifest):
        raise SlurmError(
            f"--shards {shards}: more shards than the {len(run.manifest)} jobs of {rd}"
        )
    opts = SlurmOptions(
        run_dir=rd,
        shards=shards,
        python=os.path.abspath(sys.executable),
        cpus_per_task=cpus_per_task,
        time=time_,
        mem=mem,
        partition=_word(partition, "--partition"),
        account=_word(account, "--account"),
        extra=lines,
        analyze=analyze,
        stages=stages,
        cache_dir=cache,
        warmup=warmup_shard(run.manifest),
    )
    if do_submit:
        read_submissions(rd)  # a damaged jobs.json is refused before anything is submitted
    paths = write_scripts(opts)
    click.echo(f"wrote {', '.join(str(p) for p in paths if p is not None)}")
    if not do_submit:
        click.echo(f"submit with: woundsweep slurm {rd} --shards {shards} ... --submit")
        return
    try:
        sub = submit(paths)
    except SubmitError as err:
        if any(err.submission):
            record_submission(opts, err.submission)
        raise
    # The ids first: what was submitted is printed even if recording it fails.
    click.echo(f"warm-up job {sub.warmup} (shard {opts.warmup} of one job)")
    click.echo(f"array job {sub.array} ({shards} tasks, after the warm-up)")
    click.echo(f"follow-up job {sub.followup} (after the array)")
    try:
        where = record_submission(opts, sub)
    except (OSError, SlurmError) as err:
        ids = ", ".join(i for i in sub if i)
        raise SlurmError(f"submitted jobs {ids} but could not record them: {err}") from None
    click.echo(f"job ids recorded in {where}; logs in {opts.log_dir}")

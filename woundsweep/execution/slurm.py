"""SLURM batch scripts for a sweep: a warm-up job, a job array of shards, a follow-up job.

`render(opts)` turns `SlurmOptions` into the text of three scripts (a pure function: same
options, same text), `write_scripts` puts them under ``RUN_DIR/slurm/``, `submit` hands them
to ``sbatch --parsable`` chained by dependencies, and `record_submission` appends the job ids
to ``RUN_DIR/slurm/jobs.json``:

- ``warmup.sbatch``: ``woundsweep run RUN_DIR --shard W/M --workers 1`` for a shard that
  holds one job only, the cheapest (M = the number of jobs, see `warmup_shard`). It fills the
  FFCx JIT cache before the array fans out, so the tasks do not all compile the same forms at
  once (~50 s each, with 10 s lock waits), and its job is stored like any other.
- ``sweep.sbatch``: array 0..N-1, task i runs ``woundsweep run RUN_DIR --shard i/N --workers
  $SLURM_CPUS_PER_TASK``; submitted with ``--dependency=afterok:<warm-up>``.
- ``followup.sbatch``: ``woundsweep status RUN_DIR`` (and ``woundsweep analyze RUN_DIR``);
  submitted with ``--dependency=afterany:<array>``, so it runs however the tasks ended.

Every script runs the absolute interpreter that generated it (``python -m woundsweep``), with
one BLAS/OpenMP thread per process and ``XDG_CACHE_HOME`` on a shared path (default
``RUN_DIR/slurm/cache``: DOLFINx keeps its JIT cache in ``$XDG_CACHE_HOME/fenics``). With
``--mem`` the runner's per-job memory cap is 90% of it split between the workers, so the
runner stops a job before SLURM kills the whole task. Nothing forces a rerun: resubmitting
runs only the jobs missing from the store (the runner resumes).
"""

from __future__ import annotations

import datetime as _dt
import json
import re
import shlex
import shutil
import socket
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import pandas as pd

from ..core.errors import WoundsweepError
from ..core.fsutil import atomic_write_bytes
from ..core.layout import RunLayout
from ..core.schema import parse_stage_range
from .shards import Shard, estimate_cost, partition

__all__ = [
    "SCRIPT_NAMES",
    "ScriptPaths",
    "SlurmError",
    "SlurmOptions",
    "SlurmScripts",
    "SubmitError",
    "Submission",
    "check_path",
    "mem_bytes",
    "parse_extra",
    "parse_mem",
    "parse_stages",
    "parse_time",
    "read_submissions",
    "record_submission",
    "render",
    "submit",
    "warmup_shard",
    "write_scripts",
]

SCRIPT_NAMES = ("warmup.sbatch", "sweep.sbatch", "followup.sbatch")
JOB_NAME = "woundsweep"
# Characters that #SBATCH lines cannot carry in a path: whitespace and quotes break the
# directive's parsing, % starts a filename pattern (%A, %a, %j).
_UNSAFE_PATH = re.compile(r"[\s%'\"\\]")


class SlurmError(WoundsweepError):
    """Invalid SLURM options, or sbatch missing or refusing a script."""


class SubmitError(SlurmError):
    """An sbatch call failed; ``submission`` holds the ids of the jobs submitted before."""

    def __init__(self, message: str, submission: Submission) -> None:
        super().__init__(message)
        self.submission = submission


@dataclass(frozen=True)
class SlurmOptions:
    """Everything the scripts depend on; paths absolute."""

    run_dir: Path
    shards: int
    python: str
    cpus_per_task: int = 1
    time: str | None = None
    mem: str | None = None
    partition: str | None = None
    account: str | None = None
    extra: tuple[str, ...] = ()
    analyze: bool = False
    stages: str | None = None  # None: the runner's default (all stages)
    cache_dir: Path | None = None  # None: RUN_DIR/slurm/cache
    warmup: Shard | None = None  # None: no warm-up job

    @property
    def slurm_dir(self) -> Path:
        return RunLayout(self.run_dir).slurm_dir

    @property
    def log_dir(self) -> Path:
        return self.slurm_dir / "logs"

    @property
    def cache(self) -> Path:
        return self.cache_dir if self.cache_dir is not None else self.slurm_dir / "cache"


class SlurmScripts(NamedTuple):
    """The text of the three scripts."""

    warmup: str | None
    sweep: str
    followup: str


class ScriptPaths(NamedTuple):
    """Where `write_scripts` put them (``warmup`` is None without a warm-up job)."""

    warmup: Path | None
    sweep: Path
    followup: Path


class Submission(NamedTuple):
    """Job ids from one ``--submit`` (None: not submitted)."""

    warmup: str | None
    array: str | None
    followup: str | None


# ---- validation -------------------------------------------------------------------------
def parse_time(text: str) -> str:
    """``HH:MM:SS`` or ``D-HH:MM:SS`` (minutes and seconds below 60), returned as given."""
    m = re.fullmatch(r"(?:(\d+)-)?(\d+):(\d\d):(\d\d)", text.strip())
    if not m or int(m.group(3)) >= 60 or int(m.group(4)) >= 60:
        raise SlurmError(f"--time {text!r}: expected HH:MM:SS or D-HH:MM:SS, e.g. 04:00:00")
    if not any(int(g) for g in m.groups(default="0")):
        raise SlurmError(f"--time {text!r}: must be longer than zero")
    return text.strip()


def parse_mem(text: str) -> str:
    """SLURM memory: a positive integer with an optional K, M, G or T suffix (default M)."""
    m = re.fullmatch(r"(\d+)([KMGT]?)", text.strip().upper())
    if not m or int(m.group(1)) == 0:
        raise SlurmError(f"--mem {text!r}: expected a positive size such as 4G or 3500M")
    return m.group(1) + m.group(2)


def parse_stages(text: str) -> str:
    """``A-B`` or ``A`` with 1 <= A <= B <= 6, normalised to ``A-B``."""
    a, b = parse_stage_range(text, SlurmError)
    return f"{a}-{b}"


def mem_bytes(mem: str) -> int:
    """Bytes of a `parse_mem` value (SLURM's units are binary; no suffix means M)."""
    power = "KMGT".index(mem[-1]) + 1 if mem[-1] in "KMGT" else 2
    return int(mem.rstrip("KMGT")) * 1024**power


def parse_extra(text: str) -> str:
    """One extra directive: ``#SBATCH --opt=val`` (a bare ``--opt=val`` gets the prefix)."""
    line = text.strip()
    if "\n" in line or "\r" in line:
        raise SlurmError(f"--extra {text!r}: one directive per --extra, no newlines")
    if line.startswith("--"):
        line = "#SBATCH " + line
    if not re.fullmatch(r"#SBATCH\s+-\S.*", line):
        raise SlurmError(f"--extra {text!r}: expected '#SBATCH --option[=value]'")
    return line


def check_path(path: Path, what: str) -> Path:
    """An absolute path that #SBATCH lines can hold (no whitespace, quotes, backslash or %)."""
    if _UNSAFE_PATH.search(str(path)):
        raise SlurmError(
            f"{what} {str(path)!r}: SLURM scripts cannot hold a path with spaces, quotes, "
            "backslashes or '%'; use another directory"
        )
    return path


def warmup_shard(manifest: pd.DataFrame) -> Shard:
    """A shard ``W/M`` of one job, the cheapest: M is the number of jobs.

    With as many shards as jobs the partition gives each shard one job; the lightest shard
    by `shards.estimate_cost` holds the cheapest. Computed with `shards.partition` itself,
    so it stays right if the partition changes.
    """
    count = len(manifest)
    if count == 0:
        raise SlurmError("the manifest has no jobs")
    cost = pd.Series(estimate_cost(manifest), index=manifest["job_index"].to_numpy())
    parts = partition(manifest, count)
    loads = [(float(cost.loc[p].sum()), len(p), i) for i, p in enumerate(parts) if len(p)]
    return Shard(min(loads)[2], count)


# ---- rendering ----------------------------------------------------------------------------
def _directives(opts: SlurmOptions, name: str, log: str, cpus: int) -> list[str]:
    lines = [
        f"#SBATCH --job-name={name}",
        f"#SBATCH --cpus-per-task={cpus}",
        "#SBATCH --ntasks=1",
        "#SBATCH --nodes=1",
    ]
    if opts.time:
        lines.append(f"#SBATCH --time={opts.time}")
    if opts.mem:
        lines.append(f"#SBATCH --mem={opts.mem}")
    if opts.partition:
        lines.append(f"#SBATCH --partition={opts.partition}")
    if opts.account:
        lines.append(f"#SBATCH --account={opts.account}")
    lines += [
        f"#SBATCH --output={opts.log_dir}/{log}",
        f"#SBATCH --chdir={opts.run_dir}",
        # A failed dependency cancels the job instead of leaving it pending forever.
        "#SBATCH --kill-on-invalid-dep=yes",
    ]
    return lines + list(opts.extra)


def _environment(opts: SlurmOptions) -> list[str]:
    q = shlex.quote
    return [
        "set -euo pipefail",
        "# One BLAS/OpenMP thread per process: the runner's workers are the parallelism.",
        "export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1",
        "# DOLFINx's FFCx JIT cache ($XDG_CACHE_HOME/fenics) on a path every node shares.",
        f"export XDG_CACHE_HOME={q(str(opts.cache))}",
        f"PYTHON={q(opts.python)}",
        f"RUN_DIR={q(str(opts.run_dir))}",
    ]


def _script(header: str, directives: list[str], body: list[str], opts: SlurmOptions) -> str:
    comment = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines = ["#!/bin/bash", *comment, *directives, "", *_environment(opts), "", *body]
    return "\n".join(lines) + "\n"


def _run_options(opts: SlurmOptions, workers: int) -> str:
    out = f" --stages {opts.stages}" if opts.stages else ""
    # The runner's default cap is a share of the node's RAM, not of the job's --mem: SLURM
    # would kill the whole task first. 90% of --mem split between the workers, in GB (1e9).
    if opts.mem:
        out += f" --max-memory {0.9 * mem_bytes(opts.mem) / workers / 1e9:.2f}"
    return out


def render(opts: SlurmOptions) -> SlurmScripts:
    """The warm-up, array and follow-up scripts for ``opts`` (no I/O)."""
    n = opts.shards
    run = '"$PYTHON" -m woundsweep run "$RUN_DIR"'
    sweep = _script(
        f"woundsweep sweep as a SLURM array: task i runs shard i/{n} of {opts.run_dir}.\n"
        "Written by `woundsweep slurm`; submit with its --submit, which chains the warm-up,\n"
        "this array (afterok) and the follow-up (afterany). Resubmitting runs only the jobs\n"
        "missing from the store.",
        [f"#SBATCH --array=0-{n - 1}"]
        + _directives(opts, JOB_NAME, "sweep-%A_%a.log", opts.cpus_per_task),
        [
            f'exec {run} --shard "${{SLURM_ARRAY_TASK_ID}}/{n}" '
            f'--workers "${{SLURM_CPUS_PER_TASK:-1}}"{_run_options(opts, opts.cpus_per_task)}'
        ],
        opts,
    )
    warm = None
    if opts.warmup is not None:
        w = opts.warmup
        warm = _script(
            f"woundsweep warm-up: runs the one job of shard {w} (the cheapest) alone, so the\n"
            "FFCx JIT cache is filled before the array fans out. Its job is stored as usual.",
            _directives(opts, f"{JOB_NAME}-warmup", "warmup-%j.log", 1),
            [f"exec {run} --shard {w.index}/{w.count} --workers 1{_run_options(opts, 1)}"],
            opts,
        )
    body = ['"$PYTHON" -m woundsweep status "$RUN_DIR"']
    if opts.analyze:
        body.append('"$PYTHON" -m woundsweep analyze "$RUN_DIR"')
    follow = _script(
        "woundsweep follow-up: runs after every array task has ended (afterany), however\n"
        "it ended, and reports what the store holds"
        + (", then fits and evaluates the model." if opts.analyze else "."),
        _directives(opts, f"{JOB_NAME}-followup", "followup-%j.log", opts.cpus_per_task),
        body,
        opts,
    )
    return SlurmScripts(warm, sweep, follow)


def write_scripts(opts: SlurmOptions) -> ScriptPaths:
    """Write the scripts under ``RUN_DIR/slurm/`` and create the log and cache directories.

    SLURM does not create the directory of ``--output``: a missing one loses the logs.
    """
    scripts = render(opts)
    opts.log_dir.mkdir(parents=True, exist_ok=True)
    opts.cache.mkdir(parents=True, exist_ok=True)
    paths: list[Path | None] = []
    for name, text in zip(SCRIPT_NAMES, scripts):
        path = opts.slurm_dir / name
        if text is None:
            path.unlink(missing_ok=True)  # a stale warm-up script would mislead
            paths.append(None)
            continue
        atomic_write_bytes(path, text.encode())
        path.chmod(0o755)
        paths.append(path)
    return ScriptPaths(*paths)  # type: ignore[arg-type]  # only the warm-up's text may be None


# ---- submission ----------------------------------------------------------------------------
def _sbatch(sbatch: str, args: Sequence[str]) -> str:
    try:
        res = subprocess.run(
            [sbatch, "--parsable", *args], capture_output=True, text=True, timeout=120
        )
    except (OSError, subprocess.TimeoutExpired) as err:
        raise SlurmError(f"sbatch: {err}") from None
    if res.returncode != 0:
        msg = " ".join((res.stderr.strip() or res.stdout.strip() or "no output").split())
        raise SlurmError(f"sbatch {' '.join(args)}: exit {res.returncode}: {msg}")
    m = re.match(r"\s*(\d+)", res.stdout)
    if not m:
        raise SlurmError(f"sbatch {' '.join(args)}: no job id in {res.stdout.strip()!r}")
    return m.group(1)


def submit(paths: ScriptPaths, sbatch: str | None = None) -> Submission:
    """Submit warm-up, array (afterok warm-up) and follow-up (afterany array).

    Raises `SubmitError` if an sbatch fails, naming the jobs already submitted (they are
    on its ``submission`` attribute, for the record and for ``scancel``).
    """
    exe = sbatch or shutil.which("sbatch")
    if exe is None:
        raise SlurmError("sbatch not found on PATH: run --submit on a SLURM login node")
    ids: list[str | None] = [None, None, None]
    try:
        dep: list[str] = []
        if paths.warmup is not None:
            ids[0] = _sbatch(exe, [str(paths.warmup)])
            dep = [f"--dependency=afterok:{ids[0]}"]
        ids[1] = _sbatch(exe, [*dep, str(paths.sweep)])
        ids[2] = _sbatch(exe, [f"--dependency=afterany:{ids[1]}", str(paths.followup)])
    except SlurmError as err:
        done = [i for i in ids if i]
        note = f" (already submitted: {', '.join(done)}; scancel them)" if done else ""
        raise SubmitError(f"{err}{note}", Submission(*ids)) from None
    return Submission(*ids)


def read_submissions(run_dir: Path) -> list[dict[str, Any]]:
    """The records of ``RUN_DIR/slurm/jobs.json`` (empty if none)."""
    path = RunLayout(run_dir).slurm_dir / "jobs.json"
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text())
        return list(data["submissions"])
    except (ValueError, KeyError, TypeError):
        raise SlurmError(f"{path}: unreadable (move it aside to record new submissions)") from None


def record_submission(opts: SlurmOptions, sub: Submission) -> Path:
    """Append one submission to ``RUN_DIR/slurm/jobs.json`` (atomic rewrite)."""
    path = opts.slurm_dir / "jobs.json"
    records = read_submissions(opts.run_dir)
    records.append(
        {
            "submitted": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "host": socket.gethostname(),
            "shards": opts.shards,
            "warmup_job_id": sub.warmup,
            "array_job_id": sub.array,
            "followup_job_id": sub.followup,
            "warmup_shard": str(opts.warmup) if opts.warmup else None,
        }
    )
    text = json.dumps({"submissions": records}, indent=2) + "\n"
    atomic_write_bytes(path, text.encode())
    return path

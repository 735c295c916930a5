"""How a job attempt ended: its failure class, from the exit status and what the runner saw.

The solver's exit status is an `ExitCode` (0 converged, 3 a stage not converged, 2 invalid
input, 4 mesh failed). Killed for time -> ``timeout``; killed for memory, or a
``MemoryError``/``bad_alloc`` in the log when a cap is set -> ``out-of-memory``; a signal, any
other exit status, or exit 0/3 without a valid output file -> ``crashed``. Only the
`TRANSIENT_CLASSES` are retried.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

from ..core.errors import StoreError
from ..core.schema import ExitCode, FailureClass, StageStatus
from ..store.solverfile import SolverOutput, read_solver_file
from .jitlock import JIT_TIMEOUT_RE
from .process import Attempt, log_tail, signal_name

__all__ = ["TRANSIENT_CLASSES", "Classified", "classify", "stability_note"]

# Retried up to --retries times: they depend on the machine's state (load, a JIT lock, a node
# fault), not on the job. Out-of-memory is not: a job's memory use is set by its mesh, so the
# same cap stops it again; rerun those with a larger --max-memory and --rerun-failed.
TRANSIENT_CLASSES = frozenset({FailureClass.TIMEOUT, FailureClass.CRASHED})
_OOM_RE = re.compile(r"MemoryError|std::bad_alloc|Out of memory|Cannot allocate memory")
_DISK_FULL_RE = re.compile(r"No space left on device|Disk quota exceeded|Read-only file system")


def stability_note(stage: Mapping[str, Any]) -> str:
    """'; last converged state stable|unstable (...)' from a failed stage's stability extras
    (the lowest eigenvalue nearest zero of its tangent), or '' without them."""
    eig, k_V = stage.get("stability_min_eig_mN_per_mm"), stage.get("stability_penalty_kPa")
    if eig is None or not math.isfinite(float(eig)):
        return ""
    kind = "unstable" if float(eig) < 0.0 else "stable"
    at = f" at k_V = {float(k_V):.3g} kPa" if k_V is not None else ""
    return f"; last converged state {kind} (lowest eigenvalue {float(eig):.3g} mN/mm{at})"


class Classified(NamedTuple):
    """An attempt's failure class, its one-line detail, and the solver output if valid;
    ``disk_full`` is the log's words when the attempt failed on a full (or read-only) disk."""

    failure_class: FailureClass
    detail: str
    output: SolverOutput | None
    disk_full: str = ""


def classify(
    att: Attempt, status: int, stages: tuple[int, int], max_memory_bytes: int | None, log: Path
) -> Classified:
    """Turn an ended attempt (``status`` as from ``wait``) into a failure class.

    A crash on a held FFCx JIT lock records the lock in ``att.extra["jit_lock"]``.
    """
    job = att.job
    if att.killed_for == "timeout":
        limit = att.deadline - att.started
        return Classified(
            FailureClass.TIMEOUT, f"killed after {limit:.0f} s wall-clock limit", None
        )
    if att.killed_for == "memory":
        cap = (max_memory_bytes or 0) / 2**20
        return Classified(
            FailureClass.OUT_OF_MEMORY,
            f"killed: resident memory {att.max_rss / 2**20:.0f} MiB above the {cap:.0f} MiB cap",
            None,
        )
    tail = log_tail(log, att.log_offset)
    failed = os.WIFSIGNALED(status) or os.WEXITSTATUS(status) not in (
        ExitCode.OK,
        ExitCode.NOT_CONVERGED,
    )
    full = _DISK_FULL_RE.search(tail) if failed else None
    if full:  # the disk, not the job: retrying or storing a failure would be wrong
        return Classified(FailureClass.CRASHED, full.group(0), None, disk_full=full.group(0))
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        return Classified(FailureClass.CRASHED, f"killed by {signal_name(sig)}", None)
    code = os.WEXITSTATUS(status)
    if code in (ExitCode.OK, ExitCode.NOT_CONVERGED):
        if not att.out.exists():
            return Classified(FailureClass.CRASHED, f"exit {code} but no output file", None)
        try:
            out = read_solver_file(att.out, job.job_id, stages)
        except StoreError as err:
            return Classified(
                FailureClass.CRASHED, f"exit {code} without a valid output: {err}", None
            )
        missing = [k for k in range(stages[0], stages[1] + 1) if k not in out.stages]
        bad = [k for k in sorted(out.stages) if out.stages[k].status != StageStatus.CONVERGED]
        if code == ExitCode.OK and missing:
            return Classified(
                FailureClass.CRASHED, f"exit 0 but no result for stages {missing}", None
            )
        if bad or code == ExitCode.NOT_CONVERGED:
            what = "exit 3"
            if bad:
                first = out.stages[bad[0]]
                what = f"stage {bad[0]} {first.status}{stability_note(first.diagnostics)}"
            return Classified(FailureClass.NOT_CONVERGED, what, out)
        return Classified(FailureClass.CONVERGED, "", out)
    last = next((ln for ln in reversed(tail.strip().splitlines()) if ln.strip()), "")[:300]
    if code == ExitCode.INVALID:
        return Classified(FailureClass.INVALID, f"exit 2: {last}", None)
    if code == ExitCode.MESH_FAILED:
        return Classified(FailureClass.MESH_FAILED, f"exit 4: {last}", None)
    if max_memory_bytes is not None and _OOM_RE.search(tail):
        return Classified(
            FailureClass.OUT_OF_MEMORY,
            f"exit {code}: allocation failed under the cap: {last}",
            None,
        )
    m = JIT_TIMEOUT_RE.search(tail)
    if m:
        att.extra["jit_lock"] = Path(m.group(1))
    return Classified(FailureClass.CRASHED, f"exit {code}: {last}", None)

"""Test-only fault switch: make a `woundsweep solve` job hang, crash, blow its memory or fail.

TEST-ONLY. Nothing in a real sweep sets it. `woundsweep solve` calls `maybe_inject(job_index)`
first thing, so the runner's failure handling can be tested with real processes.

``WOUNDSWEEP_FAULT`` holds one or more comma-separated specs ``KIND[@JOB][#ATTEMPT]``:

- ``KIND``: ``hang`` (sleep forever), ``segv`` (a real segmentation fault), ``oom`` (allocate and
  touch memory until stopped), ``fail`` (an uncaught Python exception, exit status 1),
  ``exit:<code>`` (exit at once with that status, no output), ``enospc`` (what a full disk
  did to a solve: HDF5's "No space left on device" error on stderr, then a segmentation fault).
- ``@JOB``: only the job with that ``job_index`` (otherwise every job).
- ``#ATTEMPT``: only that attempt (1-based), read from ``WOUNDSWEEP_ATTEMPT`` which the runner
  sets; lets a test show that a transient failure is retried and then succeeds.

The first spec that matches the job and attempt fires; no match means nothing happens.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from typing import NamedTuple

__all__ = ["ATTEMPT_ENV", "FAULT_ENV", "FaultSpec", "maybe_inject", "parse_faults"]

FAULT_ENV = "WOUNDSWEEP_FAULT"
ATTEMPT_ENV = "WOUNDSWEEP_ATTEMPT"
KINDS = ("hang", "segv", "oom", "fail", "exit", "enospc")
# The oom fault gives up (MemoryError) after this much, so that a runner whose memory cap does
# not work cannot take the whole machine down with it; the runner tests check who stopped it.
OOM_CEILING_BYTES = 8 * 1024**3
OOM_CHUNK_BYTES = 32 * 1024**2


class FaultSpec(NamedTuple):
    """One parsed ``KIND[@JOB][#ATTEMPT]`` spec; ``code`` is set for ``exit``."""

    kind: str
    code: int | None
    job_index: int | None
    attempt: int | None

    def matches(self, job_index: int, attempt: int) -> bool:
        return (self.job_index is None or self.job_index == job_index) and (
            self.attempt is None or self.attempt == attempt
        )


def _int(text: str, spec: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{FAULT_ENV}: bad number {text!r} in {spec!r}") from None


def parse_faults(value: str) -> list[FaultSpec]:
    """Parse a ``WOUNDSWEEP_FAULT`` value; raises ``ValueError`` naming the bad spec."""
    specs = []
    for raw in value.split(","):
        spec = raw.strip()
        if not spec:
            continue
        rest, attempt = spec, None
        if "#" in rest:
            rest, _, a = rest.partition("#")
            attempt = _int(a, spec)
        job = None
        if "@" in rest:
            rest, _, j = rest.partition("@")
            job = _int(j, spec)
        kind, _, arg = rest.partition(":")
        if kind not in KINDS:
            raise ValueError(f"{FAULT_ENV}: unknown fault {kind!r} in {spec!r} (one of {KINDS})")
        if (kind == "exit") != bool(arg):
            raise ValueError(f"{FAULT_ENV}: {spec!r}: only exit takes a code (exit:<code>)")
        code = _int(arg, spec) if kind == "exit" else None
        specs.append(FaultSpec(kind, code, job, attempt))
    return specs


def _fire(spec: FaultSpec, job_index: int) -> None:
    print(f"{FAULT_ENV}: injecting {spec.kind} into job {job_index}", file=sys.stderr, flush=True)
    sys.stdout.flush()
    if spec.kind == "hang":
        while True:
            time.sleep(3600)
    elif spec.kind == "segv":
        ctypes.string_at(0)  # a genuine SIGSEGV, as a crashing C extension would give
    elif spec.kind == "enospc":
        print(
            "HDF5-DIAG: Error detected in HDF5 (1.10.8) thread 1:\n"
            "  #000: H5Dio.c line 291 in H5Dwrite(): can't write data\n"
            "  #001: H5FDsec2.c line 862 in H5FD__sec2_write(): file write failed: "
            "errno = 28, error message = 'No space left on device'",
            file=sys.stderr,
            flush=True,
        )
        ctypes.string_at(0)
    elif spec.kind == "oom":
        hoard: list[bytes] = []
        while len(hoard) * OOM_CHUNK_BYTES < OOM_CEILING_BYTES:
            hoard.append(b"\x01" * OOM_CHUNK_BYTES)  # touched pages: counts in RSS at once
            time.sleep(0.01)
        raise MemoryError(
            f"{FAULT_ENV}=oom reached {OOM_CEILING_BYTES} bytes without being stopped"
        )
    elif spec.kind == "fail":
        raise RuntimeError(f"{FAULT_ENV}=fail: injected failure in job {job_index}")
    elif spec.kind == "exit":
        sys.stderr.flush()
        os._exit(spec.code if spec.code is not None else 1)


def maybe_inject(job_index: int) -> None:
    """Fire the fault that ``WOUNDSWEEP_FAULT`` names for this job and attempt, if any."""
    value = os.environ.get(FAULT_ENV, "")
    if not value:
        return
    attempt = int(os.environ.get(ATTEMPT_ENV, "1") or 1)
    for spec in parse_faults(value):
        if spec.matches(job_index, attempt):
            _fire(spec, job_index)
            return

"""Resume triage: whether a job's stored result can stand, and moving damaged ones aside.

"Parquet file present and valid" means the job is complete, fields included (the writer
stores the fields first): that is the resume rule. A result written with other settings
(another fingerprint, `woundsweep.store.identity`) or fewer stages than asked is stale and
redone; a damaged one (its Parquet file, or the sha256 of its fields or mesh file, checked by
`woundsweep.store.reader`) goes to ``RUN_DIR/corrupt/`` and is redone.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import NamedTuple

from ..config.manifest import JobRow, load_run
from ..config.sweep import Sweep, load_sweep
from ..core.errors import StoreError
from ..core.schema import ResultState
from .identity import file_sha256, fingerprints, result_fingerprint
from .paths import StorePaths
from .reader import check_result, read_footer, store_file_names

__all__ = ["JobState", "StoreTriage"]


class JobState(NamedTuple):
    """Resume bookkeeping for one job: its `ResultState`, stored failure class and why."""

    state: ResultState
    failure_class: str | None = None
    reason: str = ""


class StoreTriage(StorePaths):
    """The store of one run directory as the runner's resume sees it."""

    def __init__(self, run_dir: str | Path, sweep: Sweep | None = None) -> None:
        super().__init__(run_dir)
        self._sweep = sweep
        self._expected: dict[str, str] | None = None
        self._memo: dict = {}

    @property
    def sweep(self) -> Sweep:
        """The run's sweep (its settings make the results' fingerprints)."""
        if self._sweep is None:
            self._sweep = load_sweep(self.layout.sweep)
        return self._sweep

    def fingerprint(self, job: JobRow) -> str:
        return result_fingerprint(self.sweep, job)

    def job_state(
        self, job_id: str, stages: tuple[int, int], fingerprint: str | None = None
    ) -> JobState:
        """Is the job's result present, valid, current, with intact files, covering ``stages``?

        ``fingerprint`` defaults to the one the run's manifest and sweep give the job.
        """
        path = self.result_path(job_id)
        if not path.exists():
            return JobState(ResultState.MISSING)
        if fingerprint is None:
            if self._expected is None:
                run = load_run(self.run_dir)
                self._expected = fingerprints(run.sweep, run.manifest)
            fingerprint = self._expected.get(job_id)
        chk = check_result(path, job_id, self.run_dir, fingerprint, memo=self._memo)
        meta = chk.meta or {}
        if chk.state != ResultState.DONE:
            return JobState(chk.state, meta.get("failure_class"), chk.reason)
        lo, hi = meta["stages"]
        if lo > stages[0] or hi < stages[1]:
            return JobState(ResultState.STALE, meta["failure_class"], f"has stages {lo}-{hi}")
        return JobState(ResultState.DONE, meta["failure_class"])

    def quarantine(self, job_id: str, files: bool = False) -> Path | None:
        """Move a result file that failed validation to RUN_DIR/corrupt/ (kept for inspection).

        With ``files`` its fields file and a mesh file whose checksum differs go there too.
        """
        src = self.result_path(job_id)
        self.corrupt_dir.mkdir(parents=True, exist_ok=True)
        stamp = int(time.time())
        if files:
            meta = read_footer(src) or {}  # a damaged footer names no files to move
            try:  # only the store's own plain names: a crafted footer moves nothing outside
                names = store_file_names(meta, job_id)
            except StoreError:
                names = ("", "")
            for name, key in zip(names, ("fields_sha256", "mesh_sha256")):
                f = self.fields_dir / name
                if name and f.is_file():
                    if key == "mesh_sha256" and file_sha256(f) == meta.get(key):
                        continue  # the geometry's mesh is intact: other jobs use it
                    os.replace(f, self.corrupt_dir / f"{f.name}.{stamp}")
        dst = self.corrupt_dir / f"{src.name}.{stamp}"
        try:
            os.replace(src, dst)
        except FileNotFoundError:
            return None
        return dst

"""The store's directories in a run directory (`core.layout.RunLayout` names them), made on
demand, and the per-attempt temporaries of the solver with their cleanup.

The store::

    RUN_DIR/results/job-<job_id>.parquet   one row per requested stage of the job (all classes)
    RUN_DIR/fields/<job_id>.h5              displacement and cellwise von Mises per stored stage
    RUN_DIR/fields/mesh-<mesh_id>.h5        the mesh, once per mesh id (`GeometrySpec.mesh_id`)
    RUN_DIR/logs/job-<job_id>.log           the job's stdout/stderr, one header per attempt
    RUN_DIR/tmp/                            solver outputs in flight (host and runner pid named)
    RUN_DIR/corrupt/                        result files that failed validation, moved aside
"""

from __future__ import annotations

import os
import socket
import stat
import time
from pathlib import Path

from ..core.errors import StoreError
from ..core.layout import RunLayout

__all__ = ["StorePaths", "check_store_dir", "refuse_store_target"]


def check_store_dir(d: Path) -> None:
    """StoreError unless ``d`` (a directory of the run) is missing or a real directory: a
    symbolic link would lead the store's writes and deletions out of the run directory."""
    try:
        mode = os.lstat(d).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISLNK(mode):
        raise StoreError(
            f"{d}: a symbolic link; the run's own directories must be directories inside it "
            "(replace the link with a directory)"
        )
    if not stat.S_ISDIR(mode):
        raise StoreError(f"{d}: exists and is not a directory (move it away)")


def refuse_store_target(run_dir: str | Path, path: str | Path, option: str) -> None:
    """StoreError when an output ``path`` would land in the store of ``run_dir`` (its
    results, fields, logs, temporaries, set-aside files or mesh cache) or on its sweep,
    manifest, provenance or lock: a command's output must not replace a stored file."""
    layout = RunLayout(Path(run_dir).resolve())
    target = Path(path).resolve()
    dirs = (
        layout.results_dir, layout.fields_dir, layout.logs_dir, layout.tmp_dir,
        layout.corrupt_dir, layout.meshes_dir,
    )  # fmt: skip
    files = (layout.sweep, layout.manifest, layout.provenance, layout.lock)
    if target in files or any(target == d or d in target.parents for d in dirs):
        raise StoreError(
            f"{option} {path}: inside the store of {run_dir} (it would replace or mix with "
            "stored files; write elsewhere)"
        )


class StorePaths:
    """The store's paths in one run directory, and its temporaries."""

    def __init__(self, run_dir: str | Path) -> None:
        self.layout = RunLayout(run_dir)
        self.run_dir = self.layout.run_dir
        self.host = socket.gethostname()

    @property
    def results_dir(self) -> Path:
        return self.layout.results_dir

    @property
    def fields_dir(self) -> Path:
        return self.layout.fields_dir

    @property
    def logs_dir(self) -> Path:
        return self.layout.logs_dir

    @property
    def tmp_dir(self) -> Path:
        return self.layout.tmp_dir

    @property
    def corrupt_dir(self) -> Path:
        return self.layout.corrupt_dir

    def ensure_dirs(self) -> None:
        dirs = (self.results_dir, self.fields_dir, self.logs_dir, self.tmp_dir)
        for d in (*dirs, self.corrupt_dir, self.layout.meshes_dir):
            check_store_dir(d)  # all checked before any is made: a refused run changes nothing
        for d in dirs:
            d.mkdir(parents=True, exist_ok=True)

    def result_path(self, job_id: str) -> Path:
        return self.layout.result_file(job_id)

    def log_path(self, job_id: str) -> Path:
        return self.layout.log_file(job_id)

    def tmp_path(self, job_id: str, attempt: int, suffix: str = ".h5") -> Path:
        """A per-attempt temporary file named after this host and runner pid (see clean_tmp)."""
        return self.tmp_dir / f"{job_id}~{self.host}~{os.getpid()}~{attempt}{suffix}"

    def clean_tmp(self, max_age_s: float = 86400.0) -> int:
        """Remove temporaries of dead runners on this host, and any older than ``max_age_s``.

        Other shards (other pids, other hosts) may be writing their own at this moment.
        """
        removed = 0
        now = time.time()
        candidates: list[Path] = []
        for d in (self.tmp_dir, self.results_dir, self.fields_dir):
            check_store_dir(d)  # never delete through a link out of the run directory
        if self.tmp_dir.is_dir():
            candidates += list(self.tmp_dir.iterdir())
        for d in (self.results_dir, self.fields_dir):
            if d.is_dir():
                candidates += [p for p in d.iterdir() if p.name.startswith(".")]
        for p in candidates:
            parts = p.name.split("~")
            dead = False
            if len(parts) >= 4 and parts[1] == self.host:
                try:
                    os.kill(int(parts[2]), 0)
                except ProcessLookupError:
                    dead = True
                except (ValueError, PermissionError):
                    pass
            try:
                st = os.lstat(p)  # a link is judged (and removed) itself, never its target
            except FileNotFoundError:
                continue
            if stat.S_ISDIR(st.st_mode):
                continue
            old = now - st.st_mtime > max_age_s
            if dead or old:
                try:
                    p.unlink()
                    removed += 1
                except (FileNotFoundError, IsADirectoryError):
                    pass
        return removed

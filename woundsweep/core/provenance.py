"""Provenance records: software versions, git commit, host and time."""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import platform
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

from .. import __version__

__all__ = ["git_commit", "package_versions", "provenance"]

PACKAGES = (
    "numpy", "scipy", "pandas", "pyarrow", "h5py", "gmsh", "xgboost", "scikit-learn", "click", "pyyaml",
    "matplotlib", "fenics-dolfinx", "fenics-ffcx", "fenics-ufl", "fenics-basix", "petsc4py",
)  # fmt: skip


def package_versions() -> dict[str, str | None]:
    """Installed versions from package metadata (no imports: DOLFINx is slow to import)."""
    out: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    if out.get("h5py") is None:  # Debian's h5py ships no dist-info under that name
        try:
            import h5py

            out["h5py"] = h5py.__version__
        except ImportError:
            pass
    return out


def git_commit() -> str | None:
    """The commit of the woundsweep source tree, if it is a git checkout."""
    src = Path(__file__).resolve().parent.parent
    try:
        res = subprocess.run(
            ["git", "-C", str(src), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return res.stdout.strip() or None if res.returncode == 0 else None


def provenance() -> dict[str, Any]:
    """A JSON-serialisable provenance record."""
    return {
        "woundsweep_version": __version__,
        "git_commit": git_commit(),
        "time_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "host": socket.gethostname(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "packages": package_versions(),
    }

"""Typed exceptions. Every user-facing failure is a `WoundsweepError` with a one-line message."""

from __future__ import annotations

import sys

__all__ = [
    "AnalysisError",
    "GeometryError",
    "Interrupted",
    "SolverError",
    "StoreError",
    "SweepError",
    "WoundsweepError",
    "one_line",
    "report",
]

# Control characters (a newline in a path, say) are shown escaped, so a message stays a line.
_ESCAPES = {c: f"\\x{c:02x}" for c in (*range(32), 127)} | {10: "\\n", 13: "\\r", 9: "\\t"}


class WoundsweepError(Exception):
    """Base class: the CLI prints ``str(err)`` on one line and exits with ``exit_code``."""

    exit_code = 2


class SweepError(WoundsweepError):
    """A sweep file that cannot be read or does not validate."""

    def __init__(self, path: object, key: str, problem: str) -> None:
        self.path, self.key, self.problem = str(path), key, problem
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + problem)


class GeometryError(WoundsweepError):
    """A wound geometry that cannot be built or meshed."""

    exit_code = 4


class SolverError(WoundsweepError):
    """Invalid solver input (not a convergence failure: those are statuses)."""


class StoreError(WoundsweepError):
    """A run directory or result store that is missing, inconsistent or corrupt."""


class AnalysisError(WoundsweepError):
    """A store that cannot support the requested analysis."""


class Interrupted(BaseException):
    """Ctrl-C in the CLI (its SIGINT handler raises it in place of KeyboardInterrupt, which
    click answers with a blank line); like KeyboardInterrupt, no ``except Exception`` stops it."""

    exit_code = 130


def one_line(text: str) -> str:
    """``text`` with its control characters escaped (``\\n`` for a newline): one line."""
    return text.translate(_ESCAPES)


def report(err: WoundsweepError | OSError) -> int:
    """Print a user error, or a filesystem error on a path, as one line on stderr; return the
    exit status it calls for (the error's ``exit_code``; 2 for a filesystem error)."""
    if isinstance(err, WoundsweepError):
        print(one_line(f"woundsweep: error: {err}"), file=sys.stderr, flush=True)
        return int(err.exit_code)
    where = f"{err.filename}: " if err.filename else ""
    text = f"woundsweep: error: {where}{err.strerror or err}"
    print(one_line(text), file=sys.stderr, flush=True)
    return 2

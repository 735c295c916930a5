"""The models shipped with woundsweep (``woundsweep/models/``): what `predict` answers with
when no model is given.

The directory holds the files `predict` reads from a run's ``analysis/`` (the classifiers
``model_<split>.json`` + ``_meta.json``, the stress surrogate and the failure model, as
`model_io` writes them) and ``trained_on.json`` (`SHIPPED_FORMAT`): the sweep, the packed
tables with their sha256, the jobs and rows trained on, the surrogate kind, the analysis
settings, the woundsweep version and the sha256 of every shipped model file. `make models`
(``scripts/ship_models.py``) builds it with `install`; `shipped_model` finds and checks it.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import AnalysisError
from ..store.identity import file_sha256
from .model_io import FAILURE_STEM, SURROGATE_STEM, json_bytes
from .settings import SCHEMES

__all__ = [
    "SHIPPED_FORMAT",
    "TRAINED_ON",
    "describe",
    "install",
    "model_files",
    "models_dir",
    "read_record",
    "shipped_model",
    "trained_on_record",
]

SHIPPED_FORMAT = "woundsweep-shipped-models/1"
TRAINED_ON = "trained_on.json"
_REBUILD = "rebuild them with `make models`"
_HEX64 = re.compile(r"[0-9a-f]{64}")


def models_dir() -> Path:
    """The package's directory of shipped models (tests point it elsewhere)."""
    return Path(__file__).resolve().parent.parent / "models"


def _splits(directory: Path) -> list[str]:
    return [s for s in SCHEMES if (directory / f"model_{s}.json").is_file()]


def model_files(directory: Path) -> list[Path]:
    """The files of ``directory`` (a run's ``analysis/``) that `predict` reads."""
    stems = [f"model_{s}" for s in _splits(directory)] + [SURROGATE_STEM, FAILURE_STEM]
    names = [f"{stem}{end}" for stem in stems for end in (".json", "_meta.json")]
    return [directory / n for n in names if (directory / n).is_file()]


def _count(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _text(v: Any) -> bool:
    return isinstance(v, str) and bool(v)


def _tables(v: Any) -> bool:
    return (
        isinstance(v, list)
        and bool(v)
        and all(
            isinstance(t, dict)
            and _text(t.get("role"))
            and _text(t.get("path"))
            and isinstance(t.get("sha256"), str)
            and _HEX64.fullmatch(t["sha256"]) is not None
            for t in v
        )
    )


def _files(v: Any) -> bool:
    return (
        isinstance(v, dict)
        and bool(v)
        and all(isinstance(h, str) and _HEX64.fullmatch(h) is not None for h in v.values())
    )


# Every field `describe` and `shipped_model` read, with its check.
_CHECKS: dict[str, Callable[[Any], bool]] = {
    "sweep": _text,
    "sweep_jobs": lambda v: _count(v) and v > 0,
    "jobs": _count,
    "converged_rows": _count,
    "used_rows": _count,
    "surrogate": lambda v: v is None or _text(v),
    "tables": _tables,
    "settings": lambda v: isinstance(v, dict),
    "woundsweep_version": _text,
    "files": _files,
}


def read_record(directory: Path) -> dict[str, Any]:
    """``directory/trained_on.json``, checked field by field and against the model files
    beside it (their sha256): `AnalysisError` in one line naming the file otherwise."""
    import json

    path = directory / TRAINED_ON
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError):
        raise AnalysisError(f"{path}: missing or unreadable; {_REBUILD}") from None
    if not isinstance(record, dict) or record.get("format") != SHIPPED_FORMAT:
        raise AnalysisError(f"{path}: not a woundsweep {SHIPPED_FORMAT} record; {_REBUILD}")
    for key, ok in _CHECKS.items():
        if key not in record or not ok(record[key]):
            what = "no" if key not in record else "a malformed"
            raise AnalysisError(f"{path}: {what} {key!r}; {_REBUILD}")
    if record["jobs"] > record["sweep_jobs"]:
        raise AnalysisError(f"{path}: more jobs than its sweep has; {_REBUILD}")
    listed: dict[str, str] = record["files"]
    present = {p.name for p in model_files(directory)}
    for name in sorted(present | set(listed)):
        if name not in listed:
            problem = f"{name} is not among its files"
        elif name not in present:
            problem = f"{name} is missing"
        elif file_sha256(directory / name) != listed[name]:
            problem = f"{name} differs from the file it was written with"
        else:
            continue
        raise AnalysisError(
            f"{path}: not the record of the models beside it ({problem}); {_REBUILD}"
        )
    return record


def shipped_model(scheme: str | None) -> tuple[Path, dict[str, Any]]:
    """The shipped models' directory and their checked `read_record`; `AnalysisError` in one
    line when none are shipped or not of the split ``scheme``."""
    directory = models_dir()
    splits = _splits(directory) if directory.is_dir() else []
    if not splits:
        raise AnalysisError(
            f"no models shipped with woundsweep (no model_<split>.json in {directory}): give "
            "MODEL, a run directory after `woundsweep analyze`, or build them with `make "
            "models` in a clone of the repository"
        )
    if scheme is not None and scheme not in splits:
        raise AnalysisError(
            f"--split {scheme}: no shipped model of that split (shipped: {', '.join(splits)}); "
            "give MODEL, a run directory after `woundsweep analyze`"
        )
    return directory, read_record(directory)


def describe(record: Mapping[str, Any]) -> str:
    """One line: what the shipped models were trained on."""
    jobs, total = record["jobs"], record["sweep_jobs"]
    kind = record["surrogate"]
    surrogate = f"{kind} surrogate" if kind else "no stress surrogate"
    calibration = [t.get("sweep") or "another run" for t in record["tables"]
                   if t["role"] == "calibration"]  # fmt: skip
    if len(calibration) == 1:
        surrogate += f", intervals calibrated on {calibration[0]}"
    elif calibration:
        surrogate += (
            f", intervals calibrated on {', '.join(calibration[:-1])} and {calibration[-1]} pooled"
        )
    cross = record.get("off_grid_coverage")
    if cross:
        cov = cross["pooled"]["coverage"]
        surrogate += (
            " (coverage off the grid by cross-calibration: "
            + ", ".join(
                f"{100 * c['empirical']:.0f}% at {100 * float(lv):g}%" for lv, c in cov.items()
            )
            + ")"
        )
    return (
        f"shipped model: trained on {jobs:,} of {total:,} {record['sweep']} jobs "
        f"({100 * jobs / total:.3g} %; {record['used_rows']:,} of their "
        f"{record['converged_rows']:,} converged rows used); {surrogate}"
    )


def trained_on_record(
    metrics: Mapping[str, Any],
    sweep: str,
    sweep_jobs: int,
    tables: Sequence[Mapping[str, Any]],
    arguments: Sequence[str],
) -> dict[str, Any]:
    """The record of an analysis (its ``metrics.json``) of a run of the sweep named
    ``sweep`` (``sweep_jobs`` jobs) built from the packed ``tables`` (each with its role,
    path, sha256, ...), with ``analyze``'s ``arguments``; `install` adds the files."""
    rows = metrics["rows"]
    sur = metrics.get("surrogate") or {}
    return {
        "format": SHIPPED_FORMAT,
        "sweep": sweep,
        "sweep_jobs": int(sweep_jobs),
        "jobs": int(rows["jobs"]),
        "converged_rows": int(rows["converged_rows"]),
        "used_rows": int(rows["used_rows"]),
        "used_rows_by_stage": rows.get("used_rows_by_stage"),
        "rows_note": (
            "used_rows: the converged rows with a positive stress the models read (reopened "
            "and repeated states left out as analyze does), split into training, validation "
            "and test rows"
        ),
        "tables": [dict(t) for t in tables],
        "splits": sorted(metrics.get("schemes", {})),
        "surrogate": sur.get("surrogate"),
        "calibration": sur.get("calibration"),
        "calibration_rows": sur.get("calibration_rows"),
        # Calibrated on several runs pooled: the coverage off the grid by cross-calibration.
        "off_grid_coverage": metrics.get("off_grid_cross_calibration"),
        "stress": metrics.get("stress"),
        "settings": metrics["settings"],
        "analyze_arguments": list(arguments),
        "trained_on": metrics.get("trained_on"),
        "woundsweep_version": metrics["woundsweep_version"],
        "xgboost_version": metrics.get("xgboost_version"),
    }


def install(analysis_dir: Path, record: Mapping[str, Any], dest: Path) -> list[Path]:
    """Copy the `model_files` of ``analysis_dir`` and ``record`` (with their sha256 as
    ``files``) into ``dest``, replacing it whole: written beside it, then swapped in by two
    renames (a reader sees the old set, none for an instant, or the new one, never a mix)."""
    files = model_files(analysis_dir)
    if not _splits(analysis_dir):
        raise AnalysisError(f"{analysis_dir}: no model_<split>.json to ship")
    dest.parent.mkdir(parents=True, exist_ok=True)
    stage = dest.with_name(f".{dest.name}.tmp-{os.getpid()}")
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    try:
        for f in files:
            shutil.copyfile(f, stage / f.name)
        full = {**record, "files": {f.name: file_sha256(stage / f.name) for f in files}}
        (stage / TRAINED_ON).write_bytes(json_bytes(full))
        read_record(stage)  # what predict will read: refuse to ship what it would refuse
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    old = dest.with_name(f".{dest.name}.old-{os.getpid()}")
    if dest.exists():
        os.rename(dest, old)
    os.rename(stage, dest)
    shutil.rmtree(old, ignore_errors=True)
    return sorted(dest.iterdir())

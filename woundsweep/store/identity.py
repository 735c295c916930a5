"""Result identity: the fingerprint of what determines a job's result, and file checksums.

``job_id`` names a job by its parameters only (`woundsweep.config.manifest.canonical_hash`), so it survives a
change of materials or settings. `result_fingerprint` is the sha256 of the canonical JSON of
everything that determines the job's numbers: its parameters (geometry, skin type,
orientation), the material values it uses (the subcutis and its own skin type's set, not just
the name), the stage and solver settings, the mesh law's version, the stress statistics' version and
the result format's version. A stored result whose fingerprint differs from the current sweep's is stale.
`file_sha256` is the content checksum of the fields and mesh files recorded with a result.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..config.manifest import JobRow
from ..config.sweep import GEOMETRY_KEYS, Sweep
from ..core.versions import (
    MESH_LAW_VERSION,
    RESULT_FORMAT_VERSION,
    STAGES_VERSION,
    STATISTICS_VERSION,
)

__all__ = [
    "file_sha256",
    "fingerprints",
    "result_fingerprint",
    "results_fingerprint",
    "settings_fingerprint",
]

_JOB_KEYS = (*GEOMETRY_KEYS, "orientation_deg", "skin_type")


def _plain(v: Any) -> Any:
    """JSON-ready value: numbers as floats (NaN as null), numpy scalars unwrapped."""
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):
        v = v.item()
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return v
    if isinstance(v, (int, float)):
        v = float(v)
        return None if math.isnan(v) else v
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return str(v)


def result_fingerprint(sweep: Sweep, job: JobRow | Mapping[str, Any]) -> str:
    """sha256 (64 hex digits) of the job's parameters and the settings its result depends on.

    ``job`` is a manifest row. The analysis settings and the sweep's name are not part of it.
    """
    settings = sweep.settings_dict()
    materials = settings["materials"]
    skin = str(job["skin_type"])
    doc = {
        "format": RESULT_FORMAT_VERSION,
        "mesh_law": MESH_LAW_VERSION,
        "statistics": STATISTICS_VERSION,
        "stages_model": STAGES_VERSION,
        "job": {k: _plain(job[k]) for k in _JOB_KEYS},  # type: ignore[literal-required]  # JobRow keys
        "materials": {
            "subcutis": _plain(materials["subcutis"]),
            "skin": _plain(materials["skin_types"].get(skin)),
        },
        "stages": _plain(settings["stages"]),
        "solver": _plain(settings["solver"]),
    }
    blob = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(blob.encode()).hexdigest()


def fingerprints(sweep: Sweep, manifest: Any) -> dict[str, str]:
    """``job_id -> result_fingerprint`` for every row of a manifest (a DataFrame)."""
    return {
        str(row["job_id"]): result_fingerprint(sweep, row) for row in manifest.to_dict("records")
    }


def _digest(pairs: Any) -> str:
    blob = json.dumps(sorted(pairs), separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()


def settings_fingerprint(sweep: Sweep, manifest: Any) -> str:
    """sha256 of every manifest job's id and `result_fingerprint`: what a run's results are
    computed from (another value once a sweep changes a job's settings, or its jobs)."""
    return _digest(fingerprints(sweep, manifest).items())


def results_fingerprint(frame: Any) -> str:
    """sha256 of the (job_id, result_fingerprint) pairs of a table of result rows (a
    DataFrame): which results, computed from what."""
    pairs = frame[["job_id", "result_fingerprint"]].drop_duplicates()
    return _digest((str(j), str(f)) for j, f in pairs.itertuples(index=False))


def file_sha256(path: str | Path, _memo: dict[tuple[str, int, int], str] | None = None) -> str:
    """sha256 of a file's bytes; ``_memo`` caches by (path, size, mtime) within one scan."""
    p = Path(path)
    key = None
    if _memo is not None:
        st = p.stat()
        key = (str(p), st.st_size, st.st_mtime_ns)
        if key in _memo:
            return _memo[key]
    h = hashlib.sha256()
    with open(p, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    digest = h.hexdigest()
    if _memo is not None and key is not None:
        _memo[key] = digest
    return digest

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

from ..config.manifest import JobRow, json_rows
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


def _settings_doc(sweep: Sweep, skin: str, settings: dict[str, Any] | None = None) -> dict:
    """Everything in a result's fingerprint but the job's own parameters (its skin's values)."""
    settings = settings if settings is not None else sweep.settings_dict()
    materials = settings["materials"]
    return {
        "format": RESULT_FORMAT_VERSION,
        "mesh_law": MESH_LAW_VERSION,
        "statistics": STATISTICS_VERSION,
        "stages_model": STAGES_VERSION,
        "materials": {
            "subcutis": _plain(materials["subcutis"]),
            "skin": _plain(materials["skin_types"].get(skin)),
        },
        "stages": _plain(settings["stages"]),
        "solver": _plain(settings["solver"]),
    }


def _blob(doc: Any) -> str:
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)


def result_fingerprint(sweep: Sweep, job: JobRow | Mapping[str, Any]) -> str:
    """sha256 (64 hex digits) of the job's parameters and the settings its result depends on.

    ``job`` is a manifest row. The analysis settings and the sweep's name are not part of it.
    """
    doc = _settings_doc(sweep, str(job["skin_type"]))
    doc["job"] = {k: _plain(job[k]) for k in _JOB_KEYS}  # type: ignore[literal-required]  # JobRow keys
    return hashlib.sha256(_blob(doc).encode()).hexdigest()


_SLOT = "\0job\0"  # where a job's parameters go in the canonical text of a settings doc


def fingerprints(sweep: Sweep, manifest: Any) -> dict[str, str]:
    """``job_id -> result_fingerprint`` for every row of a manifest (a DataFrame).

    The settings are serialised once per skin type, not once per job: the canonical text is
    the settings' text with each job's parameters put in their place (the same text, so the
    same fingerprint, as `result_fingerprint`)."""
    settings = sweep.settings_dict()
    frames: dict[str, tuple[str, str]] = {}
    jobs = json_rows(manifest, _JOB_KEYS, "null")
    if jobs is None:  # a value the column path does not encode: row by row
        jobs = [_blob({k: _plain(r[k]) for k in _JOB_KEYS}) for r in manifest.to_dict("records")]
    out: dict[str, str] = {}
    for job_id, skin, job in zip(manifest["job_id"].tolist(), manifest["skin_type"].tolist(), jobs):
        skin = str(skin)
        if skin not in frames:
            doc = _settings_doc(sweep, skin, settings)
            doc["job"] = _SLOT
            head, tail = _blob(doc).split(json.dumps(_SLOT), 1)
            frames[skin] = (head, tail)
        head, tail = frames[skin]
        out[str(job_id)] = hashlib.sha256((head + job + tail).encode()).hexdigest()
    return out


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

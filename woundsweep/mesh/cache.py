"""Per-run mesh cache: ``RUN_DIR/meshes/<mesh_id>.npz``, written atomically.

A mesh is named by its `GeometrySpec.mesh_id`, the hash of everything that determines it (the
geometric parameters, mesh size factor, closure zone, element degree and `MESH_LAW_VERSION`),
so the nine jobs of a geometry (skin types x orientations) share one file and a sweep with
another zone or element gets its own. A cached file is used only when it validates
completely: it opens, holds the five arrays with the right dtypes and consistent shapes, node
indices and tags are in range, the SHA-256 of the arrays matches the one stored beside them,
and it records the same mesh id, element degree and `GeometrySpec`. Anything else
(truncated, corrupt, stale) is rebuilt and replaced; the temporary file + ``os.replace``
write means readers never see a partial file.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..config.geometry import GeometrySpec
from ..config.solver import DEGREES
from ..core.errors import StoreError
from ..core.fsutil import NotRegularFile, atomic_write, open_regular
from ..core.layout import RunLayout
from ..core.schema import CELL_TAGS, FACET_TAGS, MeshData
from ..core.versions import MESH_CACHE_FORMAT, MESH_LAW_VERSION
from .build import build_mesh

__all__ = [
    "CachedMesh",
    "get_mesh",
    "load_mesh",
    "mesh_checksum",
    "mesh_path",
    "save_mesh",
]

_ID = re.compile(r"^[0-9a-f]{16}$")
# name -> (dtype, trailing shape)
_ARRAYS: dict[str, tuple[np.dtype, tuple[int, ...]]] = {
    "points": (np.dtype(np.float64), (3,)),
    "cells": (np.dtype(np.int64), (4,)),
    "cell_tags": (np.dtype(np.int32), ()),
    "facets": (np.dtype(np.int64), (3,)),
    "facet_tags": (np.dtype(np.int32), ()),
}


class CachedMesh(NamedTuple):
    """A mesh from the cache: ``status`` is ``cached``, ``built`` (no file) or ``rebuilt``."""

    mesh: MeshData
    path: Path
    status: str
    reason: str  # why a cached file was rejected ("" unless rebuilt)


def mesh_path(run_dir: str | Path, mesh_id: str) -> Path:
    """Cache file of a mesh (the id is a 16-hex `GeometrySpec.mesh_id`)."""
    if not isinstance(mesh_id, str) or not _ID.match(mesh_id):
        raise StoreError(f"mesh id {mesh_id!r} is not 16 lowercase hex characters")
    return RunLayout(run_dir).mesh_cache_file(mesh_id)


def mesh_checksum(mesh: MeshData) -> str:
    """SHA-256 over the arrays' names, dtypes, shapes and bytes."""
    digest = hashlib.sha256()
    for name in _ARRAYS:
        arr = np.ascontiguousarray(getattr(mesh, name))
        digest.update(f"{name}:{arr.dtype.str}:{arr.shape};".encode())
        digest.update(arr.tobytes())
    return digest.hexdigest()


def save_mesh(path: str | Path, mesh: MeshData, spec: GeometrySpec) -> None:
    """Write ``mesh`` atomically with its spec, mesh id, element degree, law version and
    checksum."""
    meta = {
        "format": MESH_CACHE_FORMAT,
        "mesh_law_version": MESH_LAW_VERSION,
        "mesh_id": spec.mesh_id,
        "element_degree": spec.element_degree,
        "spec": spec.to_dict(),
        "checksum": mesh_checksum(mesh),
        "info": mesh.info,
    }
    blob = np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)

    def _write(tmp: str) -> None:
        # A file object, not a name: np.savez would append ".npz" to the temporary name.
        with open(tmp, "wb") as fh:
            np.savez(fh, meta=blob, **{name: getattr(mesh, name) for name in _ARRAYS})

    atomic_write(path, _write)


def load_mesh(path: str | Path, spec: GeometrySpec | None = None) -> MeshData:
    """Read and validate a cached mesh (against ``spec`` when given); StoreError (one line, the
    reason) if it is unusable."""
    path = Path(path)
    try:  # a regular file only: a named pipe or a link to a device is not read (it would hang)
        with os.fdopen(open_regular(path), "rb") as fh, np.load(fh, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in (*_ARRAYS, "meta")}
    except FileNotFoundError:
        raise StoreError(f"{path}: no cached mesh") from None
    except NotRegularFile as err:
        raise StoreError(f"{path}: {err.strerror}") from None
    except Exception as err:  # zipfile/numpy raise many types for damaged files
        raise StoreError(f"{path}: unreadable ({type(err).__name__}: {err})") from None
    try:
        meta = json.loads(arrays.pop("meta").tobytes().decode())
    except (UnicodeDecodeError, ValueError) as err:
        raise StoreError(f"{path}: unreadable metadata ({err})") from None
    problem = _check(arrays, meta, spec)
    if problem:
        raise StoreError(f"{path}: {problem}")
    info = dict(meta["info"])
    return MeshData(info=info, **arrays)


def _check(arrays: dict[str, np.ndarray], meta: Any, spec: GeometrySpec | None) -> str:
    """The first reason the cached arrays cannot be used, or ''."""
    if not isinstance(meta, dict) or meta.get("format") != MESH_CACHE_FORMAT:
        return "unknown cache format"
    if meta.get("mesh_law_version") != MESH_LAW_VERSION:
        return f"built with mesh law {meta.get('mesh_law_version')}, now {MESH_LAW_VERSION}"
    degree = meta.get("element_degree")
    if degree not in DEGREES:
        return f"records no element degree of {DEGREES} ({degree!r})"
    if spec is not None:
        if degree != spec.element_degree:
            return f"built for P{degree} elements, not P{spec.element_degree}"
        if meta.get("mesh_id") != spec.mesh_id:
            return f"holds mesh {meta.get('mesh_id')}, not {spec.mesh_id}"
        if meta.get("spec") != json.loads(json.dumps(spec.to_dict())):
            return "built from other geometric parameters"
    for name, (dtype, tail) in _ARRAYS.items():
        arr = arrays[name]
        if arr.dtype != dtype or arr.shape[1:] != tail or arr.ndim != 1 + len(tail):
            return f"{name} has dtype {arr.dtype} and shape {arr.shape}"
    n, m, k = len(arrays["points"]), len(arrays["cells"]), len(arrays["facets"])
    if min(n, m, k) == 0:
        return "empty mesh"
    if len(arrays["cell_tags"]) != m or len(arrays["facet_tags"]) != k:
        return "tag arrays do not match the cells/facets"
    for name in ("cells", "facets"):
        if arrays[name].min() < 0 or arrays[name].max() >= n:
            return f"{name} refer to missing nodes"
    if not np.isin(arrays["cell_tags"], list(CELL_TAGS.values())).all():
        return "unknown cell tags"
    if not np.isin(arrays["facet_tags"], list(FACET_TAGS.values())).all():
        return "unknown facet tags"
    if not np.isfinite(arrays["points"]).all():
        return "non-finite coordinates"
    info = meta.get("info")
    if not isinstance(info, dict):
        return "missing mesh info"
    if info.get("element_degree") != degree:
        return f"its info records element degree {info.get('element_degree')!r}, not {degree}"
    if mesh_checksum(MeshData(info=info, **arrays)) != meta.get("checksum"):
        return "checksum mismatch"
    return ""


def get_mesh(run_dir: str | Path, spec: GeometrySpec) -> CachedMesh:
    """The mesh of ``spec``: the cached one (``meshes/<mesh_id>.npz``) if valid, else built
    (GeometryError) and cached."""
    path = mesh_path(run_dir, spec.mesh_id)
    reason = ""
    if os.path.lexists(path):
        try:
            return CachedMesh(load_mesh(path, spec), path, "cached", "")
        except StoreError as err:
            reason = str(err)
    mesh = build_mesh(spec)
    save_mesh(path, mesh, spec)
    return CachedMesh(mesh, path, "rebuilt" if reason else "built", reason)

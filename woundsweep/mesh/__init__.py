"""The mesh of one wound geometry (`woundsweep.config.geometry.GeometrySpec`): size law, gmsh build and the per-run cache.

`sizing` (the size law) is pure Python; `build` and `cache` import gmsh; `refine` (uniform refinement of a built mesh) is numpy. Names are
re-exported lazily, so importing this package costs nothing. Mesh tags live in
`woundsweep.core.schema`.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__ = [
    "PAPER_CELL_CAP",
    "SIZE_LAW",
    "CachedMesh",
    "MeshData",
    "build_mesh",
    "get_mesh",
    "load_mesh",
    "mesh_checksum",
    "mesh_path",
    "mesh_size_mm",
    "refine_uniform",
    "save_mesh",
]

_HOME = {
    "PAPER_CELL_CAP": "sizing",
    "SIZE_LAW": "sizing",
    "mesh_size_mm": "sizing",
    "MeshData": "build",
    "build_mesh": "build",
    "CachedMesh": "cache",
    "get_mesh": "cache",
    "load_mesh": "cache",
    "mesh_checksum": "cache",
    "mesh_path": "cache",
    "save_mesh": "cache",
    "refine_uniform": "refine",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

"""The mesh of one wound geometry: parameters, size law, gmsh build and the per-run cache.

`spec` (GeometrySpec, validation) and `sizing` (the size law) are pure Python; `build` and
`cache` import gmsh; `refine` (uniform refinement of a built mesh) is numpy. Names are
re-exported lazily, so importing this package costs nothing. Mesh tags live in
`woundsweep.schema`.
"""

from __future__ import annotations

from ..lazy import lazy_exports

__all__ = [
    "CACHE_FORMAT",
    "MESH_LAW_VERSION",
    "PAPER_CELL_CAP",
    "SHAPES",
    "SIZE_LAW",
    "CachedMesh",
    "GeometrySpec",
    "MeshData",
    "build_mesh",
    "get_mesh",
    "load_mesh",
    "mesh_checksum",
    "mesh_path",
    "mesh_size_mm",
    "refine_uniform",
    "save_mesh",
    "wound_distance_mm",
]

_HOME = {
    "SHAPES": "spec",
    "GeometrySpec": "spec",
    "wound_distance_mm": "spec",
    "MESH_LAW_VERSION": "sizing",
    "PAPER_CELL_CAP": "sizing",
    "SIZE_LAW": "sizing",
    "mesh_size_mm": "sizing",
    "MeshData": "build",
    "build_mesh": "build",
    "CACHE_FORMAT": "cache",
    "CachedMesh": "cache",
    "get_mesh": "cache",
    "load_mesh": "cache",
    "mesh_checksum": "cache",
    "mesh_path": "cache",
    "save_mesh": "cache",
    "refine_uniform": "refine",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

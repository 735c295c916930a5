"""The mesh of one wound geometry (`woundsweep.config.geometry.GeometrySpec`): size law, gmsh build and the per-run cache.

`sizing` (the size law) is pure Python; `build` and `cache` import gmsh; `refine` (uniform refinement of a built mesh) is numpy. Names are
re-exported lazily, so importing this package costs nothing. Mesh tags live in
`woundsweep.core.schema`.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "sizing": ("PAPER_CELL_CAP", "SIZE_LAW", "mesh_size_mm"),
        "build": ("MeshData", "build_mesh", "edge_length_near_mm"),
        "cache": ("CachedMesh", "get_mesh", "load_mesh", "mesh_checksum", "mesh_path", "save_mesh"),
        "refine": ("refine_uniform",),
    },
)

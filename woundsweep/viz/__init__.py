"""Results to look at: ParaView series (`export`), the 3D view of a job (`view`) and the
static atlas site of a run (`atlas`), from the store alone (no DOLFINx).

Modules: `jobdata` (a stored job's mesh, tags and fields), `surface` (closure zone, exterior
surface, the maximum), `export` (VTU + PVD via meshio), `html` (page pieces, packaged
assets), `view` (the viewer's data and page; plotly.js), `atlas` (the site). Names are
re-exported lazily.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__ = [
    "AtlasSummary",
    "JobFields",
    "build_atlas",
    "closure_zone_facets",
    "export_job",
    "load_job",
    "open_job",
    "view_data",
    "view_page",
]

_HOME = {
    "AtlasSummary": "atlas",
    "build_atlas": "atlas",
    "JobFields": "jobdata",
    "load_job": "jobdata",
    "open_job": "jobdata",
    "closure_zone_facets": "surface",
    "export_job": "export",
    "view_data": "view",
    "view_page": "view",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOME)

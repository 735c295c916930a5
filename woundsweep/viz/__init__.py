"""Results to look at: ParaView series (`export`), the 3D view of a job (`view`) and the
static atlas site of a run (`atlas`), from the store alone (no DOLFINx).

Modules: `jobdata` (a stored job's mesh, tags and fields), `surface` (closure zone, exterior
surface, the maximum), `export` (VTU + PVD via meshio), `html` (page pieces, packaged
assets), `view` (the viewer's data and page; plotly.js), `atlas` (the site). Names are
re-exported lazily.
"""

from __future__ import annotations

from ..core.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "atlas": ("AtlasSummary", "build_atlas"),
        "jobdata": ("JobFields", "load_job", "open_job"),
        "surface": ("closure_zone_facets",),
        "export": ("export_job",),
        "view": ("view_data", "view_page"),
    },
)

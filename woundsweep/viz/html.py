"""HTML pieces shared by the view and the atlas: escaping, numbers, tables, the page shell,
and the packaged assets (`ASSETS`: the viewer's and the index's JavaScript, the style sheet).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from html import escape
from importlib import resources
from typing import Any

__all__ = [
    "CELL_MEAN_MAX",
    "JOB_COLUMNS",
    "STRESS_LABELS",
    "STAGE_COLUMNS",
    "asset",
    "fmt",
    "json_script",
    "page",
    "plotly_js",
    "table",
]

# The three von Mises numbers of a stage, each with one name wherever it is shown (the store's
# names for the first two) and what it is.
CELL_MEAN_MAX = "max_cell_mean_von_mises_kPa"
STRESS_LABELS: dict[str, str] = {
    "p99_von_mises_kPa": "p99 of the volume: the volume-weighted 99th percentile of the "
    "solver's samples (the paper's maximal stress)",
    "max_von_mises_kPa": "largest sample: the largest von Mises at one of the solver's sample "
    "points (P2: 14 per cell)",
    CELL_MEAN_MAX: "largest cell mean: the largest of the stored cell means (what the 3D "
    "view and the export colour)",
}
# The per-stage table of a job: (column, header); units are in the names.
STAGE_COLUMNS: tuple[tuple[str, str], ...] = (
    ("stage", "stage"),
    ("stage_name", "name"),
    ("status", "status"),
    ("field", "field"),
    ("newton_iterations", "Newton its"),
    ("p99_von_mises_kPa", "p99_von_mises_kPa (p99 of the volume)"),
    ("max_von_mises_kPa", "max_von_mises_kPa (largest sample)"),
    ("max_location_x_mm", "max_x_mm"),
    ("max_location_y_mm", "max_y_mm"),
    ("max_location_z_mm", "max_z_mm"),
    ("closure_gap_max_mm", "closure_gap_max_mm"),
    ("closed", "closed"),
    ("min_J", "min_J"),
    ("contact_force_mN", "contact_force_mN"),
    ("max_penetration_mm", "max_penetration_mm"),
    ("time_s", "time_s"),
)
# What a job page lists besides the manifest's parameters.
JOB_COLUMNS = (
    "failure_class",
    "failed_stage",
    "failure_detail",
    "attempts",
    "exit_code",
    "job_wall_time_s",
    "total_cpu_time_s",
    "max_rss_MiB",
    "host",
    "stages_requested",
    "fields",
    "dolfinx_version",
    "woundsweep_version",
)


def fmt(value: Any) -> str:
    """A table cell: 4 significant digits for floats, '-' for missing values."""
    if value is None:
        return "-"
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        if value != 0 and (abs(value) >= 1e5 or abs(value) < 1e-3):
            return f"{value:.3e}"
        return f"{value:.4g}"
    text = str(value)
    return text if text not in ("nan", "NaT", "None", "<NA>") else "-"


def table(headers: Sequence[str], rows: Iterable[Sequence[Any]], cls: str = "") -> str:
    """An HTML table; cells are formatted with `fmt` and escaped."""
    head = "".join(f"<th>{escape(h)}</th>" for h in headers)
    body = "".join(
        "<tr>" + "".join(f"<td>{escape(fmt(v))}</td>" for v in row) + "</tr>\n" for row in rows
    )
    c = f' class="{escape(cls)}"' if cls else ""
    return f"<table{c}><thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody></table>\n"


def json_script(element_id: str, data: Any) -> str:
    """Data for the page's JavaScript, safe inside a <script> element."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return f'<script type="application/json" id="{element_id}">{text}</script>\n'


def asset(name: str) -> str:
    """The text of a packaged asset (``woundsweep/viz/assets/<name>``)."""
    # Traversable.joinpath takes several parts from Python 3.11 on (typeshed's 3.10 stub: one);
    # on 3.10 files() of a package directory is a pathlib.Path, which takes several too.
    files = resources.files("woundsweep.viz")
    return files.joinpath("assets", name).read_text("utf-8")  # type: ignore[call-arg]


def plotly_js() -> str:
    """plotly.js as shipped by the plotly package (about 4.8 MB minified)."""
    from plotly.offline import get_plotlyjs

    return get_plotlyjs()


def page(title: str, body: str, head: str = "", css_href: str | None = None) -> str:
    """A whole HTML page; the style sheet inline, or linked when ``css_href`` is given."""
    style = (
        f'<link rel="stylesheet" href="{escape(css_href)}">'
        if css_href
        else f"<style>\n{asset('style.css')}</style>"
    )
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{escape(title)}</title>\n{style}\n{head}</head>\n<body>\n{body}</body>\n</html>\n"
    )

"""The 3D view of one job: the deformed exterior surface coloured by the cellwise von Mises
stress (kPa), one entry per requested stage, the closure zone outlined and the maximum marked.

`view_data` turns a `JobFields` into the viewer's data (arrays as base64 little-endian
float32 / int32, decoded by ``assets/viewer.js``), optionally with extra lines per stage
(`LineTrace`: threads, outlines; they move with the deformation scale); `job_body` is the HTML
of a job (view, stage table, parameters) shared by ``woundsweep view`` and the atlas' job
pages; `view_page` is the self-contained page of ``woundsweep view`` (plotly.js and the viewer
inlined), `fields_page` the same view of fields that are no job's (``woundsweep case --view``).
"""

from __future__ import annotations

import base64
import math
from collections.abc import Mapping, Sequence
from html import escape
from typing import Any, NamedTuple

import numpy as np

from ..config.manifest import JobRow
from ..config.solver import element_name
from ..config.sweep import MANIFEST_COLUMNS
from ..core.schema import STAGE_NAMES
from .html import (
    CELL_MEAN_MAX,
    JOB_COLUMNS,
    STAGE_COLUMNS,
    STRESS_LABELS,
    asset,
    json_script,
    page,
    plotly_js,
    table,
)
from .jobdata import JobFields, StageNote, records
from .surface import max_cell_point, plane_slice, surface_of, zone_outline

__all__ = ["LineTrace", "fields_page", "job_body", "stage_rows", "view_data", "view_page"]


class LineTrace(NamedTuple):
    """An extra line of the 3D view: polylines in the reference configuration (mm; a NaN row
    ends one and starts the next), each point moved by its ``displacement`` times the view's
    deformation scale. Traces of one ``group`` share one legend entry; ``name`` is the hover
    text."""

    name: str
    points: np.ndarray  # (p, 3) reference mm
    displacement: np.ndarray  # (p, 3) mm
    color: str = "black"
    width: float = 4.0
    group: str = ""


def _b64(a: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _closure_lines(jf: JobFields, k: int) -> dict[str, Any] | None:
    """A stage's line loads along the wound (mN/mm at y, mm), or None where not stored."""
    lines = jf.closure_lines.get(k)
    if not lines:
        return None
    return {name: [_num(v) for v in values] for name, values in lines.items()}


def _profile_lines(jf: JobFields, k: int) -> list[dict[str, Any]]:
    """A stage's stored profile lines: name, running length from the first point (mm), von
    Mises (kPa, null where a point is outside the mesh)."""
    out = []
    for name, line in jf.profiles.get(k, {}).items():
        pts = np.asarray(line["points_mm"], float)
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
        out.append(
            {
                "name": name,
                "s_mm": [round(float(v), 5) for v in s],
                "von_mises_kPa": [_num(v) for v in np.asarray(line["von_mises_kPa"], float)],
                "start_mm": [round(float(c), 4) for c in pts[0]],
                "end_mm": [round(float(c), 4) for c in pts[-1]],
            }
        )
    return out


def _coords(a: np.ndarray) -> list[float | None]:
    return [None if not math.isfinite(v) else round(float(v), 5) for v in np.asarray(a, float)]


def _trace(t: LineTrace) -> dict[str, Any]:
    """A `LineTrace` as the viewer reads it: coordinates and displacements as lists, null
    where a line breaks."""
    p, u = np.asarray(t.points, float), np.asarray(t.displacement, float)
    if p.shape != u.shape or p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"trace {t.name!r}: points {p.shape} and displacement {u.shape}")
    u = np.where(np.isfinite(p), u, np.nan)
    axes = {c: _coords(p[:, i]) for i, c in enumerate("xyz")}
    moves = {f"u{c}": _coords(u[:, i]) for i, c in enumerate("xyz")}
    return {"name": t.name, "group": t.group, "color": t.color, "width": t.width,
            **axes, **moves}  # fmt: skip


def view_data(
    jf: JobFields,
    traces: Mapping[int, Sequence[LineTrace]] | None = None,
    labels: Mapping[int, str] | None = None,
    title: str | None = None,
    initial: int | None = None,
    camera: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The viewer's data: the surface and the mid-section cut once, then per requested stage
    its fields (surface, cut, profile lines) or a reason. ``traces``: extra lines per stage;
    ``labels``: the stages' names in the selector (default "stage k: ..."); ``title``: the
    plot's title before the stage's name (default "job N"); ``initial``: the stage shown
    first (default the last stored); ``camera``: plotly's scene camera at first (default an
    oblique view of the whole patch)."""
    traces = traces or {}
    labels = labels or {}
    s = surface_of(jf.points, jf.cells, jf.facets, jf.zone)
    ref = jf.points[s.nodes]
    lo, hi = jf.points.min(axis=0), jf.points.max(axis=0)
    y_mid = 0.5 * float(lo[1] + hi[1])
    cut = plane_slice(jf.points, jf.cells, 1, y_mid)
    cut_nodes, cut_edges = np.unique(np.r_[cut.edge_a, cut.edge_b], return_inverse=True)
    n_edges = len(cut.edge_a)
    p99 = {int(r["stage"]): _num(r.get("p99_von_mises_kPa")) for r in jf.rows}
    largest_sample = {int(r["stage"]): _num(r.get("max_von_mises_kPa")) for r in jf.rows}
    stages = []
    for note in jf.notes:
        k = note.stage
        entry: dict[str, Any] = {
            "stage": k,
            "label": labels.get(k, f"stage {k}: {STAGE_NAMES.get(k, '')}"),
            "status": note.status,
            "stored": note.stored,
            "reason": note.reason,
            "p99_von_mises_kPa": p99.get(k),
            "max_von_mises_kPa": largest_sample.get(k),
        }
        if note.stored:
            u, vm = jf.fields[k]
            tri_vm = np.asarray(vm, np.float64)[s.owner]
            cell, mref, mdef = max_cell_point(jf.points, jf.cells, u, vm)
            entry.update(
                u=_b64(np.asarray(u)[s.nodes], "<f4"),
                vm=_b64(tri_vm, "<f4"),
                cut_u=_b64(np.asarray(u)[cut_nodes], "<f4"),
                cut_vm=_b64(np.asarray(vm, np.float64)[cut.owner], "<f4"),
                lines=_profile_lines(jf, k),
                closure=_closure_lines(jf, k),
                traces=[_trace(t) for t in traces.get(k, ())],
                surface_max_kPa=float(np.nanmax(tri_vm)),
                **{CELL_MEAN_MAX: float(vm[cell])},
                max={
                    "value_kPa": float(vm[cell]),
                    "cell": cell,
                    "reference_mm": [float(c) for c in mref],
                    "deformed_mm": [float(c) for c in mdef],
                },
            )
        stages.append(entry)
    return {
        "job_index": int(jf.job["job_index"]),
        "job_id": str(jf.job["job_id"]),
        "n_nodes": int(len(s.nodes)),
        "n_triangles": int(len(s.triangles)),
        "x": _b64(ref[:, 0], "<f4"),
        "y": _b64(ref[:, 1], "<f4"),
        "z": _b64(ref[:, 2], "<f4"),
        "tri": _b64(s.triangles, "<i4"),
        "outline": _b64(zone_outline(s.triangles, s.zone), "<i4"),
        "element": element_name(jf.element_degree) if jf.element_degree is not None else "",
        "cut": {
            "y_mm": y_mid,
            "x": _b64(jf.points[cut_nodes, 0], "<f4"),
            "y": _b64(jf.points[cut_nodes, 1], "<f4"),
            "z": _b64(jf.points[cut_nodes, 2], "<f4"),
            "a": _b64(cut_edges[:n_edges], "<i4"),
            "b": _b64(cut_edges[n_edges:], "<i4"),
            "t": _b64(cut.edge_t, "<f4"),
            "tri": _b64(cut.triangles, "<i4"),
            "n_triangles": int(len(cut.triangles)),
        },
        "stages": stages,
        "title": title,
        "initial": initial,
        "camera": camera,
    }


def stage_rows(rows: list[dict[str, Any]], notes: list[StageNote] | None) -> list[list[Any]]:
    """The stage table's rows (`STAGE_COLUMNS`); ``field`` says stored or why not."""
    by_stage = {n.stage: n for n in notes or []}
    out = []
    for r in records(rows):
        k = int(r["stage"])
        note = by_stage.get(k)
        field = "-" if note is None else ("stored" if note.stored else note.reason)
        extra = {"stage_name": STAGE_NAMES.get(k, ""), "field": field}
        out.append([extra[c] if c in extra else r.get(c) for c, _ in STAGE_COLUMNS])
    return out


def _param_table(job: JobRow, rows: list[dict[str, Any]]) -> str:
    items = [(c, job.get(c)) for c in MANIFEST_COLUMNS]
    items += [(c, rows[0].get(c)) for c in JOB_COLUMNS if rows]
    return table(["parameter", "value"], items, "params")


def job_body(
    job: JobRow,
    rows: list[dict[str, Any]],
    jf: JobFields | None,
    *,
    view_note: str = "",
    header: str = "",
    footer: str = "",
    element: str = "",
) -> str:
    """A job's HTML: title (with the run's ``element``), the 3D view and the profile lines
    (with ``jf``) or ``view_note``, stages, parameters."""
    idx, fc = int(job["job_index"]), rows[0]["failure_class"] if rows else "not run"
    if jf is not None and jf.element_degree is not None:
        element = element_name(jf.element_degree)
    elem = f" &middot; element {escape(element)}" if element else ""
    title = (
        f"<h1>job {idx} <small>{escape(str(job['job_id']))} &middot; {escape(str(fc))}"
        f"{elem}</small></h1>\n"
    )
    notes = jf.notes if jf is not None else None
    if jf is not None:
        view = _view_block(view_data(jf), _JOB_LEGEND)
    else:
        view = f'<p class="noview">{escape(view_note)}</p>\n'
    return (
        header
        + title
        + view
        + "<h2>Stages</h2>\n"
        + '<div class="tablewrap">'
        + table([h for _, h in STAGE_COLUMNS], stage_rows(rows, notes), "stages")
        + "</div>\n<h2>Parameters</h2>\n"
        + _param_table(job, rows)
        + footer
    )


def _view_block(data: dict[str, Any], legend: str) -> str:
    """The view's controls, plot, side plots, ``legend`` (HTML) and data (``#wsdata``)."""
    return (
        '<div class="controls"><label>stage <select id="stage"></select></label>'
        '<label>deformation &times; <input type="number" id="scale" value="1" min="0" '
        'max="20" step="0.5"></label>'
        '<label><input type="checkbox" id="cut"> cut at the wound\'s mid-section</label>'
        '<label><input type="checkbox" id="fullrange"> colour scale to the maximum</label>'
        '<label><input type="checkbox" id="seethrough"> see-through surface</label>'
        '<span id="note"></span></div>\n'
        '<div class="views"><div id="plot"></div>'
        '<div class="side"><div id="lines"></div><div id="closure"></div></div></div>\n'
        + f'<p class="legend">{legend}</p>\n'
        + json_script("wsdata", data)
    )


_JOB_LEGEND = (
    "Left: the deformed exterior surface (displacement times the "
    "deformation scale), each triangle coloured by the von Mises stress of the "
    "tetrahedron it bounds (its cell mean); the colour scale ends at the stage's p99 "
    "of the volume and the cells above it are shaded from pale to deep magenta up to "
    "the largest cell mean (the colour bar's top band); the cut shows the half y &ge; "
    "the wound's mid-section and the cut face; black outline: the closure zone; red "
    "diamond: the cell of the largest cell mean (deformed midpoint). Right: von Mises "
    "along the stored profile lines (reference configuration); below it the closing "
    "force per unit length along the wound (the load that holds the sutured zone shut: "
    "where the sutures work hardest) and the flanks' contact force per unit length. "
    "Lengths in mm, stresses in kPa, line loads in mN/mm. The stage's three von Mises "
    "numbers: " + "; ".join(escape(text) for text in STRESS_LABELS.values()) + "."
)


def view_page(jf: JobFields) -> str:
    """The self-contained HTML of ``woundsweep view``: no network needed to open it."""
    body = job_body(jf.job, jf.rows, jf) + f"<script>\n{asset('viewer.js')}</script>\n"
    head = f"<script>\n{plotly_js()}\n</script>\n"
    return page(f"woundsweep job {int(jf.job['job_index'])}", body, head)


def fields_page(
    jf: JobFields,
    title: str,
    *,
    traces: Mapping[int, Sequence[LineTrace]] | None = None,
    labels: Mapping[int, str] | None = None,
    legend: str = "",
    before: str = "",
    after: str = "",
    initial: int | None = None,
    camera: dict[str, Any] | None = None,
) -> str:
    """A self-contained page of the 3D view of ``jf`` (`view_data` with ``traces``,
    ``labels``, ``initial`` and ``camera``; the plot titled by the stage's label) without a
    job's tables: ``title`` (text) as heading, ``before`` and ``after`` (HTML) around the
    view, ``legend`` (HTML) under it."""
    data = view_data(jf, traces, labels, "", initial, camera)
    body = (
        f"<h1>{escape(title)}</h1>\n"
        + before
        + _view_block(data, legend)
        + after
        + f"<script>\n{asset('viewer.js')}</script>\n"
    )
    return page(title, body, f"<script>\n{plotly_js()}\n</script>\n")

"""The atlas: a static site of a run directory that opens from disk.

Layout of ``OUT/``::

    index.html             every job of the manifest: parameters, failure class, failed and
                           converged stages, p99 per stage (inline JSON; sorted, filtered
                           and drawn a page of 50-1,000 rows at a time by assets/index.js)
    jobs/job-<index>.html  per job: stage table, parameters, its log (the last LOG_BYTES) and,
                           for the jobs chosen by ``views``, its 3D view
    analysis/index.html    RUN_DIR/analysis/'s report and figures, when they exist
    assets/                the one copy of plotly.js, viewer.js, index.js and style.css

Pages link the shared assets relatively, so the site can be moved or zipped whole. The build
reads each fields file once and holds one geometry's mesh at a time; its time and size grow
linearly with the jobs (and the views' surfaces).
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable
from html import escape
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import pandas as pd

from ..config.manifest import Run
from ..config.solver import element_name
from ..config.sweep import GEOMETRY_KEYS
from ..core.errors import StoreError
from ..core.fsutil import read_tail
from ..core.layout import ANALYSIS_METRICS
from ..core.schema import STAGES, StageStatus
from ..store.reader import rows_element_degree
from .html import asset, json_script, page, plotly_js
from .jobdata import load_job
from .view import job_body

__all__ = ["LOG_BYTES", "AtlasSummary", "build_atlas", "log_html", "parse_views"]

LOG_BYTES = 64 * 1024
_INDEX_PARAMS = (
    *GEOMETRY_KEYS,
    "orientation_deg",
    "skin_type",
    "wound_width_mm",
    "wound_depth_mm",
    "wound_length_mm",
)
_ASSETS = ("viewer.js", "index.js", "style.css")


class AtlasSummary(NamedTuple):
    """What a build wrote: counts, bytes (all, of the views, of plotly.js) and seconds."""

    index: Path  # type: ignore[assignment]  # shadows tuple.index (never called on it)
    jobs: int
    views: int
    total_bytes: int
    view_bytes: int
    plotly_bytes: int
    seconds: float


def parse_views(spec: str, job_indices: list[int]) -> set[int]:
    """``all``, ``none`` or job indices and ranges (``0-9,15``) -> the jobs to draw in 3D."""
    text = spec.strip().lower()
    if text == "all":
        return set(job_indices)
    if text == "none":
        return set()
    have, chosen = set(job_indices), set()
    for part in text.split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            a, b = int(lo), int(hi) if sep else int(lo)
        except ValueError:
            raise StoreError(
                f"--views {spec!r}: expected all, none or job indices like 0-9,15"
            ) from None
        for end in (a, b):  # before the range is built: 0-99999999999999999 is refused
            if end not in have:
                raise StoreError(f"--views {spec!r}: no job {end} in the run")
        if a > b:
            raise StoreError(f"--views {spec!r}: the range {a}-{b} is empty (low-high)")
        chosen |= set(range(a, b + 1))
    missing = sorted(chosen - have)
    if missing:
        raise StoreError(f"--views {spec!r}: no job {missing[0]} in the run")
    return chosen


def _write(path: Path, text: str) -> int:
    """Write a page whole (a temporary name, then a rename); no fsync: the site is derived
    from the run and rebuilt at will, and two fsyncs per page would dominate the build."""
    data = text.encode("utf-8")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except OSError as err:  # a full disk, `ulimit -f`: no temporary left, the page named
        tmp.unlink(missing_ok=True)
        raise OSError(err.errno, err.strerror, str(path)) from None
    return len(data)


def log_html(path: Path) -> str:
    """A job log's page block: its path and its last `LOG_BYTES`, escaped."""
    if not os.path.lexists(path):
        return '<p class="noview">no log</p>\n'
    try:  # a regular file only: a named pipe or a link there is not read
        size, tail = read_tail(path, LOG_BYTES)
    except OSError as err:
        return f'<p class="noview">log not shown: {escape(str(path))}: {escape(str(err.strerror))}</p>\n'
    text = tail.decode("utf-8", "replace")
    cut = (
        f"(the last {LOG_BYTES / 1024:.0f} KiB of {size / 1024:.0f} KiB) "
        if size > LOG_BYTES
        else ""
    )
    return (
        f'<p class="legend">{cut}{escape(str(path))}</p>\n<pre class="log">{escape(text)}</pre>\n'
    )


def _index_table(manifest: pd.DataFrame, results: pd.DataFrame, views: set[int]) -> dict[str, Any]:
    """Columns and rows of the index: one row per manifest job, stored or not."""
    p99 = results.pivot_table(
        index="job_index", columns="stage", values="p99_von_mises_kPa", aggfunc="first"
    )
    jobs = results.drop_duplicates("job_index").set_index("job_index")
    ok = results["status"] == StageStatus.CONVERGED
    converged = ok.groupby(results["job_index"]).sum()
    # Converged stages whose sutured zone has reopened (docs/model.md, "Closure measures").
    closed = results["closed"] if "closed" in results else pd.Series(np.nan, index=results.index)
    reopened = (
        (ok & (pd.to_numeric(closed, errors="coerce") == 0)).groupby(results["job_index"]).sum()
    )
    # The job, its outcome and the p99 per stage first, so that they fit 1,280 px; then the
    # parameters (the job column stays in view when the table scrolls sideways).
    cols = [("job_index", "job", "num"), ("failure_class", "failure_class", "str")]
    cols += [(f"p99_s{k}", f"p99 kPa s{k}", "num") for k in STAGES]
    cols += [("failed_stage", "failed_stage", "num"), ("converged_stages", "converged", "num")]
    cols += [("reopened_stages", "reopened", "num")]
    cols += [
        (c, c, "num" if pd.api.types.is_numeric_dtype(manifest[c]) else "str")
        for c in _INDEX_PARAMS
    ]
    cols += [("view", "3D", "str")]
    rows = []
    for job in manifest.sort_values("job_index").itertuples(index=False):
        j = int(job.job_index)
        stored = j in jobs.index
        row: list[Any] = [j, str(jobs.at[j, "failure_class"]) if stored else "pending"]
        for k in STAGES:
            row.append(_cell(p99.at[j, k]) if j in p99.index and k in p99.columns else None)
        row.append(_cell(jobs.at[j, "failed_stage"]) if stored else None)
        # Counts (sums of booleans); `.at` is any Scalar to pandas-stubs.
        row.append(int(cast(int, converged.at[j])) if stored else None)
        row.append(int(cast(int, reopened.at[j])) if stored else None)
        row += [_cell(getattr(job, c)) for c in _INDEX_PARAMS]
        row.append("yes" if j in views else "")
        rows.append(row)
    return {"columns": [{"key": k, "label": h, "type": t} for k, h, t in cols], "rows": rows}


def _int(v: Any) -> int:
    try:
        return 0 if v is None or v != v else int(v)
    except (TypeError, ValueError):
        return 0


def _cell(v: Any) -> Any:
    if v is None:
        return None
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return None if not np.isfinite(f) else float(f"{f:.6g}")
    if isinstance(v, (int, np.integer)):
        return int(v)
    return None if pd.isna(v) else str(v)


def _nav(idx: int, prev: int | None, nxt: int | None, has_analysis: bool) -> str:
    links = ['<a href="../index.html">index</a>']
    if has_analysis:
        links.append('<a href="../analysis/index.html">analysis</a>')
    if prev is not None:
        links.append(f'<a href="job-{prev}.html">&larr; job {prev}</a>')
    if nxt is not None:
        links.append(f'<a href="job-{nxt}.html">job {nxt} &rarr;</a>')
    return "<nav>" + "".join(links) + "</nav>\n"


def _analysis(run: Run, out: Path) -> int:
    """Copy the analysis' figures and render its report; bytes written (0 if none)."""
    src = run.layout.analysis_dir
    if not src.is_dir():
        return 0
    dst = out / "analysis"
    dst.mkdir(parents=True, exist_ok=True)
    total = 0
    figures = sorted(p for p in src.iterdir() if p.suffix in (".png", ".svg"))
    for p in figures + sorted(src.glob(ANALYSIS_METRICS)):
        shutil.copyfile(p, dst / p.name)
        total += p.stat().st_size
    body = '<nav><a href="../index.html">index</a></nav>\n'
    report = run.layout.analysis_report
    if not report.exists():
        body += "<h1>Analysis</h1>\n"
    else:
        from markdown_it import MarkdownIt

        body += MarkdownIt("commonmark").enable("table").render(report.read_text("utf-8"))
    body += "<h2>Figures</h2>\n" + "".join(
        f'<a href="{escape(p.name)}"><img class="figure" src="{escape(p.name)}" alt="{escape(p.stem)}"></a>\n'
        for p in figures
        if p.suffix == ".png"
    )
    body += (
        "<p>"
        + ", ".join(
            f'<a href="{escape(p.name)}">{escape(p.name)}</a>' for p in sorted(dst.glob("*.json"))
        )
        + "</p>\n"
    )
    return total + _write(
        dst / "index.html", page("woundsweep analysis", body, css_href="../assets/style.css")
    )


def build_atlas(
    run: Run,
    results: pd.DataFrame,
    out: str | Path,
    views: set[int],
    progress: Callable[[int, dict[str, Any]], None] | None = None,
) -> AtlasSummary:
    """Write the site of ``run`` (a `sweep.grid.Run`) with its validated ``results`` to ``out``.

    ``progress(n, info)`` is called after each job page (``info``: bytes of the views so
    far, views drawn, cells of the drawn views and of all chosen views).
    """
    t0 = time.perf_counter()
    out = Path(out)
    (out / "jobs").mkdir(parents=True, exist_ok=True)
    (out / "assets").mkdir(parents=True, exist_ok=True)
    total = sum(_write(out / "assets" / name, asset(name)) for name in _ASSETS)
    plotly_bytes = _write(out / "assets" / "plotly.min.js", plotly_js()) if views else 0
    total += plotly_bytes + _analysis(run, out)
    has_analysis = (out / "analysis" / "index.html").exists()
    man = run.manifest.sort_values(["geometry_id", "job_index"])
    order = sorted(int(j) for j in man["job_index"])
    where = {j: i for i, j in enumerate(order)}
    by_job: dict[int, list[dict[str, Any]]] = {}
    for r in results.sort_values(["job_index", "stage"]).to_dict("records"):
        by_job.setdefault(int(r["job_index"]), []).append(r)
    cells = {j: max((_int(r["cells"]) for r in rs), default=0) for j, rs in by_job.items()}
    info = {
        "view_bytes": 0,
        "views": 0,
        "cells_done": 0,
        "cells_total": sum(cells.get(j, 0) for j in views),
    }
    cache: dict[Any, Any] = {}
    drawn: set[int] = set()
    degree = rows_element_degree(results[results["job_id"].isin(set(run.manifest["job_id"]))])
    element = element_name(degree) if degree is not None else ""
    head = '<script src="../assets/plotly.min.js"></script>\n'
    for n, job in enumerate(man.to_dict("records"), 1):
        j = int(job["job_index"])
        rows = by_job.get(j, [])
        pos = where[j]
        prev = order[pos - 1] if pos else None
        nxt = order[pos + 1] if pos + 1 < len(order) else None
        jf, note = None, "3D view not built (woundsweep atlas --views selects the jobs)"
        if not rows:
            note = "no result stored yet"
        elif not rows[0]["fields_file"]:
            note = (
                f"no stored fields (`run --fields {rows[0]['fields']}`, {rows[0]['failure_class']})"
            )
        elif j in views:
            jf = load_job(run, job, rows, cache)
        footer = "<h2>Log</h2>\n" + log_html(run.layout.log_file(str(job["job_id"])))
        body = job_body(
            job, rows, jf, view_note=note, header=_nav(j, prev, nxt, has_analysis), footer=footer,
            element=element,
        )  # fmt: skip
        if jf is not None:
            body += '<script src="../assets/viewer.js"></script>\n'
        size = _write(
            out / "jobs" / f"job-{j}.html",
            page(
                f"woundsweep job {j}", body, head if jf is not None else "", "../assets/style.css"
            ),
        )
        total += size
        if jf is not None:
            drawn.add(j)
            info["view_bytes"] += size
            info["views"] += 1
            info["cells_done"] += cells.get(j, 0)
        if progress is not None:
            progress(n, info)
    data = _index_table(run.manifest, results, drawn)
    body = (
        f"<h1>woundsweep atlas <small>{escape(run.run_dir.name)} &middot; "
        f"{len(order):,} jobs"
        + (f" &middot; element {escape(element)}" if element else "")
        + "</small></h1>\n"
        + (
            '<nav><a href="analysis/index.html">analysis: report and figures</a></nav>\n'
            if has_analysis
            else ""
        )
        + '<p class="legend">Click a header to sort; type in the boxes to filter (text: substring; '
        "numbers: 2, &gt;1, &lt;=0.5 or 1..2; - for missing); the rows are shown a page at a "
        "time. Units are in the column names; "
        "&ldquo;p99 kPa s<i>k</i>&rdquo; is stage <i>k</i>&rsquo;s p99_von_mises_kPa, the p99 of "
        "the volume (the volume-weighted 99th percentile of von Mises). "
        f"Built {escape(time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()))} from {escape(str(run.run_dir))}; "
        f"{results['job_index'].nunique():,} jobs stored.</p>\n"
        '<div class="pager" id="pager"></div>\n'
        '<div class="tablewrap"><table id="index"></table></div>\n'
        '<div class="pager" id="pager-bottom"></div>\n'
        + json_script("atlasdata", data)
        + '<script src="assets/index.js"></script>\n'
    )
    index = out / "index.html"
    total += _write(index, page("woundsweep atlas", body, css_href="assets/style.css"))
    return AtlasSummary(
        index, len(order), info["views"], total, info["view_bytes"], plotly_bytes,
        time.perf_counter() - t0,
    )  # fmt: skip

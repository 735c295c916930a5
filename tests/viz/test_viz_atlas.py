"""The atlas site and the view file without a browser: what the pages hold, the index data
against the store, the choice of 3D views, the analysis pages, bounded logs, bad input."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from viz_store import displacement, make_store, von_mises

from woundsweep.cli import main
from woundsweep.config.manifest import load_run
from woundsweep.core.errors import StoreError
from woundsweep.mesh.cache import load_mesh, mesh_path
from woundsweep.store.reader import read_results
from woundsweep.viz import atlas as atlas_mod
from woundsweep.viz.atlas import parse_views


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = make_store(tmp_path_factory.mktemp("atlas") / "run")
    (rd / "analysis").mkdir()
    (rd / "analysis" / "report.md").write_text("# Report\n\n| a | b |\n|---|---|\n| 1 | 2 |\n")
    (rd / "analysis" / "roc_random.png").write_bytes(b"\x89PNG\r\n\x1a\nfake")
    (rd / "analysis" / "metrics.json").write_text("{}")
    (rd / "analysis" / "model_random.json").write_text("{}")
    return rd


def _index_data(out: Path) -> dict:
    html = (out / "index.html").read_text()
    m = re.search(r'<script type="application/json" id="atlasdata">(.*?)</script>', html, re.S)
    return json.loads(m.group(1))


def test_index_holds_every_job_with_the_store_values(run: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "site"
    assert main(["atlas", str(run), "--out", str(out)]) == 0
    text, err = capsys.readouterr()
    assert re.fullmatch(
        r"atlas: 6 jobs in \d+\.\d s \(reading the store \d+\.\d s, pages \d+\.\d s;"
        r" index \d+\.\d MB\)",
        err.splitlines()[-1],
    ), err
    assert (
        "atlas of 6 jobs (3 stored), 3D views for 2 (1 chosen jobs have no stored fields)" in text
    )
    assert f"index: {out / 'index.html'}" in text
    data = _index_data(out)
    keys = [c["key"] for c in data["columns"]]
    rows = {r[0]: dict(zip(keys, r)) for r in data["rows"]}
    assert sorted(rows) == [0, 1, 2, 3, 4, 5]
    res = read_results(run)
    for (j, k), v in res.set_index(["job_index", "stage"])["p99_von_mises_kPa"].items():
        got = rows[j][f"p99_s{k}"]
        assert (got is None) if v != v else got == pytest.approx(v, rel=1e-5)
    # The page draws the rows a page at a time, with navigation above and below the table.
    html = (out / "index.html").read_text()
    assert 'id="pager"' in html and 'id="pager-bottom"' in html and "a page at a" in html
    classes = [rows[j]["failure_class"] for j in range(6)]
    assert classes == ["converged", "not-converged", "converged"] + ["pending"] * 3
    assert rows[1]["failed_stage"] == 4 and rows[1]["p99_s3"] is not None
    assert rows[1]["p99_s4"] is None
    assert [rows[j]["converged_stages"] for j in range(6)] == [6, 3, 6, None, None, None]
    # Job 2 kept no fields (`run --fields none`): no view, and its page says why.
    assert [rows[j]["view"] for j in range(6)] == ["yes", "yes", "", "", "", ""]
    assert (
        "no stored fields (`run --fields none`, converged)"
        in (out / "jobs" / "job-2.html").read_text()
    )
    pages = sorted(p.name for p in (out / "jobs").iterdir())
    assert pages == [f"job-{j}.html" for j in range(6)]
    assert sorted(p.name for p in (out / "assets").iterdir()) == [
        "index.js", "plotly.min.js", "style.css", "viewer.js",
    ]  # fmt: skip
    # One copy of plotly.js: no page inlines it.
    size = (out / "assets" / "plotly.min.js").stat().st_size
    assert size > 1_000_000
    assert all(p.stat().st_size < size / 4 for p in (out / "jobs").iterdir())
    # The analysis: report rendered (its table too), figures and metrics copied, models not.
    page = (out / "analysis" / "index.html").read_text()
    assert "<table>" in page and '<img class="figure" src="roc_random.png"' in page
    assert sorted(p.name for p in (out / "analysis").iterdir()) == [
        "index.html", "metrics.json", "roc_random.png",
    ]  # fmt: skip


def test_views_subset_and_none(run: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "sub"
    assert main(["atlas", str(run), "--out", str(out), "--views", "1"]) == 0
    assert "3D views for 1" in capsys.readouterr().out
    assert 'id="wsdata"' in (out / "jobs" / "job-1.html").read_text()
    page0 = (out / "jobs" / "job-0.html").read_text()
    assert 'id="wsdata"' not in page0 and "3D view not built" in page0
    out2 = tmp_path / "none"
    assert main(["atlas", str(run), "--out", str(out2), "--views", "none"]) == 0
    assert not (out2 / "assets" / "plotly.min.js").exists()
    assert "pages with a 3D view: 0 jobs" in capsys.readouterr().out


def test_parse_views() -> None:
    assert parse_views("all", [0, 1, 2]) == {0, 1, 2}
    assert parse_views("none", [0, 1]) == set()
    assert parse_views("0-2, 5", list(range(8))) == {0, 1, 2, 5}
    for bad in ("1-x", "9", "a"):
        with pytest.raises(StoreError):
            parse_views(bad, [0, 1, 2])


def test_long_log_is_cut_to_its_end(run: Path, tmp_path: Path, monkeypatch) -> None:
    log = tmp_path / "job.log"
    log.write_text("early line\n" + "x" * 5000 + "\nthe last line\n")
    monkeypatch.setattr(atlas_mod, "LOG_BYTES", 1000)
    html = atlas_mod.log_html(log)
    assert (
        "the last line" in html and "early line" not in html and "the last 1 KiB of 5 KiB" in html
    )


@pytest.mark.parametrize(
    "args, needle",
    [
        (["view", "{run}", "--job", "0", "--out", "{tmp}/v.png"], "expected an .html file"),
        (["view", "{run}", "--job", "9", "--out", "{tmp}/v.html"], "no job 9"),
        (["view", "{tmp}", "--job", "0", "--out", "{tmp}/v.html"], "not a run directory"),
        (["atlas", "{run}", "--out", "{tmp}/s", "--views", "0-x"], "--views '0-x'"),
    ],
)
def test_bad_input_one_line_exit_2(run: Path, tmp_path: Path, capsys, args, needle) -> None:
    argv = [a.format(run=run, tmp=tmp_path) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1


def test_view_file_is_self_contained(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "v.html"
    assert main(["view", str(run), "--job", "0", "--out", str(out)]) == 0
    html = out.read_text()
    assert "<script src=" not in html and "<link" not in html  # nothing to fetch
    assert "Plotly" in html and 'id="wsdata"' in html
    data = json.loads(re.search(r'id="wsdata">(.*?)</script>', html, re.S).group(1))
    assert [s["stage"] for s in data["stages"]] == [1, 2, 3, 4, 5, 6]
    assert all(s["stored"] for s in data["stages"])
    # The marked maximum is the fixture's largest cell value, at that cell's midpoint.
    r = load_run(run)
    job = r.manifest.iloc[0]
    mesh = load_mesh(mesh_path(run, r.geometry(job).mesh_id))
    for s in data["stages"]:
        vm = von_mises(mesh.points, mesh.cells, s["stage"], 0)
        i = int(np.argmax(vm))
        assert s["max"]["cell"] == i and s["max"]["value_kPa"] == pytest.approx(vm[i], rel=1e-6)
        mid = mesh.points[mesh.cells[i]].mean(axis=0)
        u = displacement(mesh.points, s["stage"], 0)[mesh.cells[i]].mean(axis=0)
        np.testing.assert_allclose(s["max"]["reference_mm"], mid, atol=1e-12)
        np.testing.assert_allclose(s["max"]["deformed_mm"], mid + u, atol=1e-6)
        assert s["surface_max_kPa"] <= s["max"]["value_kPa"]

"""The view and the atlas in a real browser (headless Chromium from Debian, via selenium):
pages load from disk without console errors, the 3D canvas is drawn (coloured pixels in a
screenshot), the stage selector redraws with the stage's data, and the index lists, sorts
and filters the jobs. Screenshots go to $WOUNDSWEEP_SCREENSHOTS when it is set.

The browser tests are marked `system`: `make test-deps` (scripts/test-deps.sh, run by
`make test`) installs Debian's chromium and chromium-driver; without them they are skipped
with the reason (tests/support/browser.py)."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from browser import canvas_colour_fraction, console_errors, wait_for
from viz_store import make_store

from woundsweep.cli import main


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("browser")
    run = make_store(base / "run")
    view = base / "job0.html"
    assert main(["view", str(run), "--job", "0", "--out", str(view)]) == 0
    assert main(["view", str(run), "--job", "1", "--out", str(base / "job1.html")]) == 0
    assert main(["atlas", str(run), "--out", str(base / "atlas")]) == 0
    return {"run": run, "view": view, "view1": base / "job1.html", "atlas": base / "atlas"}


def _shot(driver, name: str, tmp_path: Path) -> bytes:
    png = driver.get_screenshot_as_png()
    (tmp_path / name).write_bytes(png)
    dest = os.environ.get("WOUNDSWEEP_SCREENSHOTS")
    if dest:
        Path(dest).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(tmp_path / name, Path(dest) / name)
    return png


_DRAWN = "var p=document.getElementById('plot'); return p && p._fullLayout && p.data && p.data.length >= 2 && document.querySelector('#plot canvas') !== null;"


def _plot_box(driver) -> tuple[int, int, int, int]:
    """The middle of the plot in screenshot pixels (away from the legend and colour bar)."""
    r = driver.execute_script(
        "var b=document.getElementById('plot').getBoundingClientRect();"
        "return [b.left, b.top, b.width, b.height, window.devicePixelRatio];"
    )
    x, y, w, h, dpr = r
    return (
        int((x + 0.25 * w) * dpr),
        int((y + 0.25 * h) * dpr),
        int((x + 0.7 * w) * dpr),
        int((y + 0.8 * h) * dpr),
    )


def _load(driver, path: Path) -> None:
    driver.get(path.as_uri())
    wait_for(driver, "return document.readyState === 'complete';")


@pytest.mark.system
def test_checks_can_fail(driver, tmp_path: Path) -> None:
    # A page with a script error and no drawing: the two checks must see both.
    bad = tmp_path / "bad.html"
    bad.write_text(
        "<html><body><div id='plot' style='width:800px;height:600px'></div>"
        "<script>undefinedFunction();</script></body></html>"
    )
    _load(driver, bad)
    time.sleep(0.5)
    assert any("undefinedFunction" in m for m in console_errors(driver))
    colour, _ = canvas_colour_fraction(_shot(driver, "bad.png", tmp_path), _plot_box(driver))
    assert colour < 0.01


def test_missing_chromium_skips_with_the_reason(monkeypatch) -> None:
    # Never silently, and never by installing: no browser is a skip that names what is
    # missing and `make test-deps`, and a warning that shows in pytest's summary.
    import browser

    monkeypatch.setattr(browser.shutil, "which", lambda name: None)
    with pytest.warns(UserWarning, match="browser tests skipped: chromium and chromedriver"):
        with pytest.raises(pytest.skip.Exception, match="make test-deps"):
            browser.start_chromium()
    monkeypatch.setattr(
        browser.shutil, "which", lambda name: "/usr/bin/chromium" if name == "chromium" else None
    )
    with pytest.warns(UserWarning, match="chromedriver not found: run `make test-deps`"):
        with pytest.raises(pytest.skip.Exception, match="make test-deps"):
            browser.start_chromium()


@pytest.mark.system
def test_view_renders_and_switches_stage(driver, site, tmp_path: Path) -> None:
    console_errors(driver)  # drop earlier pages' messages
    _load(driver, site["view"])
    wait_for(driver, _DRAWN)
    time.sleep(1.0)  # let WebGL finish the frame
    assert console_errors(driver) == []
    colour, std = canvas_colour_fraction(_shot(driver, "view.png", tmp_path), _plot_box(driver))
    assert colour > 0.05 and std > 10, (colour, std)
    # The last stored stage is shown first; every stage 1-6 can be chosen.
    options = driver.execute_script(
        "return Array.from(document.querySelectorAll('#stage option')).map(o => [o.textContent, o.disabled]);"
    )
    assert len(options) == 6 and not any(d for _, d in options)
    assert driver.execute_script("return document.getElementById('stage').value") == "5"
    # The default colour scale ends at the stage's p99, the cells above it in the top band.
    p99 = driver.execute_script(
        "var d=JSON.parse(document.getElementById('wsdata').textContent); return d.stages[5].p99_von_mises_kPa;"
    )
    bar = driver.execute_script("return document.getElementById('plot').data[0].colorbar;")
    assert driver.execute_script(
        "return document.getElementById('plot').data[0].cmax;"
    ) == pytest.approx(1.15 * p99, rel=1e-6)
    assert bar["ticktext"][-2].startswith("p99 ") and bar["ticktext"][-1].startswith("max ")
    # The band above p99 is shaded: the cells above it keep their order (the centre shows).
    shown, vm = driver.execute_script(
        "var t=document.getElementById('plot').data[0]; return [t.intensity, t.customdata];"
    )
    above = [(v, s) for v, s in zip(vm, shown) if v > p99]
    assert above and len({s for _, s in above}) > 1
    assert [s for _, s in sorted(above)] == sorted(s for _, s in above)
    # "colour scale to the maximum": the stage's surface maximum is the top.
    driver.execute_script("document.getElementById('fullrange').click();")
    cmax = {}
    for k in (1, 2):
        driver.execute_script(
            f"var s=document.getElementById('stage'); s.value='{k - 1}'; s.dispatchEvent(new Event('change'));"
        )
        wait_for(
            driver,
            f"return document.getElementById('plot').layout.title.text.indexOf('stage {k}') >= 0;",
        )
        cmax[k] = driver.execute_script("return document.getElementById('plot').data[0].cmax;")
    # The fixture's von Mises is 10 kPa * stage + the same field: the surface max moves by 10.
    assert cmax[2] - cmax[1] == pytest.approx(10.0, abs=1e-3)
    # The deformation scale moves the surface: at 0 it is the reference mesh.
    x1 = driver.execute_script("return document.getElementById('plot').data[0].x[0];")
    driver.execute_script(
        "var s=document.getElementById('scale'); s.value='0'; s.dispatchEvent(new Event('input'));"
    )
    x0 = driver.execute_script("return document.getElementById('plot').data[0].x[0];")
    ref = driver.execute_script(
        "var d=JSON.parse(document.getElementById('wsdata').textContent);"
        "var s=atob(d.x), u=new Uint8Array(s.length); for (var i=0;i<s.length;i++) u[i]=s.charCodeAt(i);"
        "return new Float32Array(u.buffer)[0];"
    )
    assert x0 == pytest.approx(ref, abs=1e-6) and x1 != pytest.approx(x0, abs=1e-9)
    # The cut adds the section's triangles and keeps the surface's y >= mid half.
    n_full = driver.execute_script("return document.getElementById('plot').data[0].i.length;")
    driver.execute_script("document.getElementById('cut').click();")
    n_cut = driver.execute_script("return document.getElementById('plot').data[0].i.length;")
    data = driver.execute_script(
        "return JSON.parse(document.getElementById('wsdata').textContent).cut.n_triangles;"
    )
    assert data > 0 and n_cut != n_full and n_cut > data
    assert (
        driver.execute_script("return document.getElementById('lines').layout.title.text;")
        == "no profile lines stored"
    )
    names = driver.execute_script("return document.getElementById('plot').data.map(t => t.name);")
    assert names == ["surface", "closure zone", "largest cell mean"]
    note = driver.find_element("id", "note").text
    assert "largest cell mean" in note and "p99 of the volume" in note and "largest sample" in note
    assert console_errors(driver) == []


@pytest.mark.system
def test_view_names_stages_without_fields(driver, site) -> None:
    console_errors(driver)
    _load(driver, site["view1"])
    wait_for(driver, _DRAWN)
    options = driver.execute_script(
        "return Array.from(document.querySelectorAll('#stage option')).map(o => [o.textContent, o.disabled]);"
    )
    assert [d for _, d in options] == [True, True, False, True, True, True]
    assert "not kept by `run --fields final`" in options[0][0]
    assert "max-iterations" in options[3][0] and "not run" in options[5][0]
    assert console_errors(driver) == []


@pytest.mark.system
def test_atlas_index_lists_sorts_filters(driver, site, tmp_path: Path) -> None:
    console_errors(driver)
    _load(driver, site["atlas"] / "index.html")
    wait_for(driver, "return document.querySelectorAll('#index tbody tr').length > 0;")
    _shot(driver, "atlas-index.png", tmp_path)
    rows = lambda: driver.execute_script(  # noqa: E731
        "return Array.from(document.querySelectorAll('#index tbody tr')).map(r => Number(r.dataset.job));"
    )
    assert rows() == [0, 1, 2, 3, 4, 5]
    assert driver.find_element("id", "count").text == "rows 1-6 of 6"
    classes = driver.execute_script(
        "var c=[...document.querySelectorAll('#index thead tr:first-child th')].findIndex(t => t.dataset.col==='failure_class');"
        "return [...document.querySelectorAll('#index tbody tr')].map(r => r.children[c].textContent);"
    )
    assert classes == ["converged", "not-converged", "converged"] + ["pending"] * 3
    driver.find_elements("css selector", "#index thead tr:first-child th")[
        0
    ].click()  # job, descending
    assert rows() == [5, 4, 3, 2, 1, 0]
    box = driver.find_element("css selector", "input[data-col='skin_type']")
    box.send_keys("soft")
    assert rows() == [5, 4]
    box.clear()
    box.send_keys(" ")  # an input event with an empty filter
    p99 = driver.find_element("css selector", "input[data-col='p99_s6']")
    p99.send_keys(">0")
    assert rows() == [2, 0]  # the jobs with a stage 6, still sorted by job descending
    assert console_errors(driver) == []


@pytest.mark.system
def test_atlas_job_page_draws_with_shared_plotly(driver, site, tmp_path: Path) -> None:
    page = site["atlas"] / "jobs" / "job-0.html"
    assert '<script src="../assets/plotly.min.js">' in page.read_text()
    console_errors(driver)
    _load(driver, page)
    wait_for(driver, _DRAWN)
    time.sleep(1.0)
    assert console_errors(driver) == []
    colour, _ = canvas_colour_fraction(_shot(driver, "atlas-job.png", tmp_path), _plot_box(driver))
    assert colour > 0.05
    assert "job 0 log line" in driver.find_element("css selector", "pre.log").text
    # The pending job's page has no view and says why.
    _load(driver, site["atlas"] / "jobs" / "job-3.html")
    assert "no result stored yet" in driver.find_element("css selector", "p.noview").text
    assert console_errors(driver) == []
    assert np.isfinite(colour)


def _boxes(driver, plot: str) -> dict[str, list[float]]:
    """Screen rectangles [left, top, right, bottom] of a 2D plot's legend, x-axis title and
    title (absent ones left out)."""
    return driver.execute_script(
        "var out={}, p=document.getElementById(arguments[0]);"
        "[['legend','.legend'],['xtitle','.g-xtitle'],['title','.g-gtitle']].forEach(function(s){"
        " var e=p.querySelector(s[1]); if(!e) return; var b=e.getBoundingClientRect();"
        " if(b.width>0&&b.height>0) out[s[0]]=[b.left,b.top,b.right,b.bottom];});"
        "return out;",
        plot,
    )


def _overlap(a: list[float], b: list[float]) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


@pytest.mark.system
def test_profile_plots_do_not_overprint_at_1280x900(driver, site, tmp_path: Path) -> None:
    """At 1,280 x 900 the legends of the profile and line-load plots overlap neither their
    x-axis titles nor their titles (on a view with three profile lines and both line loads).
    The rectangle check is shown to fail on a legend placed under the axis."""
    from woundsweep.viz.jobdata import open_job
    from woundsweep.viz.view import view_page

    jf = open_job(site["run"], 0)
    y = np.linspace(-2.0, 2.0, 100)
    line = {"points_mm": np.c_[np.zeros(100), y, np.zeros(100)], "von_mises_kPa": 10 + y**2}
    profiles = {6: {n: line for n in ("along_wound", "through_thickness", "across_patch")}}
    yc = np.linspace(-1.5, 1.5, 7)
    closure = {
        6: {
            "closure_line_y_mm": yc,
            "closing_force_per_length_mN_per_mm": 5 - yc**2,
            "contact_force_per_length_mN_per_mm": 1 + 0 * yc,
        }
    }
    page = tmp_path / "lines.html"
    page.write_text(view_page(jf._replace(profiles=profiles, closure_lines=closure)))
    driver.set_window_size(1280, 900)
    w, h = driver.execute_script("return [window.innerWidth, window.innerHeight]")
    driver.set_window_size(2 * 1280 - w, 2 * 900 - h)  # the viewport is 1,280 x 900
    try:
        console_errors(driver)
        _load(driver, page)
        wait_for(driver, _DRAWN)
        wait_for(driver, "return document.querySelector('#closure .legend') !== null;")
        time.sleep(0.5)
        _shot(driver, "view-1280x900.png", tmp_path)
        for plot in ("lines", "closure"):
            boxes = _boxes(driver, plot)
            assert {"legend", "xtitle", "title"} <= set(boxes), (plot, boxes)
            for a, b in (("legend", "xtitle"), ("legend", "title"), ("xtitle", "title")):
                assert not _overlap(boxes[a], boxes[b]), (plot, a, b, boxes)
        # The old placement (a horizontal legend just under the plot) fails the check.
        driver.execute_script(
            "Plotly.relayout('lines', {'legend.orientation': 'h', 'legend.x': 0, "
            "'legend.xanchor': 'left', 'legend.y': -0.2, 'legend.yanchor': 'top'});"
        )
        time.sleep(0.3)
        boxes = _boxes(driver, "lines")
        assert _overlap(boxes["legend"], boxes["xtitle"]), boxes
        assert console_errors(driver) == []
    finally:
        driver.set_window_size(1400, 1000)

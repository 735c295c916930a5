"""`woundsweep case --view`'s page in a real browser (headless Chromium, as in
test_viz_browser.py), on the made-up case of tests/support/case_view_data.py: it loads from
disk without console errors, draws the surface with one thread per suture and the wound's rim,
and redraws for the other state, the cut and the deformation scale. Marked `system`."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from browser import console_errors, wait_for
from case_view_data import SUTURE_Y, write_page

_DRAWN = (
    "var p=document.getElementById('plot'); return p && p._fullLayout && p.data && "
    "p.data.length >= 3 && document.querySelector('#plot canvas') !== null;"
)
_NAMES = "return document.getElementById('plot').data.map(t => t.name);"


@pytest.mark.system
def test_the_case_view_loads_and_draws_its_threads(driver, tmp_path: Path) -> None:  # noqa: ANN001
    page = write_page(tmp_path / "case")
    driver.get(page.as_uri())
    wait_for(driver, "return document.readyState === 'complete';")
    wait_for(driver, _DRAWN)
    assert console_errors(driver) == []
    names = driver.execute_script(_NAMES)
    assert names.count("threads (sutures)") == len(SUTURE_Y)
    assert "the wound's rim" in names and names[0] == "surface"
    # The sutured state first, by name in the plot's title.
    title = driver.execute_script("return document.getElementById('plot').layout.title.text;")
    assert title.startswith("sutured")
    # The other state, the cut and no deformation redraw without errors; with the cut the
    # threads at y < 0 (the cut-away half) are left empty.
    driver.execute_script(
        "var s=document.getElementById('stage'); s.value='1'; s.dispatchEvent(new Event('change'));"
        "var c=document.getElementById('cut'); c.checked=true; c.dispatchEvent(new Event('change'));"
        "var b=document.getElementById('scale'); b.value='0'; b.dispatchEvent(new Event('input'));"
    )
    time.sleep(1.0)
    assert console_errors(driver) == []
    title = driver.execute_script("return document.getElementById('plot').layout.title.text;")
    assert title.startswith("at the end of the load after closure")
    drawn = driver.execute_script(
        "return document.getElementById('plot').data.filter(t => t.name === 'threads (sutures)')"
        ".map(t => t.x.length);"
    )
    assert len(drawn) == len(SUTURE_Y) and drawn[0] == 0 and all(n > 0 for n in drawn[1:])
    shown = driver.execute_script(
        "return document.getElementById('plot').data.filter(t => t.showlegend !== false)"
        ".map(t => t.name);"
    )
    assert "threads (sutures)" in shown  # the legend keeps the threads when the first is cut

"""The atlas index of a few hundred jobs in a real browser (headless Chromium, as in
test_viz_browser.py): it draws one page of rows at a time, turns pages, changes the page
size, sorts and filters the whole table (not the page), counts what it shows, and keeps its
state in the URL so that a reload (or the back button from a job page) returns to the same
rows. Marked `system` (`make test-deps` installs Chromium)."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest
from browser import console_errors
from synthetic_store import SMALL_SWEEP, write_store

from woundsweep.cli import main

# 72 geometries x 3 skins x 1 orientation = 216 jobs: three pages of 100 rows.
SWEEP = {
    **SMALL_SWEEP,
    "grid": {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [0.5, 1],
        "orientation_deg": [0],
    },
}
JOBS = 216


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """The site's index.html and its data (columns, rows) as the page embeds them."""
    base = tmp_path_factory.mktemp("index")
    write_store(base / "run", sweep=SWEEP, seed=3, failed_fraction=0.15)
    assert main(["atlas", str(base / "run"), "--views", "none", "--out", str(base / "site")]) == 0
    path = base / "site" / "index.html"
    text = path.read_text()
    m = re.search(r'<script type="application/json" id="atlasdata">(.*?)</script>', text, re.S)
    data = json.loads(m.group(1))
    assert len(data["rows"]) == JOBS
    return path, data


def _rows(driver) -> list[int]:
    return driver.execute_script(
        "return [...document.querySelectorAll('#index tbody tr')].map(r => Number(r.dataset.job));"
    )


def _count(driver) -> str:
    return driver.find_element("id", "count").text


def _click(driver, selector: str) -> None:
    driver.execute_script(f"document.querySelector({json.dumps(selector)}).click();")


def _type(driver, col: str, text: str) -> None:
    from selenium.webdriver.common.keys import Keys

    # Keystrokes (not clear(), which fires no input event): what a reader does.
    box = driver.find_element("css selector", f"input[data-col='{col}']")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(Keys.BACKSPACE, text)


def _attr(driver, selector: str, name: str) -> str:
    return driver.find_element("css selector", selector).get_attribute(name)


def _col(data: dict, key: str) -> int:
    return [c["key"] for c in data["columns"]].index(key)


@pytest.mark.system
def test_index_pages_through_every_job(driver, index) -> None:
    path, _ = index
    console_errors(driver)
    driver.get(path.as_uri())
    assert _rows(driver) == list(range(100))  # one page, not every job
    assert _count(driver) == f"rows 1-100 of {JOBS}"
    _click(driver, "#pager button[data-page='next']")
    assert _rows(driver) == list(range(100, 200)) and _count(driver) == "rows 101-200 of 216"
    assert _attr(driver, "#pageno", "value") == "2"
    _click(driver, "#pager button[data-page='last']")
    assert _rows(driver) == list(range(200, JOBS)) and _count(driver) == "rows 201-216 of 216"
    assert driver.execute_script(
        "return document.querySelector(\"#pager button[data-page='next']\").disabled;"
    )
    # A smaller page keeps the first shown row in view; the page box jumps.
    driver.find_element("css selector", "#pagesize option[value='50']").click()
    assert _count(driver) == "rows 201-216 of 216"
    driver.execute_script(  # the pager is redrawn on each change: no element kept across
        "var b=document.getElementById('pageno'); b.value='2'; b.dispatchEvent(new Event('change'));"
    )
    assert _rows(driver) == list(range(50, 100)) and _count(driver) == "rows 51-100 of 216"
    # The navigation under the table turns the same pages.
    _click(driver, "#pager-bottom button[data-page='previous']")
    assert _rows(driver) == list(range(50))
    assert console_errors(driver) == []


@pytest.mark.system
def test_index_sorts_and_filters_the_whole_table(driver, index) -> None:
    path, data = index
    driver.get(path.as_uri())
    driver.find_element("css selector", "#pagesize option[value='50']").click()
    # p99 of stage 6 descending over all pages, missing values (failed jobs) last.
    c6 = _col(data, "p99_s6")
    _click(driver, "th[data-col='p99_s6']")
    _click(driver, "th[data-col='p99_s6']")
    have = [r for r in data["rows"] if r[c6] is not None]
    want = [r[0] for r in sorted(have, key=lambda r: -r[c6])]
    want += sorted(r[0] for r in data["rows"] if r[c6] is None)
    assert 0 < len(have) < JOBS
    seen = []
    for _ in range(5):
        rows = _rows(driver)
        assert len(rows) <= 50
        seen += rows
        _click(driver, "#pager button[data-page='next']")
    assert seen == want
    # A filter selects among all jobs, counts them, and starts at their first page.
    cf = _col(data, "failure_class")
    failed = [r[0] for r in data["rows"] if r[cf] == "not-converged"]
    _type(driver, "failure_class", "not-conv")
    assert 0 < len(failed) < 50
    assert _count(driver) == f"rows 1-{len(failed)} of {len(failed)} (filtered from 216)"
    assert sorted(_rows(driver)) == sorted(failed)
    _type(driver, "failure_class", "")
    c1 = _col(data, "p99_s1")
    values = sorted(r[c1] for r in data["rows"] if r[c1] is not None)
    lo, hi = values[20], values[80]
    _type(driver, "p99_s1", f"{lo}..{hi}")
    inside = [r[0] for r in data["rows"] if r[c1] is not None and lo <= r[c1] <= hi]
    assert _count(driver) == f"rows 1-50 of {len(inside)} (filtered from 216)"
    assert set(_rows(driver)) <= set(inside)
    _type(driver, "skin_type", "no such skin")
    assert _rows(driver) == [] and _count(driver) == "no rows (filtered from 216)"
    _click(driver, "#clearfilters")
    assert _count(driver) == "rows 1-50 of 216"
    assert _attr(driver, "input[data-col='p99_s1']", "value") == ""


@pytest.mark.system
def test_index_state_survives_a_reload(driver, index) -> None:
    path, _ = index
    driver.get(path.as_uri())
    driver.find_element("css selector", "#pagesize option[value='50']").click()
    _click(driver, "th[data-col='p99_s3']")
    _type(driver, "wound_shape", "wedge")
    _click(driver, "#pager button[data-page='next']")
    before = (_rows(driver), _count(driver))
    assert before[1].startswith("rows 51-100 of ")
    assert "f.wound_shape=wedge" in driver.current_url and "s=p99_s3" in driver.current_url
    driver.refresh()
    time.sleep(0.2)
    assert (_rows(driver), _count(driver)) == before
    assert _attr(driver, "input[data-col='wound_shape']", "value") == "wedge"
    assert _attr(driver, "th[data-col='p99_s3']", "class") == "asc"
    assert console_errors(driver) == []

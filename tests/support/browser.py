"""Headless Chromium for the viz tests: Debian's ``chromium`` and ``chromium-driver``, driven
by selenium. The tests never install them: scripts/test-deps.sh (`make test-deps`, run by
`make test`) does; when they are missing the tests are skipped with the reason (also issued
as a warning, so it shows in pytest's summary)."""

from __future__ import annotations

import io
import shutil
import time
import warnings
from typing import Any

import numpy as np
import pytest

__all__ = ["canvas_colour_fraction", "console_errors", "start_chromium"]

_PACKAGES = ["chromium", "chromium-driver"]


def _skip(reason: str) -> None:
    warnings.warn(f"browser tests skipped: {reason}", stacklevel=2)
    pytest.skip(reason)


def start_chromium() -> Any:
    """A selenium driver for headless Chromium (software WebGL), or skip with the reason."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        _skip("selenium is not installed (pip install -e '.[test]')")
    chrome, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if not (chrome and driver):
        missing = [
            name for name, path in (("chromium", chrome), ("chromedriver", driver)) if not path
        ]
        _skip(
            f"{' and '.join(missing)} not found: run `make test-deps` (scripts/test-deps.sh "
            f"installs Debian's {' and '.join(_PACKAGES)})"
        )
    opts = webdriver.ChromeOptions()
    opts.binary_location = chrome
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-dev-shm-usage",
        "--window-size=1400,1000",
    ):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        return webdriver.Chrome(service=Service(executable_path=driver), options=opts)
    except Exception as err:  # selenium raises WebDriverException subclasses
        _skip(f"chromium did not start: {type(err).__name__}: {str(err).splitlines()[0]}")


def console_errors(driver: Any) -> list[str]:
    """The page's console messages of level SEVERE (errors) since the last call."""
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def canvas_colour_fraction(png: bytes, box: tuple[int, int, int, int]) -> tuple[float, float]:
    """(share of strongly coloured pixels, pixel standard deviation) inside ``box`` (x0, y0,
    x1, y1) of a screenshot: a drawn viridis surface is coloured; axes and paper are grey."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)
    x0, y0, x1, y1 = box
    crop = img[y0:y1, x0:x1]
    chroma = crop.max(axis=2) - crop.min(axis=2)
    return float((chroma > 40).mean()), float(crop.std())


def wait_for(driver: Any, script: str, timeout: float = 60.0) -> Any:
    """Run ``script`` in the page until it returns something truthy (AssertionError after
    ``timeout`` s)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for: {script}")

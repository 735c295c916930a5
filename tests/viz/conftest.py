"""Fixtures of the viz tests: `driver`, headless Chromium for the browser tests (one per test
module; the tests skip with the reason when Chromium or selenium is missing)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from browser import start_chromium


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    d = start_chromium()
    yield d
    d.quit()

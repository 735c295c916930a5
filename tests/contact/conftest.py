"""Fixtures of the contact tests: `squares` (two facing, non-matching triangulated squares)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def squares():
    """Two facing unit squares with non-matching triangulations (3 x 3 against 4 x 4)."""
    from contact_surfaces import two_squares

    return two_squares(3, 4)

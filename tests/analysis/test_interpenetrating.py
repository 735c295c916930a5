"""The interpenetration flag (the flanks pass through each other) counted and optionally left out of
the stress model; the flag itself is tested in test_closure.py."""

from __future__ import annotations

import pandas as pd
import pytest

from woundsweep.analysis.data import select_rows
from woundsweep.analysis.settings import STRESS


def frame() -> pd.DataFrame:
    # Jobs a, b, c: stage-3 rows overlapping (a), open (b), overlapping but unconverged (c).
    return pd.DataFrame(
        {
            "job_id": ["a", "a", "b", "b", "c"],
            "stage": [2, 3, 2, 3, 3],
            "status": ["converged"] * 4 + ["max-iterations"],
            STRESS: [20.0, 40.0, 21.0, 30.0, 50.0],
            "interpenetrating": [None, 1, None, 0, 1],
        }
    )


@pytest.mark.parametrize("drop", [False, True])
def test_select_rows_counts_and_optionally_drops_the_overlapping_rows(drop: bool) -> None:
    rows, counts = select_rows(frame(), drop_interpenetrating=drop)
    assert counts["interpenetrating_rows"] == 1  # the unconverged row is not counted
    assert counts["interpenetrating_dropped"] is drop
    kept = set(zip(rows["job_id"], rows["stage"]))
    assert kept == ({("a", 2), ("b", 2), ("b", 3)} | (set() if drop else {("a", 3)}))
    assert counts["used_rows"] == len(rows) == (3 if drop else 4)


def test_select_rows_of_a_store_without_the_column() -> None:
    rows, counts = select_rows(frame().drop(columns="interpenetrating"), True)
    assert counts["interpenetrating_rows"] == 0 and len(rows) == 4

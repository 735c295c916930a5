"""Rows that repeat an earlier stage's state of their job are one state: left out of the
models by default and counted (`analysis.data.duplicate_states`, `select_rows`)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_store import SMALL_SWEEP, write_store

from woundsweep.analysis.data import duplicate_states, load_results, select_rows
from woundsweep.analysis.report import SCALE_NOTE, zero_index_notes
from woundsweep.analysis.settings import DUPLICATE_COLUMNS, DUPLICATE_RTOL, STRESS

SWEEP = {
    **SMALL_SWEEP,
    "grid": {
        **SMALL_SWEEP["grid"],
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
        "wound_width_factor": [0.5],
        "orientation_deg": [0],
    },
}


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory):
    rd = tmp_path_factory.mktemp("dup") / "run"
    write_store(rd, sweep=SWEEP, seed=5, failed_fraction=0.0)
    return load_results(rd)


def _copy_state(df, job: str, src: int, dst: int, scale: float = 1.0):
    out = df.copy()
    a = (out["job_id"] == job) & (out["stage"] == src)
    b = (out["job_id"] == job) & (out["stage"] == dst)
    for c in (STRESS, *DUPLICATE_COLUMNS):
        if c in out:
            out.loc[b, c] = out.loc[a, c].to_numpy() * scale
    return out


def test_a_duplicate_row_is_left_out_and_counted(results) -> None:
    base, counts = select_rows(results)
    assert counts["duplicate_rows"] == 0  # the synthetic stages all differ
    job = str(results["job_id"].iloc[0])
    df = _copy_state(results, job, 4, 5)
    df = _copy_state(df, job, 4, 6, scale=1 + 0.1 * DUPLICATE_RTOL)  # within the tolerance
    used, counts = select_rows(df)
    assert counts["duplicate_rows"] == 2 and counts["duplicate_dropped"]
    assert len(used) == len(base) - 2
    left = used[used["job_id"] == job]["stage"].tolist()
    assert 4 in left and 5 not in left and 6 not in left  # the first of the repeats stays
    assert "within 1e-06 relative" in counts["duplicate_rule"]
    kept, counts = select_rows(df, keep_duplicates=True)
    assert len(kept) == len(base) and counts["duplicate_rows"] == 2
    assert not counts["duplicate_dropped"]


def test_a_state_outside_the_tolerance_is_distinct(results) -> None:
    job = str(results["job_id"].iloc[0])
    df = _copy_state(results, job, 4, 5, scale=1 + 10 * DUPLICATE_RTOL)
    assert not duplicate_states(df[df["status"] == "converged"]).any()


def test_a_zero_sobol_index_of_the_thickness_is_explained() -> None:
    notes = zero_index_notes(
        {"dermal_thickness_mm": {"ST": 0.0004}, "wound_depth": {"ST": 0.6}, "stage": {"ST": 0.2}}
    )
    assert notes[1] == "Total index below 0.005: dermal_thickness_mm."
    assert notes[2] == SCALE_NOTE and "scale-invariant" in SCALE_NOTE
    assert zero_index_notes({"stage": {"ST": 0.3}}) == []
    assert np.isfinite(DUPLICATE_RTOL)

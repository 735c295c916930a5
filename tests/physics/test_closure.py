"""The closure measures along the wound's line (`woundsweep.physics.closure`) and what the store,
`status` and the analysis make of a reopened stage."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from woundsweep.analysis.data import select_rows
from woundsweep.core.schema import StageResult, stage_field_kinds
from woundsweep.execution.summary import summarize
from woundsweep.physics.closure import (
    CLOSED_MAX_PER_W,
    CLOSED_MEDIAN_PER_W,
    ClosureLine,
    ClosureMeasures,
)

W = 2.0  # wound width (mm) of the synthetic zone
YS = np.linspace(-1.0, 1.0, 21)
ZS = (0.0, -0.5, -1.0)


def slot() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference nodes of a slot's two flanks (x = -1 and x = +1) on a y-z grid, the mirror
    pairs and the left flank's nodes."""
    pts, pairs = [], []
    for y in YS:
        for z in ZS:
            pairs.append((len(pts), len(pts) + 1))
            pts += [(-W / 2, y, z), (W / 2, y, z)]
    X = np.array(pts)
    pairs = np.array(pairs)
    return X, pairs, pairs[:, 0]


def closing(X: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """Displacement that leaves pair i with the deformed gap ``gap[i]`` (half per flank)."""
    u = np.zeros_like(X)
    move = (W - gap) / 2
    u[0::2, 0] = move
    u[1::2, 0] = -move
    return u.ravel()


def test_a_closed_slot_has_zero_gap_and_no_overlap() -> None:
    X, pairs, left = slot()
    line = ClosureLine(X, pairs, left, z_top=0.0)
    assert line.width_mm == pytest.approx(W)
    assert len(line.surface) == len(YS)  # only the pairs at z = 0
    m = line.measure(closing(X, np.zeros(len(pairs))))
    assert m.gap_max_mm == pytest.approx(0.0, abs=1e-12) and m.overlap_mm == 0.0
    assert m.closed and not m.interpenetrating
    open_ = line.measure(np.zeros(X.size))  # the reference: open by w everywhere
    assert open_.gap_median_per_w == pytest.approx(1.0) and not open_.closed


def test_ends_open_while_the_middle_crosses_is_flagged() -> None:
    """The largest opening (the ends) hides the overlap in the middle: the overlap is measured
    on every mirror pair, the gap at the surface."""
    X, pairs, left = slot()
    y, z = X[pairs[:, 0], 1], X[pairs[:, 0], 2]
    gap = np.where(np.abs(y) > 0.7, 0.3, 0.0)  # both ends open by 15 % of w at every depth
    gap = np.where((np.abs(y) < 0.3) & (z < 0), -0.2, gap)  # the deep middle crosses by 0.2 mm
    m = ClosureLine(X, pairs, left, z_top=0.0).measure(closing(X, gap))
    assert m.gap_max_mm == pytest.approx(0.3)  # the widest surface opening: an end
    assert m.gap_min_mm == pytest.approx(0.0)  # the surface middle touches
    assert m.overlap_mm == pytest.approx(0.2)
    assert m.interpenetrating and not m.closed


@pytest.mark.parametrize(
    ("median", "widest", "closed"),
    [
        (0.9 * CLOSED_MEDIAN_PER_W, 0.9 * CLOSED_MAX_PER_W, True),
        (1.1 * CLOSED_MEDIAN_PER_W, 0.9 * CLOSED_MAX_PER_W, False),
        (0.5 * CLOSED_MEDIAN_PER_W, 1.1 * CLOSED_MAX_PER_W, False),
    ],
)
def test_the_closed_criterion(median: float, widest: float, closed: bool) -> None:
    m = ClosureMeasures(0.0, median * W, widest * W, 0.0, W)
    assert m.closed is closed


def test_line_loads_are_forces_per_length_along_the_wound() -> None:
    """A closing force of q mN/mm spread as nodal forces over the left flank's nodes reads as
    q in every bin; the contact's residual term reads with its sign (away from the mid-plane
    on the left flank = positive line load)."""
    X, pairs, left = slot()
    line = ClosureLine(X, pairs, left, z_top=0.0)
    q = 3.0  # mN/mm along y, shared by the depths
    f = np.zeros(X.size)
    dy = YS[1] - YS[0]
    share = np.where(np.isclose(np.abs(X[left, 1]), 1.0), dy / 2, dy)  # trapezoid at the ends
    f[3 * left] = q * share / len(ZS)
    loads = line.line_loads(f, -0.5 * f)
    inner = (loads.y_mm > -0.8) & (loads.y_mm < 0.8)
    assert np.allclose(loads.closing_mN_per_mm[inner], q, rtol=1e-9)
    assert np.sum(loads.closing_mN_per_mm * np.diff(line.edges)) == pytest.approx(q * 2.0)
    assert np.allclose(loads.contact_mN_per_mm, -0.5 * loads.closing_mN_per_mm)
    none = line.line_loads(None, None)
    assert not none.closing_mN_per_mm.any() and not none.contact_mN_per_mm.any()


def test_closure_columns_are_in_the_schema() -> None:
    kinds = stage_field_kinds()
    assert kinds["closed"] is int and kinds["interpenetrating"] is int
    for name in ClosureMeasures(0.0, 0.0, 0.0, 0.0, W).columns():
        assert kinds[name] is float
    assert StageResult(3, "converged").closed is None


def rows() -> pd.DataFrame:
    """Two jobs: job a closed in stages 2-6; job b reopened in stages 4 and 5, not converged
    in 6. Stage 1 has no flag."""
    recs = []
    for job, closed in (("a", [1, 1, 1, 1, 1]), ("b", [1, 1, 0, 0, None])):
        recs.append({"job_id": job, "stage": 1, "status": "converged", "closed": None})
        for k, c in zip(range(2, 7), closed):
            status = "converged" if c is not None else "max-iterations"
            recs.append({"job_id": job, "stage": k, "status": status, "closed": c})
    df = pd.DataFrame(recs)
    df["closed"] = df["closed"].astype("Int64")
    df["p99_von_mises_kPa"] = 10.0
    df["interpenetrating"] = pd.array([None] * len(df), dtype="Int64")
    return df


def test_reopened_rows_are_counted_and_left_out_of_the_model() -> None:
    df = rows()
    used, counts = select_rows(df, keep_duplicates=True)  # every stage's p99 is 10 here
    assert counts["reopened_rows"] == 2 and counts["reopened_dropped"] is True
    assert len(used) == 11 - 2  # 11 converged rows, 2 reopened
    assert set(zip(used["job_id"], used["stage"])).isdisjoint({("b", 4), ("b", 5)})
    kept, counts = select_rows(df, keep_reopened=True, keep_duplicates=True)
    assert len(kept) == 11 and counts["reopened_dropped"] is False


def test_status_counts_the_reopened_stages() -> None:
    df = rows()
    jobs = df.drop_duplicates("job_id").copy()
    for col, value in (
        ("failure_class", "converged"),
        ("failed_stage", np.nan),
        ("total_cpu_time_s", 0.0),  # no CPU time: no cost-model estimate of what is left
        ("attempts", 1),
    ):
        df[col] = value
    t = pd.Timestamp("2026-01-01", tz="UTC")
    df["started_at_utc"], df["finished_at_utc"] = t, t + pd.Timedelta(seconds=10)
    manifest = pd.DataFrame({"job_id": jobs["job_id"]})
    manifest["job_index"] = range(len(manifest))
    s = summarize(manifest, df)
    assert s["reopened_by_stage"] == {"4": 1, "5": 1}
    assert s["closure_rows"] == 9 and s["closed_rows"] == 7


def test_a_reopened_stage_is_stored_and_counted(empty_run, capsys) -> None:
    """Through the store: a job whose stage 4 reopened is stored with closed = 0 there,
    `status` counts it, and the stress model's rows leave it out."""
    import json

    from store_files import store_converged

    from woundsweep.cli import main
    from woundsweep.store.reader import read_results

    store_converged(empty_run, 0, reopened_at=4)
    store_converged(empty_run, 1)
    df = read_results(empty_run)
    flags = df.set_index(["job_index", "stage"])["closed"]
    assert flags.loc[(0, 4)] == 0 and flags.loc[(0, 5)] == 1 and flags.loc[(1, 4)] == 1
    assert main(["status", str(empty_run), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["reopened_by_stage"] == {"4": 1}
    assert s["closure_rows"] == 10 and s["closed_rows"] == 9
    used, counts = select_rows(df)
    assert counts["reopened_rows"] == 1 and len(used) == 11

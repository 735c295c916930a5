"""The closing loads side by side (`analyze --beside`): the summary counts the rows, the closed
ones and the along-wound maxima at each run's own zone ends; runs with one closing load twice
are refused before any training."""

from __future__ import annotations

import numpy as np
import pandas as pd
from synthetic_store import SMALL_SWEEP, write_store

from woundsweep.analysis.closures import closure_summary, report_lines
from woundsweep.cli import main


def _rows(at_fraction: list[float], closed: list[int], stage: int) -> pd.DataFrame:
    """Rows of a trench (L = 3) whose along-wound maximum sits at the given line fractions."""
    L = 3.0
    t = np.asarray(at_fraction)
    return pd.DataFrame(
        {
            "stage": stage,
            "wound_shape": "wedge",
            "patch_half_length_mm": L,
            "wound_length_mm": np.nan,
            "profile_along_wound_max_at_mm": t * 2 * L - L,
            "closed": closed,
        }
    )


def test_maxima_at_each_closures_own_zone_ends_are_counted() -> None:
    # The reactions' zone ends at 1/3 and 2/3, the code's at 1/4 and 3/4.
    reactions = _rows([1 / 3, 2 / 3, 0.5, 0.36], [1, 1, 1, 1], 2)
    code = _rows([0.25, 0.5, 0.5, 1 / 3], [0, 1, 0, 0], 3)
    out = closure_summary([(reactions, "reactions", 1 / 3), (code, "paper-code", 0.5)])
    g2 = out["reactions"]["groups"]["stage 2"]
    assert g2 == {"rows": 4, "closed": 4, "at_zone_ends": 0.75}
    g3 = out["paper-code"]["groups"]["stages 3-6"]
    assert g3 == {"rows": 4, "closed": 1, "at_zone_ends": 0.25}
    assert out["paper-code"]["zone_ends"] == [0.25, 0.75]
    text = "\n".join(report_lines({"closures": out}))
    assert "| paper-code | stages 3-6 | 4 | 1 | 25 % |" in text
    assert report_lines({"closures": {"reactions": out["reactions"]}}) == []


def test_runs_are_compared_on_the_jobs_they_share() -> None:
    # A slice of the grid beside the whole: the whole run's other jobs are left out.
    reactions = _rows([1 / 3, 2 / 3, 0.5, 0.5], [1, 1, 1, 1], 2).assign(job_id=list("abcd"))
    code = _rows([0.5, 0.25], [0, 1], 3).assign(job_id=["b", "e"])
    out = closure_summary([(reactions, "reactions", 1 / 3), (code, "paper-code", 0.5)])
    assert out["reactions"]["jobs"] == out["paper-code"]["jobs"] == 1
    assert out["reactions"]["groups"]["stage 2"] == {"rows": 1, "closed": 1, "at_zone_ends": 1.0}
    assert out["paper-code"]["groups"]["stages 3-6"]["rows"] == 1
    assert "On the jobs every run has (1)" in "\n".join(report_lines({"closures": out}))


def test_beside_a_run_with_the_same_closure_is_refused(tmp_path, capsys) -> None:
    sweep = {**SMALL_SWEEP, "grid": {**SMALL_SWEEP["grid"], "dermal_thickness_mm": [1],
                                     "orientation_deg": [0], "skin_type": ["normal"]}}  # fmt: skip
    a, b = tmp_path / "a", tmp_path / "b"
    write_store(a, sweep=sweep, stages=(1, 2))
    write_store(b, sweep=sweep, stages=(1, 2))
    assert main(["analyze", str(a), "--beside", str(b)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "each run needs its own closing load" in err[0]

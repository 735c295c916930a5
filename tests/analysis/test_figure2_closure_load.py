"""Figure 2 from the profile lines groups the bars by ``closure_load`` when a run has more
than one (side by side), and reads a store without the column as ``reactions``."""

from __future__ import annotations

import numpy as np
import pandas as pd

from woundsweep.analysis.figures_profiles import profile_max_locations
from woundsweep.core.schema import PROFILE_LINES


def _pos(loads: list[str]) -> pd.DataFrame:
    n = 12 * len(loads)
    rng = np.random.default_rng(0)
    out = pd.DataFrame(
        {
            "stage_group": np.tile(["stage 1", "stage 2", "stages 3-6"], n // 3),
            "closure_load": np.repeat(loads, 12),
        }
    )
    for line in PROFILE_LINES:
        out[f"{line}_index"] = rng.integers(0, 100, n).astype(float)
    return out


def test_two_closure_loads_are_drawn_side_by_side() -> None:
    fig = profile_max_locations(_pos(["reactions", "solved"]))
    ax = fig.axes[3]  # the first histogram (stage 1, along the wound)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["closure load: reactions", "closure load: solved"]
    bars = ax.patches
    xs = sorted({round(b.get_x(), 9) for b in bars})
    widths = {round(b.get_width(), 9) for b in bars}
    assert len(widths) == 1 and len(xs) == len(bars)  # half-width bars, none on another


def test_one_closure_load_draws_one_set_of_bars() -> None:
    fig = profile_max_locations(_pos(["reactions"]))
    assert fig.axes[3].get_legend() is None
    from woundsweep.analysis.profile_locations import profile_positions

    rows = pd.DataFrame(
        {
            "stage": [1, 3],
            **{f"profile_{line}_max_at_mm": [0.0, 0.0] for line in PROFILE_LINES},
            "patch_half_length_mm": [4.0, 4.0],
            "wound_width_mm": [1.0, 1.0],
            "total_thickness_mm": [2.0, 2.0],
        }
    )
    assert list(profile_positions(rows)["closure_load"]) == ["reactions", "reactions"]

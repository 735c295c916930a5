"""Figure 2 from the profile lines and the mesh-sensitivity section, on synthetic stores
whose line maxima and p99 per mesh size factor are known by construction."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import write_results, write_store

from woundsweep.analysis.data import load_results, select_rows
from woundsweep.analysis.figures_mesh import mesh_ratio_figure
from woundsweep.analysis.figures_profiles import profile_max_locations
from woundsweep.analysis.mesh_sensitivity import (
    matched_ratios,
    mesh_importance,
    mesh_sensitivity,
    report_lines,
)
from woundsweep.analysis.paper import location_summary, normalised_locations
from woundsweep.analysis.profile_locations import (
    bin_edges,
    profile_positions,
    profile_summary,
)
from woundsweep.analysis.profile_locations import report_lines as profile_report
from woundsweep.analysis.settings import STAGE_GROUPS
from woundsweep.physics.profiles import PROFILE_LINES, profile_lines

# 2 widths x 3 shape variants = 6 geometries per mesh size factor, x 2 skins.
TINY = {
    "name": "tiny",
    "grid": {
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [2],
        "wound_width_factor": [0.3, 0.5],
        "mesh_size_factor": [0.3, 0.5, 0.7],
        "skin_type": ["normal", "soft"],
        "orientation_deg": [0],
    },
    "shapes": {
        "cylindrical": {"wound_aspect_factor": [0, 0.2]},
        "wedge": {"wound_depth_factor": [0.5]},
    },
    "solver": {"element_degree": 1},
}


def _rows(rd: Path) -> pd.DataFrame:
    return select_rows(load_results(rd))[0]


# --- Figure 2 from the profile lines ---------------------------------------------------


@pytest.fixture(scope="module")
def profile_store(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame]:
    """A store whose rows hold line maxima at known sample indices (``idx_<line>``), some
    rows without them and one position outside its line."""
    rd = tmp_path_factory.mktemp("profiles") / "run"
    rows = write_store(rd, sweep=TINY, failed_fraction=0.0, stages=(1, 2, 3, 4))
    rng = np.random.default_rng(7)
    idx = rng.integers(0, 100, (len(rows), 3))
    axis = {"along_wound": 1, "through_thickness": 2, "across_patch": 0}
    for r, row in enumerate(rows.itertuples()):
        L, w, T = row.patch_half_length_mm, row.wound_width_mm, row.total_thickness_mm
        # The solver's own lines, from the patch's bounding box.
        pts = profile_lines(np.array([[-L, -L, -T], [L + w, L, 0.0]]))
        for k, line in enumerate(PROFILE_LINES):
            rows.loc[r, f"profile_{line}_max_at_mm"] = pts[k, idx[r, k], axis[line]]
            rows.loc[r, f"profile_{line}_max_kPa"] = 1.0
    for k, line in enumerate(PROFILE_LINES):
        rows[f"idx_{line}"] = idx[:, k].astype(float)
    stage = rows["stage"].to_numpy()
    # Three stage-1 rows store no line at all; two stage-2 rows miss the across line.
    none = np.flatnonzero(stage == 1)[:3]
    across = np.flatnonzero(stage == 2)[:2]
    for line in PROFILE_LINES:
        rows.loc[none, [f"profile_{line}_max_at_mm", f"idx_{line}"]] = np.nan
    rows.loc[across, ["profile_across_patch_max_at_mm", "idx_across_patch"]] = np.nan
    # One stage-3 maximum 10 % of 2L before the line's start: outside, counted in bin 0.
    out = np.flatnonzero(stage == 3)[0]
    rows.loc[out, "profile_along_wound_max_at_mm"] = -1.2 * rows.loc[out, "patch_half_length_mm"]
    rows.loc[out, "idx_along_wound"] = 0.0
    write_results(rd, rows.drop(columns=[f"idx_{line}" for line in PROFILE_LINES]))
    return rd, rows


def _expected(rows: pd.DataFrame, stages: tuple[int, ...], line: str) -> np.ndarray:
    """Counts per bin in ascending plot coordinate: four samples per bin; through the
    thickness the coordinate -z/T runs from the surface (the last sample) down."""
    i = rows.loc[rows["stage"].isin(stages), f"idx_{line}"].dropna().to_numpy(dtype=int)
    j = (99 - i) // 4 if line == "through_thickness" else i // 4
    return np.bincount(j, minlength=25)


def test_profile_counts_are_the_stored_positions(profile_store) -> None:
    rd, written = profile_store
    summary = profile_summary(profile_positions(_rows(rd)))
    g = summary["groups"]
    for name, stages in STAGE_GROUPS:
        n = int(written["stage"].isin(stages).sum())
        assert g[name]["rows"] == n
        for line in PROFILE_LINES:
            assert g[name]["lines"][line]["counts"] == _expected(written, stages, line).tolist()
    assert g["stage 1"]["lines"]["along_wound"]["rows_without_position"] == 3
    assert g["stage 2"]["lines"]["across_patch"]["rows_without_position"] == 2
    assert g["stage 2"]["lines"]["along_wound"]["rows_without_position"] == 0
    assert g["stages 3-6"]["lines"]["along_wound"]["outside_line"] == 1
    assert sum(v["outside_line"] for v in g["stage 1"]["lines"].values()) == 0


def test_profile_bins_hold_the_normalised_positions(profile_store) -> None:
    """Each position, normalised as the figure's axis says, lies inside its bin."""
    _, written = profile_store
    r = written.dropna(subset=["profile_through_thickness_max_at_mm"]).iloc[5]
    L, w, T = r.patch_half_length_mm, r.wound_width_mm, r.total_thickness_mm
    u = {
        "along_wound": (r.profile_along_wound_max_at_mm + L) / (2 * L),
        "through_thickness": -r.profile_through_thickness_max_at_mm / T,
        "across_patch": (r.profile_across_patch_max_at_mm - w / 2) / (L + w / 2),
    }
    one = pd.DataFrame(
        {"stage_group": ["stage 1"], **{f"{ln}_index": [r[f"idx_{ln}"]] for ln in PROFILE_LINES}}
    )
    lines = profile_summary(one)["groups"]["stage 1"]["lines"]
    for line in PROFILE_LINES:
        e = bin_edges(line)
        assert len(e) == 26 and np.all(np.diff(e) > 0)
        counts = lines[line]["counts"]
        k = counts.index(1)
        assert e[k] < u[line] < e[k + 1], (line, u[line], e[k], e[k + 1])


def test_profile_figure_draws_the_counts(profile_store) -> None:
    rd, written = profile_store
    pos = profile_positions(_rows(rd))
    fig = profile_max_locations(pos)
    for i, (_name, stages) in enumerate(STAGE_GROUPS, start=1):
        for j, line in enumerate(PROFILE_LINES):
            ax = fig.axes[3 * i + j]
            heights = [p.get_height() for p in ax.patches]
            assert heights == _expected(written, stages, line).tolist()
            assert ax.get_xlim() == pytest.approx((bin_edges(line)[0], bin_edges(line)[-1]))


def test_profile_report_says_n_per_group(profile_store) -> None:
    rd, written = profile_store
    rows = _rows(rd)
    metrics = {
        "max_location": location_summary(normalised_locations(rows)),
        "max_location_profiles": profile_summary(profile_positions(rows)),
    }
    text = "\n".join(profile_report(metrics))
    # 36 jobs: stages 1 and 2 one row each, stages 3-4 two rows per job.
    assert "| stage 1 | 36 | 33 / 33 / 33 | 3 |" in text
    assert "| stage 2 | 36 | 36 / 36 / 34 | 2 |" in text
    assert "| stages 3-6 | 72 | 72 / 72 / 72 | 0 |" in text
    assert "1 line positions lay outside their line" in text


# --- Mesh sensitivity --------------------------------------------------------------------

# p99 / p99 at the finest factor (0.7), by stage and factor; soft skin at 0.3 in stage 1: 0.7.
RATIO = {1: {0.3: 0.8, 0.5: 1.1, 0.7: 1.0}, 2: {0.3: 0.9, 0.5: 0.95, 0.7: 1.0}}
# Stage 1 of group A loses its finest row; group B keeps only its finest row.
GROUP_A = {"wound_width_factor": 0.3, "wound_shape": "cylindrical", "skin_type": "normal"}
GROUP_B = {"wound_width_factor": 0.5, "wound_shape": "wedge", "skin_type": "soft"}


def _mesh_stress(df: pd.DataFrame, rng: np.random.Generator) -> np.ndarray:
    base = 10.0 + 7.0 * df["wound_width_factor"] + 3.0 * df["wound_aspect_factor"].fillna(1.0)
    base = base * np.where(df["skin_type"] == "soft", 0.6, 1.0) * (1 + df["stage"])
    f = df["mesh_size_factor"].to_numpy()
    stage = df["stage"].to_numpy()
    m = np.array([RATIO[s][x] for s, x in zip(stage, f)])
    m = np.where((stage == 1) & (f == 0.3) & (df["skin_type"] == "soft"), 0.7, m)

    def match(g: dict) -> np.ndarray:
        return np.logical_and.reduce([df[k].to_numpy() == v for k, v in g.items()])

    drop = (stage == 1) & (
        (match(GROUP_A) & (df["wound_aspect_factor"] == 0) & (f == 0.7))
        | (match(GROUP_B) & (f < 0.7))
    )
    return np.where(drop, 0.0, base * m)  # p99 = 0: not a used row


@pytest.fixture(scope="module")
def mesh_rows(tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:
    rd = tmp_path_factory.mktemp("mesh") / "run"
    write_store(rd, _mesh_stress, sweep=TINY, failed_fraction=0.0, stages=(1, 2))
    return _rows(rd)


def test_matched_groups_relative_differences_are_exact(mesh_rows: pd.DataFrame) -> None:
    ms = mesh_sensitivity(mesh_rows, {})
    assert ms["factors"] == [0.3, 0.5, 0.7]
    assert ms["left_out"]["1"] == {
        "finest_factor": 0.7,
        "groups": 12,
        "one_factor": 1,
        "no_finest_row": 1,
    }
    assert ms["left_out"]["2"]["one_factor"] == ms["left_out"]["2"]["no_finest_row"] == 0
    s1, s2 = ms["stages"]["1"], ms["stages"]["2"]
    # Stage 1: 10 groups; |diff| 0.1 (factor 0.5) x 10, 0.2 (normal, 0.3) x 5, 0.3 (soft) x 5.
    assert s1["groups"] == 10
    assert s1["median_abs_rel_diff"] == pytest.approx(0.15, rel=1e-12)
    assert s1["max_abs_rel_diff"] == pytest.approx(0.3, rel=1e-12)
    assert s1["by_factor"]["0.3"]["median_ratio"] == pytest.approx(0.75, rel=1e-12)
    assert s1["by_factor"]["0.3"]["rows"] == 10
    assert s1["by_factor"]["0.5"]["median_ratio"] == pytest.approx(1.1, rel=1e-12)
    assert s2["groups"] == 12
    assert s2["median_abs_rel_diff"] == pytest.approx(0.075, rel=1e-12)
    assert s2["max_abs_rel_diff"] == pytest.approx(0.1, rel=1e-12)
    text = "\n".join(report_lines(ms))
    assert "| 1 | 0.7 | 10 | 15.0% | 30.0% | 0.3: 0.750, 0.5: 1.100, 0.7: 1.000 |" in text
    assert "| 2 | 0.7 | 12 | 7.5% | 10.0% |" in text
    assert "No matched geometries" not in text


def test_mesh_figure_draws_groups_and_medians(mesh_rows: pd.DataFrame) -> None:
    ratios, _ = matched_ratios(mesh_rows)
    fig = mesh_ratio_figure(ratios)
    ax1 = fig.axes[0]
    assert ax1.get_title() == "stage 1 (10 groups)"
    assert len(ax1.collections[0].get_segments()) == 10
    x, y = ax1.lines[0].get_data()
    assert list(x) == [0.3, 0.5, 0.7]
    assert np.asarray(y) == pytest.approx([0.75, 1.1, 1.0], rel=1e-12)


def test_one_mesh_factor_says_no_matched_groups(tmp_path: Path) -> None:
    sweep = {**TINY, "grid": {**TINY["grid"], "mesh_size_factor": [0.5]}}
    write_store(tmp_path / "run", sweep=sweep, failed_fraction=0.0, stages=(1, 2))
    rows = _rows(tmp_path / "run")
    ms = mesh_sensitivity(rows, {})
    assert ms["stages"] == {} and matched_ratios(rows)[0].empty
    assert ms["left_out"]["1"]["one_factor"] == 12
    no = [ln for ln in report_lines(ms) if ln.startswith("No matched geometries")]
    assert no == [
        "No matched geometries: no rows equal but for `mesh_size_factor` hold two or more "
        "factors (factors in the rows: 0.5)."
    ]


def test_mesh_importance_rank_and_share() -> None:
    grouped = {"stage": 6.0, "mesh_size_factor": 2.0, "skin_type": 2.0, "wound_shape": 0.0}
    metrics = {
        "surrogate": {
            "importance": {
                "grouped": {g: {"total_gain": v} for g, v in grouped.items()},
                "shap": {"grouped": {**grouped, "mesh_size_factor": 0.0}},
            },
            "sensitivity": {"indices": {"stage": {"ST": 0.9}}},
        },
        "schemes": {},
    }
    imp = mesh_importance(metrics)
    assert imp["surrogate_total_gain"] == {"value": 2.0, "rank": 2, "of": 4, "share": 0.2}
    assert imp["surrogate_mean_abs_shap"]["rank"] is None
    assert imp["surrogate_sobol_total"] is None  # a fixed input has no Sobol index
    text = "\n".join(report_lines({"factors": [0.5], "importance": imp, "stages": {}}))
    assert "| surrogate, total gain | rank 2 of 4, 20.0% (2) |" in text
    assert "| surrogate, mean abs SHAP | not used (0; 4 parameters) |" in text
    assert "| surrogate, Sobol total index | fixed (one value) |" in text

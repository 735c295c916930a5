"""The stress model and ``predict`` on fusiform excisions (a synthetic store of excisions and
wedges): the excision's columns, the angle to the Langer line as a continuous value (the
answers at the two neighbouring trained orientations weighted linearly), the default mesh
size factor, and one-line refusals."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from synthetic_store import write_store

from woundsweep.analysis.data import encode_features
from woundsweep.analysis.prediction import angle_weights
from woundsweep.analysis.settings import FEATURES, FUSIFORM_FEATURES, model_features
from woundsweep.cli import main

# Excisions: 2 thicknesses x 3 lengths x 2 depths = 12 geometries; wedges: 2 x 2 = 4;
# each at 2 mesh size factors x 2 skin types x 4 orientations = 16 jobs: 256 jobs x 6 stages.
SWEEP = {
    "name": "fusiform-synthetic",
    "grid": {
        "dermal_thickness_mm": [1, 2],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [8],
        "wound_width_factor": [0.09],
        "mesh_size_factor": [0.3, 0.5],
        "skin_type": ["normal", "soft"],
        "orientation_deg": [0, 30, 60, 90],
    },
    "shapes": {
        "fusiform": {"wound_length_factor": [2.5, 3, 4], "wound_depth_factor": [0.6, 0.7]},
        "wedge": {"wound_depth_factor": [0.3, 0.5]},
    },
    "stages": {"closure_zone": {"y_fraction": 1, "depth_fraction": 0.5}},
    "solver": {"element_degree": 1},
}
FAST = ["--param", "n_estimators=40", "--param", "learning_rate=0.3",
        "--param", "early_stopping_rounds=5", "--param", "sobol_samples=256"]  # fmt: skip


def angle_stress(df: pd.DataFrame, rng: np.random.Generator) -> np.ndarray:
    """Highest across the Langer line (orientation 0), rising with the excision's length and
    the wedge's depth, a little with the stage; 1 % noise."""
    t = np.radians(df["orientation_deg"].to_numpy(dtype=float))
    length = df["wound_length_factor"].fillna(3.0).to_numpy()
    depth = df["wound_depth_factor"].to_numpy()
    return (
        10.0
        * (1.0 + 0.6 * np.cos(t) ** 2)
        * (1.0 + 0.2 * (length - 3.0))
        * np.exp(depth)
        * (1.0 + 0.05 * (df["stage"].to_numpy() - 1))
        * rng.lognormal(0.0, 0.01, len(df))
    )


@pytest.fixture(scope="module")
def analyzed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("fusiform-model") / "run"
    write_store(rd, angle_stress, sweep=SWEEP, seed=5, failed_fraction=0.0)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["analyze", str(rd), *FAST, "--no-figures"]) == 0
    return rd


EXCISION = {
    "--shape": "fusiform", "--dermal-thickness": "1", "--subcutis-thickness-factor": "1",
    "--patch-size-factor": "8", "--wound-width-factor": "0.09", "--wound-length-factor": "3",
    "--wound-depth-factor": "0.7", "--skin-type": "normal", "--stage": "2",
}  # fmt: skip


def args(**change: str | None) -> list[str]:
    opts = {**EXCISION, **{"--" + k.replace("_", "-"): v for k, v in change.items()}}
    return [a for k, v in opts.items() if v is not None for a in (k, v)]


def answer(run_main, rd: Path, *argv: str) -> dict:
    rc, out, err = run_main("predict", rd, *argv, "--json")
    assert rc == 0, err
    return json.loads(out)


def assert_refused(rc: int, err: str, needle: str) -> None:
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("woundsweep: error:"), err
    assert needle in lines[0], lines[0]


def test_the_excisions_columns_enter_only_with_excisions(analyzed: Path) -> None:
    meta = json.loads((analyzed / "analysis" / "model_geometry_meta.json").read_text())
    assert meta["features"] == list(FUSIFORM_FEATURES)
    assert meta["shape_codes"]["fusiform"] == 2.0
    assert meta["levels"]["fusiform"]["wound_length_factor"] == [2.5, 3.0, 4.0]
    assert meta["levels"]["fusiform"]["orientation_deg"] == [0.0, 30.0, 60.0, 90.0]
    assert "wound_length_factor" not in meta["ranges"]["wedge"]
    assert model_features(["wedge", "cylindrical"]) == FEATURES
    rows = pd.DataFrame(
        {
            "wound_shape": ["wedge", "fusiform"],
            **{f: [1.0, 1.0] for f in FUSIFORM_FEATURES if f not in ("wound_shape", "skin_type")},
            "skin_type": ["soft", "soft"],
            "wound_aspect_factor": [np.nan, np.nan],
        }
    )
    rows.loc[0, "wound_length_factor"] = np.nan
    X = encode_features(rows, {"soft": 10.7})
    assert X.shape == (2, len(FEATURES) + 1)
    assert X[:, FUSIFORM_FEATURES.index("wound_shape")].tolist() == [1.0, 2.0]
    assert encode_features(rows.iloc[:1], {"soft": 10.7}).shape == (1, len(FEATURES))
    m = json.loads((analyzed / "analysis" / "metrics.json").read_text())
    assert "wound_length_factor" in m["surrogate"]["sensitivity"]["inputs"]


def test_angle_weights_by_hand() -> None:
    meta = {"levels": {"fusiform": {"orientation_deg": [0.0, 30.0, 60.0, 90.0]}}}
    # Linear in cos 2t: cos 120 = -1/2, cos 130 = -0.6428, cos 180 = -1.
    w90 = (math.cos(math.radians(130)) + 0.5) / (-1 + 0.5)
    assert w90 == pytest.approx(0.2856, abs=1e-4)
    assert angle_weights(meta, "fusiform", 65.0) == [
        (60.0, pytest.approx(1 - w90)),
        (90.0, pytest.approx(w90)),
    ]
    # Across a multiple of 90 deg cos 2t turns back: linear in the angle there.
    wide = {"levels": {"fusiform": {"orientation_deg": [45.0, 135.0]}}}
    assert angle_weights(wide, "fusiform", 60.0) == [
        (45.0, pytest.approx(5 / 6)),
        (135.0, pytest.approx(1 / 6)),
    ]
    assert angle_weights(meta, "fusiform", 30.0) == [(30.0, 1.0)]
    assert angle_weights(meta, "fusiform", 0.0) == [(0.0, 1.0)]
    assert angle_weights({"levels": {}}, "fusiform", 65.0) == [(65.0, 1.0)]


def test_the_angle_to_the_langer_line_is_answered_linearly_in_cos_2t_between_trained_angles(
    analyzed: Path, run_main
) -> None:
    at = {a: answer(run_main, analyzed, *args(angle_to_langer=str(a))) for a in (0, 25, 30)}
    by_orientation = answer(run_main, analyzed, *args(orientation="65"))
    assert by_orientation["predictions"] == at[25]["predictions"]
    assert at[25]["orientation_deg"] == 65.0 and at[25]["angle_to_langer_deg"] == 25.0
    # Angle 25 = orientation 65, weighted linearly in cos 2t between orientation 60 (angle
    # 30, cos 2t = -1/2) and 90 (angle 0, cos 2t = -1).
    w0 = (math.cos(math.radians(130)) + 0.5) / (-1 + 0.5)
    assert at[25]["orientation_weights"] == [
        [60.0, pytest.approx(1 - w0)],
        [90.0, pytest.approx(w0)],
    ]
    (p0,), (p25,), (p30,) = (at[a]["predictions"] for a in (0, 25, 30))
    log_mix = (1 - w0) * math.log(p30["stress_kPa"]) + w0 * math.log(p0["stress_kPa"])
    assert p25["stress_kPa"] == pytest.approx(math.exp(log_mix), rel=1e-9)
    mix = (1 - w0) * np.array(p30["probabilities"]) + w0 * np.array(p0["probabilities"])
    assert p25["probabilities"] == pytest.approx(mix.tolist(), abs=1e-12)
    assert p25["quantile"] == int(np.argmax(mix)) + 1
    lo, hi = p25["interval_kPa"]
    assert math.sqrt(lo * hi) == pytest.approx(p25["stress_kPa"], rel=1e-9)
    assert any("orientation_deg=65 (interpolated between trained values 60 and 90)" in f
               for f in at[25]["interpolated"])  # fmt: skip
    assert at[30]["interpolated"] == [] and at[30]["orientation_weights"] == [[60.0, 1.0]]
    # Continuous: close to each trained angle's answer next to it, monotone in between
    # (the synthetic stress falls as the axis turns toward the Langer line).
    fine = [
        answer(run_main, analyzed, *args(angle_to_langer=f"{a:g}"))["predictions"][0]["stress_kPa"]
        for a in (29.999, 20, 10, 0.001)
    ]
    assert fine[0] == pytest.approx(p30["stress_kPa"], rel=1e-4)
    assert fine[-1] == pytest.approx(p0["stress_kPa"], rel=1e-4)
    assert fine == sorted(fine, reverse=True) and p30["stress_kPa"] > p0["stress_kPa"]


def test_the_mesh_size_factor_defaults_to_the_finest_trained(analyzed: Path, run_main) -> None:
    a = answer(run_main, analyzed, *args(angle_to_langer="45"))
    assert a["mesh_size_factor"] == 0.5 and a["mesh_size_factor_default"] is True
    b = answer(run_main, analyzed, *args(angle_to_langer="45"), "--mesh-size-factor", "0.5")
    assert b["predictions"] == a["predictions"] and b["mesh_size_factor_default"] is False
    rc, out, err = run_main("predict", analyzed, *args(angle_to_langer="45"))
    assert rc == 0, err
    assert "angle to the Langer line 45 deg" in out
    assert "mesh_size_factor 0.5 (the finest trained, none given)" in out


@pytest.mark.parametrize(
    ("change", "extra", "needle"),
    [
        ({"angle_to_langer": "95"}, [], "95"),
        ({"angle_to_langer": "-1"}, [], "-1"),
        ({"angle_to_langer": "30"}, ["--orientation", "60"], "exactly one of --orientation"),
        ({}, [], "exactly one of --orientation"),
        ({"angle_to_langer": "30", "wound_length_factor": None}, [], "needs wound_length_factor"),
        ({"angle_to_langer": "30"}, ["--wound-aspect-factor", "0.1"], "wound_aspect_factor does not apply"),
        ({"angle_to_langer": "30", "wound_length_factor": "5"}, [], "wound_length_factor=5 (trained on 2.5..4)"),
        ({"angle_to_langer": "30", "skin_type": "stiff"}, [], "skin type 'stiff' was not in the training data"),
    ],
)  # fmt: skip
def test_bad_predictions_are_one_line(
    analyzed: Path, run_main, change: dict, extra: list[str], needle: str
) -> None:
    rc, _, err = run_main("predict", analyzed, *args(**change), *extra)
    assert_refused(rc, err, needle)


def test_a_trench_model_refuses_an_excision(tmp_path: Path, run_main) -> None:
    sweep = {**SWEEP, "shapes": {"wedge": {"wound_depth_factor": [0.3, 0.5, 0.7]}}}
    sweep["grid"] = {**SWEEP["grid"], "dermal_thickness_mm": [1, 1.5, 2, 3]}
    rd = tmp_path / "run"
    write_store(rd, angle_stress, sweep=sweep, seed=1, failed_fraction=0.0)
    rc, _, err = run_main("analyze", rd, "--split", "geometry", *FAST, "--no-figures")
    assert rc == 0, err
    meta = json.loads((rd / "analysis" / "model_geometry_meta.json").read_text())
    assert meta["features"] == list(FEATURES)
    rc, _, err = run_main("predict", rd, *args(angle_to_langer="30"), "--allow-extrapolation")
    assert_refused(rc, err, "trained without fusiform wounds")


@pytest.mark.parametrize(
    ("path", "jobs", "geometries", "angles"),
    [
        ("sweeps/fusiform.yaml", 252, 12, list(range(0, 91, 15))),
        ("tests/data/fusiform-small.yaml", 144, 12, [0, 30, 60, 90]),
    ],
)
def test_the_fusiform_sweeps_expand_as_their_headers_say(
    path: str, jobs: int, geometries: int, angles: list[int]
) -> None:
    from cli_run import ROOT

    from woundsweep.config.manifest import expand
    from woundsweep.config.sweep import load_sweep

    sweep = load_sweep(ROOT / path)
    m = expand(sweep)
    assert len(m) == jobs and m["geometry_id"].nunique() == geometries
    assert sorted(m["orientation_deg"].unique()) == angles
    assert set(m["skin_type"]) == {"normal", "stiff", "soft"}
    assert sorted(m["wound_length_factor"].unique()) == [2.5, 3.0, 4.0]
    # The far field: a margin of at least 2.7 excision lengths around every excision.
    assert (m["patch_half_length_mm"] / m["wound_length_mm"]).min() >= 2.7
    assert f"{jobs} jobs" in (ROOT / path).read_text()


def test_positions_along_the_excision_are_scaled_by_its_patch() -> None:
    from woundsweep.analysis.paper import normalised_locations

    # A trench (L = 10) and an excision (L = 10, l = 8: its patch spans y in [-14, 14]), both
    # with the maximum at y = 7, x = w/2 + 5, z = -1.
    rows = pd.DataFrame(
        {
            "patch_half_length_mm": [10.0, 10.0],
            "wound_width_mm": [2.0, 2.0],
            "wound_length_mm": [np.nan, 8.0],
            "total_thickness_mm": [4.0, 4.0],
            "stage": [2, 2],
            "max_location_x_mm": [6.0, 6.0],
            "max_location_y_mm": [7.0, 7.0],
            "max_location_z_mm": [-1.0, -1.0],
        }
    )
    locs = normalised_locations(rows)
    assert locs["y_along"].tolist() == pytest.approx([17 / 20, 21 / 28])
    assert locs["x_across"].tolist() == pytest.approx([5 / 11, 5 / 11])
    assert locs["z_depth"].tolist() == pytest.approx([0.25, 0.25])

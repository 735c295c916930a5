"""Random designs (a sweep's ``sample`` section): exact counts, reproducible draws within their
ranges, the refusals, and the sweeps/paper-random-*.yaml sets."""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import yaml
from cli_run import PAPER

from woundsweep.config.manifest import count_jobs, expand, load_run
from woundsweep.config.sweep import load_sweep, parse_sweep
from woundsweep.core.errors import SweepError

SKINS = ["normal", "stiff", "soft"]
RANGES = {
    "dermal_thickness_mm": [0.5, 4],
    "subcutis_thickness_factor": [0.5, 2],
    "patch_size_factor": [1, 3],
    "wound_width_factor": [0.3, 0.8],
    "orientation_deg": [0, 90],
    "wound_aspect_factor": [0, 0.2],
    "wound_depth_factor": [0.3, 0.7],
}
LOG = ["dermal_thickness_mm", "subcutis_thickness_factor"]


def _doc(geometries: int = 10, seed: int = 1, **extra: Any) -> dict[str, Any]:
    """A sampled sweep over the paper grid's ranges on a coarse mesh (no exclusion rule)."""
    grid = {k: RANGES[k] for k in list(RANGES)[:4]}
    grid |= {"mesh_size_factor": [0.3], "skin_type": SKINS, "orientation_deg": [0, 90]}
    return {
        "grid": copy.deepcopy(grid),
        "shapes": {
            "cylindrical": {"wound_aspect_factor": [0, 0.2]},
            "wedge": {"wound_depth_factor": [0.3, 0.7]},
        },
        "sample": {"geometries": geometries, "seed": seed, "log_axes": list(LOG)},
        **extra,
    }


def _expand(doc: dict[str, Any]) -> pd.DataFrame:
    return expand(parse_sweep(doc))


WIDE = "wound_width_factor * patch_size_factor > 1"  # w > T: rejects about a third of draws


def test_job_counts_are_exact_with_and_without_rejections() -> None:
    free = _expand(_doc())
    assert len(free) == count_jobs(parse_sweep(_doc())) == 2 * 10 * 3
    # Without the rule some draws are wide wounds, so the rule below must reject draws.
    assert (free["wound_width_factor"] * free["patch_size_factor"] > 1).sum() >= 3
    doc = _doc(exclude=[WIDE])
    kept = _expand(doc)
    assert len(kept) == count_jobs(parse_sweep(doc)) == 60
    assert (kept["wound_width_factor"] * kept["patch_size_factor"] <= 1).all()
    assert kept.groupby("wound_shape")["geometry_id"].nunique().to_dict() == {
        "cylindrical": 10,
        "wedge": 10,
    }
    assert kept["job_index"].tolist() == list(range(60)) and kept["job_id"].is_unique
    # Only the skin types' list multiplies the jobs; the other axes are drawn.
    one_skin = _doc()
    one_skin["grid"]["skin_type"] = ["stiff"]
    assert len(_expand(one_skin)) == count_jobs(parse_sweep(one_skin)) == 20


def test_rules_that_reject_every_draw_are_refused_in_one_line() -> None:
    with pytest.raises(SweepError, match="reject nearly every draw") as err:
        _expand(_doc(exclude=["dermal_thickness_mm > 0.51"]))
    assert "\n" not in str(err.value) and err.value.key == "sample"


def test_max_jobs_counts_the_sampled_jobs() -> None:
    with pytest.raises(SweepError, match="the sample has 60 jobs, above the limit of 59"):
        expand(parse_sweep(_doc()), max_jobs=59)
    assert len(expand(parse_sweep(_doc()), max_jobs=60)) == 60


def test_a_seed_gives_one_manifest() -> None:
    a, b, c = _expand(_doc(seed=7)), _expand(_doc(seed=7)), _expand(_doc(seed=8))
    pd.testing.assert_frame_equal(a, b)
    assert not set(a["job_id"]) & set(c["job_id"])
    # The YAML's key order is not part of the draw.
    rev = _doc(seed=7)
    rev["grid"] = dict(reversed(list(rev["grid"].items())))
    pd.testing.assert_frame_equal(_expand(rev), a)


def test_draws_lie_in_their_ranges_at_four_significant_digits() -> None:
    df = _expand(_doc(geometries=50, exclude=[WIDE]))
    for name, (low, high) in RANGES.items():
        values = df[name].dropna()
        assert len(values) > 0, name
        assert ((values >= low) & (values <= high)).all(), name
        assert all(float(f"{v:.4g}") == v for v in values), name
        assert values.nunique() > 40, name  # drawn, not fixed
    assert (df["mesh_size_factor"] == 0.3).all()
    # The shapes' own factors: NaN for the other shape, as in a grid's manifest.
    assert df.loc[df["wound_shape"] == "wedge", "wound_aspect_factor"].isna().all()
    assert df.loc[df["wound_shape"] == "cylindrical", "wound_depth_factor"].isna().all()


def test_a_log_axis_is_log_uniform() -> None:
    """Over 2,000 draws the median of a log axis is near its bounds' geometric mean (its
    standard error is under 2 %); a uniform axis' near their arithmetic mean."""
    doc = _doc(geometries=2000, seed=3)
    doc["shapes"] = {"wedge": {"wound_depth_factor": [0.3, 0.7]}}
    doc["grid"]["skin_type"] = ["normal"]
    geo = _expand(doc)
    td = geo["dermal_thickness_mm"].median()
    assert td == pytest.approx(math.sqrt(0.5 * 4), rel=0.1)  # 1.41; uniform would give 2.25
    fs = geo["subcutis_thickness_factor"].median()
    assert fs == pytest.approx(1.0, rel=0.1)  # uniform: 1.25
    assert geo["patch_size_factor"].median() == pytest.approx(2.0, rel=0.1)
    assert np.log(geo["dermal_thickness_mm"]).std() == pytest.approx(
        math.log(8) / math.sqrt(12), rel=0.1
    )


def test_each_geometry_has_every_skin_type_each_job_its_own_orientation() -> None:
    df = _expand(_doc(geometries=20, exclude=[WIDE]))
    for _, jobs in df.groupby("geometry_id", sort=False):
        assert jobs["skin_type"].tolist() == SKINS
        assert jobs["job_index"].diff().dropna().eq(1).all()  # consecutive
        assert jobs["orientation_deg"].nunique() == 3
        geometry = jobs.drop(columns=["job_index", "job_id", "skin_type", "orientation_deg"])
        assert len(geometry.drop_duplicates()) == 1
    # Shapes sorted, geometry-major.
    assert df["wound_shape"].tolist() == ["cylindrical"] * 60 + ["wedge"] * 60
    # A fixed orientation is every job's.
    fixed = _doc()
    fixed["grid"]["orientation_deg"] = [30]
    assert set(_expand(fixed)["orientation_deg"]) == {30.0}


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(doc: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        node = doc
        for k in parents:
            node = node[k]
        if value is None:
            del node[last]
        else:
            node[last] = value

    return edit


@pytest.mark.parametrize(
    ("edit", "key", "message"),
    [
        (_set("grid.patch_size_factor", [1, 2, 3]), "grid.patch_size_factor", "one value or a"),
        (
            _set("shapes.wedge.wound_depth_factor", [0.3, 0.5, 0.7]),
            "shapes.wedge.wound_depth_factor",
            "one value or a",
        ),
        (_set("grid.wound_width_factor", [0.8, 0.3]), "grid.wound_width_factor", "low < high"),
        (_set("grid.orientation_deg", [90, 0]), "grid.orientation_deg", "low < high"),
        (_set("grid.patch_size_factor", [2, 2]), "grid.patch_size_factor", "duplicate"),
        (
            _set("sample.log_axes", ["wound_aspect_factor"]),
            "shapes.cylindrical.wound_aspect_factor",
            "positive bounds",
        ),
        (_set("sample.log_axes", ["mesh_size_factor"]), "grid.mesh_size_factor", "range"),
        (_set("sample.log_axes", ["skin_type"]), "sample.log_axes", "unknown axis"),
        (_set("sample.log_axes", "dermal_thickness_mm"), "sample.log_axes", "list"),
        (_set("sample.method", "lhs"), "sample.method", "unknown key"),
        (_set("sample.seed", None), "sample.seed", "missing"),
        (_set("sample.seed", -1), "sample.seed", "from 0"),
        (_set("sample.seed", 1.5), "sample.seed", "integer"),
        (_set("sample.geometries", None), "sample.geometries", "missing"),
        (_set("sample.geometries", 0), "sample.geometries", "from 1"),
        (_set("sample.geometries", 10**7), "sample.geometries", "1000000"),
        (_set("sample.geometries", True), "sample.geometries", "integer"),
        (_set("sample", [24, 1]), "sample", "mapping"),
    ],
)
def test_bad_designs_are_refused_naming_the_key(
    edit: Callable[[dict[str, Any]], None], key: str, message: str
) -> None:
    doc = _doc()
    edit(doc)
    with pytest.raises(SweepError, match=message) as err:
        parse_sweep(doc)
    assert err.value.key == key


def test_the_design_is_part_of_the_resolved_sweep() -> None:
    assert parse_sweep(_doc(seed=1)).resolved() != parse_sweep(_doc(seed=2)).resolved()
    assert parse_sweep(_doc()).resolved()["sample"] == {
        "geometries": 10,
        "seed": 1,
        "log_axes": LOG,
    }
    assert "sample" not in load_sweep(PAPER).resolved()
    # The result's settings (its fingerprint) do not hold it: a job's result is its own.
    assert "sample" not in parse_sweep(_doc()).settings_dict()


def test_generate_writes_a_sampled_manifest_load_run_accepts(
    tmp_path: Path, run_main: Callable[..., tuple[int, str, str]]
) -> None:
    path, rd = tmp_path / "random.yaml", tmp_path / "run"
    path.write_text(yaml.safe_dump(_doc(exclude=[WIDE], name="random")))
    rc, out, err = run_main("generate", path, "--out", rd)
    assert (rc, err) == (0, "") and out.startswith("60 jobs written")
    run = load_run(rd)
    pd.testing.assert_frame_equal(run.manifest, expand(load_sweep(path)))
    assert run.sweep.sample is not None and run.sweep.sample.seed == 1
    assert run.geometry(run.job(59)).shape == "wedge"
    assert run_main("generate", path, "--out", rd)[1].endswith("nothing to do\n")
    # Another seed is another sweep: refused over the run unless --force.
    path.write_text(yaml.safe_dump(_doc(seed=2, exclude=[WIDE], name="random")))
    rc, out, err = run_main("generate", path, "--out", rd)
    assert rc != 0 and "different sweep" in err
    assert run_main("generate", path, "--out", rd, "--force")[0] == 0
    assert set(load_run(rd).manifest["job_id"]).isdisjoint(run.manifest["job_id"])


def test_paper_random_sweeps_span_the_paper_grid() -> None:
    """sweeps/paper-random-{1,2}.yaml: the paper grid's full ranges on its finest mesh, the
    settings and rule of the between sets, 24 geometries per shape, seeds 1 and 2."""
    paper = load_sweep(PAPER)
    between = load_sweep(PAPER.parent / "paper-between-calibration.yaml")
    manifests = []
    for seed in (1, 2):
        sweep = load_sweep(PAPER.parent / f"paper-random-{seed}.yaml")
        assert sweep.sample is not None
        assert (sweep.sample.geometries, sweep.sample.seed) == (24, seed)
        assert set(sweep.sample.log_axes) == set(LOG)
        for k in ("materials", "stages", "solver", "analysis", "exclude"):
            assert getattr(sweep, k) == getattr(between, k), k
        for name, values in paper.grid.items():
            if name == "skin_type":
                assert sweep.grid[name] == values
            elif name == "mesh_size_factor":
                assert sweep.grid[name] == [max(values)]
            else:
                assert sweep.grid[name] == [min(values), max(values)], name
        for shape, axes in paper.shapes.items():
            for name, values in axes.items():
                assert sweep.shapes[shape][name] == [min(values), max(values)]
        manifest = expand(sweep)
        assert len(manifest) == count_jobs(sweep) == 144
        assert (manifest["wound_width_mm"] <= manifest["total_thickness_mm"]).all()
        manifests.append(manifest)
    assert set(manifests[0]["job_id"]).isdisjoint(manifests[1]["job_id"])

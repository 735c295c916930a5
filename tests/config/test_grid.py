"""Sweep expansion: exact counts of the paper grid, derived lengths, pinned content hashes."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import pandas as pd
import pytest
import yaml
from cli_run import DEMO, PAPER

from woundsweep.config.manifest import expand
from woundsweep.config.solver import SolverSettings
from woundsweep.config.sweep import MANIFEST_COLUMNS, load_sweep, parse_sweep
from woundsweep.core.errors import SweepError


def test_paper_grid_counts(paper: pd.DataFrame) -> None:
    assert len(paper) == 11_664
    assert list(paper.columns) == list(MANIFEST_COLUMNS)
    assert paper["job_index"].tolist() == list(range(11_664))
    assert paper["job_id"].is_unique
    geo = paper.drop_duplicates("geometry_id")
    assert len(geo) == 1_296
    assert geo["wound_shape"].value_counts().to_dict() == {"cylindrical": 648, "wedge": 648}
    # Every geometry carries exactly the 3 skin types x 3 orientations, consecutively.
    per_geo = paper.groupby("geometry_id").agg(
        n=("job_id", "size"),
        skins=("skin_type", lambda s: frozenset(s)),
        angles=("orientation_deg", lambda s: frozenset(s)),
        span=("job_index", lambda s: s.max() - s.min()),
    )
    assert (per_geo["n"] == 9).all()
    assert (per_geo["skins"] == frozenset({"normal", "stiff", "soft"})).all()
    assert (per_geo["angles"] == frozenset({0.0, 45.0, 90.0})).all()
    assert (per_geo["span"] == 8).all()


def test_paper_grid_exclusion_keeps_six_width_pairs(paper: pd.DataFrame) -> None:
    pairs = set(
        map(tuple, paper[["patch_size_factor", "wound_width_factor"]].drop_duplicates().values)
    )
    # w = f_w * f_p * T > T  <=>  f_w * f_p > 1: (2, 0.8), (3, 0.5), (3, 0.8) are dropped.
    assert pairs == {(1, 0.3), (1, 0.5), (1, 0.8), (2, 0.3), (2, 0.5), (3, 0.3)}
    assert (paper["wound_width_mm"] <= paper["total_thickness_mm"]).all()
    # 4 dermal x 3 subcutis x 6 pairs x 3 mesh x 3 shape values per shape = 648.
    for shape, col in (("cylindrical", "wound_aspect_factor"), ("wedge", "wound_depth_factor")):
        sub = paper[paper["wound_shape"] == shape]
        assert sorted(sub[col].unique()) == (
            [0.0, 0.1, 0.2] if shape == "cylindrical" else [0.3, 0.5, 0.7]
        )
        other = "wound_depth_factor" if shape == "cylindrical" else "wound_aspect_factor"
        assert sub[other].isna().all()


def _one(df: pd.DataFrame, **kw: object) -> pd.Series:
    mask = pd.Series(True, index=df.index)
    for k, v in kw.items():
        mask &= df[k] == v
    rows = df[mask]
    assert len(rows) == 1, kw
    return rows.iloc[0]


def test_derived_lengths_hand_checked(paper: pd.DataFrame) -> None:
    common = dict(dermal_thickness_mm=2.0, subcutis_thickness_factor=2.0, patch_size_factor=3.0,
                  wound_width_factor=0.3, mesh_size_factor=0.5, skin_type="soft", orientation_deg=45.0)  # fmt: skip
    cyl = _one(paper, wound_shape="cylindrical", wound_aspect_factor=0.2, **common)
    # t_s = 2*2 = 4, T = 6, L = 3*6 = 18, w = 0.3*18 = 5.4; R = sqrt(2.7^2 + 1.08^2).
    assert cyl.subcutis_thickness_mm == pytest.approx(4.0)
    assert cyl.total_thickness_mm == pytest.approx(6.0)
    assert cyl.patch_half_length_mm == pytest.approx(18.0)
    assert cyl.wound_width_mm == pytest.approx(5.4)
    assert cyl.wound_depth_mm == pytest.approx(math.sqrt(7.29 + 1.1664) - 1.08)
    wedge = _one(paper, wound_shape="wedge", wound_depth_factor=0.7, **common)
    assert wedge.wound_depth_mm == pytest.approx(0.7 * 6.0)
    # a = 0: a half cylinder, depth = w/2. t_d = 0.5, f_s = 0.5: T = 0.75, L = 0.75, w = 0.375.
    half = _one(paper, wound_shape="cylindrical", wound_aspect_factor=0.0, dermal_thickness_mm=0.5,
                subcutis_thickness_factor=0.5, patch_size_factor=1.0, wound_width_factor=0.5,
                mesh_size_factor=0.3, skin_type="normal", orientation_deg=0.0)  # fmt: skip
    assert half.wound_width_mm == pytest.approx(0.375)
    assert half.wound_depth_mm == pytest.approx(0.1875)


def test_job_ids_pinned(paper: pd.DataFrame) -> None:
    # The canonical form: sorted keys, floats, no spaces; the id is sha256's first 16 hex digits.
    canon0 = ('{"dermal_thickness_mm":0.5,"mesh_size_factor":0.3,"orientation_deg":0.0,'
              '"patch_size_factor":1.0,"skin_type":"normal","subcutis_thickness_factor":0.5,'
              '"wound_aspect_factor":0.0,"wound_shape":"cylindrical","wound_width_factor":0.3}')  # fmt: skip
    job0 = paper.iloc[0]
    assert job0.job_id == hashlib.sha256(canon0.encode()).hexdigest()[:16] == "52a5128ae5292088"
    canon_geo = canon0.replace('"orientation_deg":0.0,', "").replace('"skin_type":"normal",', "")
    assert job0.geometry_id == hashlib.sha256(canon_geo.encode()).hexdigest()[:16]
    last = paper.iloc[-1]
    assert (last.wound_shape, last.dermal_thickness_mm, last.skin_type, last.orientation_deg) == (
        "wedge", 4.0, "soft", 90.0)  # fmt: skip
    canon_last = ('{"dermal_thickness_mm":4.0,"mesh_size_factor":0.7,"orientation_deg":90.0,'
                  '"patch_size_factor":3.0,"skin_type":"soft","subcutis_thickness_factor":2.0,'
                  '"wound_depth_factor":0.7,"wound_shape":"wedge","wound_width_factor":0.3}')  # fmt: skip
    assert last.job_id == hashlib.sha256(canon_last.encode()).hexdigest()[:16] == "c45bfa4174e69c6c"


def _reverse(obj: object) -> object:
    if isinstance(obj, dict):
        return {k: _reverse(obj[k]) for k in reversed(list(obj))}
    return obj


def test_key_order_does_not_change_ids(paper: pd.DataFrame, tmp_path: Path) -> None:
    data = yaml.safe_load(PAPER.read_text())
    rev = tmp_path / "reversed.yaml"
    rev.write_text(yaml.safe_dump(_reverse(data), sort_keys=False))
    assert list(yaml.safe_load(rev.read_text())["grid"])[0] == "orientation_deg"
    again = expand(load_sweep(rev))
    pd.testing.assert_frame_equal(again, paper)


def test_integer_and_float_values_hash_alike() -> None:
    data = yaml.safe_load(DEMO.read_text())
    a = expand(parse_sweep(data))
    data["grid"]["dermal_thickness_mm"] = [1.0, 2.0]
    data["grid"]["orientation_deg"] = [0.0]
    b = expand(parse_sweep(data))
    assert a["job_id"].tolist() == b["job_id"].tolist()


def test_demo_sweep_is_small_and_mixed() -> None:
    demo = expand(load_sweep(DEMO))
    assert 20 <= len(demo) <= 40
    assert set(demo["wound_shape"]) == {"cylindrical", "wedge"}
    assert demo["skin_type"].nunique() == 2
    assert len(demo) == demo["geometry_id"].nunique() * 2


def test_settings_defaults_are_table_2() -> None:
    s = load_sweep(DEMO)
    stiff = s.materials.skin_types["stiff"]
    assert stiff.c_kPa == 42.6 and stiff.tsf == 1.05 and stiff.mu_kPa == (35.6, 11.8, 11.8)
    assert s.materials.to_dict()["subcutis"] == {"C10_kPa": 0.4, "C20_kPa": 1.4, "K_kPa": 50.0}
    assert s.stages.contact_penalty_GPa == (1.0, 5.0, 100.0)
    # The demo states the paper's element, which is the default.
    assert s.solver.element_degree == load_sweep(PAPER).solver.element_degree == 2
    assert SolverSettings().element_degree == 2 and s.solver.newton.max_iterations == 60
    # The paper file spells out the same values as the defaults.
    assert load_sweep(PAPER).materials == s.materials
    assert load_sweep(PAPER).stages == s.stages


def test_a_stage_key_outside_the_schema_is_unknown() -> None:
    data = yaml.safe_load(Path(DEMO).read_text())
    data["stages"] = {"contact_model": "smooth"}
    with pytest.raises(SweepError) as err:
        parse_sweep(data)
    assert str(err.value).endswith(
        "stages.contact_model: unknown key (expected one of "
        "['closure_load', 'closure_zone', 'contact_penalty_GPa'])"
    )


@pytest.mark.parametrize(
    ("stages", "message"),
    [
        ({"closure_load": "smooth"}, "stages.closure_load: unknown closing load 'smooth'"),
        ({"closure_load": 3}, "stages.closure_load: expected a name, got 3"),
        ({"closure_zone": {"depth_per_w": -1}}, "closure_zone.depth_per_w: expected a positive"),
        ({"closure_zone": {"y_fraction": 1.5}}, "closure_zone.y_fraction: expected a fraction"),
    ],
)
def test_bad_stage_settings_are_named(stages: dict, message: str) -> None:
    data = yaml.safe_load(Path(DEMO).read_text())
    data["stages"] = stages
    with pytest.raises(SweepError, match=message.replace("(", r"\(")):
        parse_sweep(data)


def test_paper_code_preset_is_the_paper_grid_with_the_code_closure() -> None:
    """sweeps/paper-code.yaml differs from sweeps/paper.yaml in its stages only: the same jobs
    (ids and parameters) with the published code's zone and closing load."""
    from woundsweep.config.manifest import expand
    from woundsweep.config.paper import ClosureZone, StageSettings

    paper, code = load_sweep(PAPER), load_sweep(PAPER.parent / "paper-code.yaml")
    assert code.stages == StageSettings.paper_code()
    assert code.stages.closure_zone == ClosureZone(0.5, 0.5, 0.35)
    assert (paper.grid, paper.shapes, paper.exclude) == (code.grid, code.shapes, code.exclude)
    assert (paper.materials, paper.solver) == (code.materials, code.solver)
    a, b = expand(paper), expand(code)
    assert len(a) == len(b) == 11664
    assert a["job_id"].tolist() == b["job_id"].tolist()
    # The zone's depth follows the width: 0.35 w, capped at the wound's depth.
    zone = code.stages.closure_zone
    assert zone.depth_fraction_for(1.0, 0.7) == pytest.approx(0.5)
    assert zone.depth_fraction_for(2.0, 0.5) == 1.0


def test_paper_code_slice_is_every_wound_of_the_grid_once() -> None:
    """sweeps/paper-code-slice.yaml: the paper-code preset's jobs at t_d = 1 mm and mesh factor
    0.5 (the same ids), one job per combination of the other factors: 972 of 11,664."""
    from woundsweep.config.manifest import expand

    code, cut = (
        load_sweep(PAPER.parent / "paper-code.yaml"),
        load_sweep(PAPER.parent / "paper-code-slice.yaml"),
    )
    assert (cut.stages, cut.materials, cut.solver) == (code.stages, code.materials, code.solver)
    full, part = expand(code), expand(cut)
    on = full[(full["dermal_thickness_mm"] == 1) & (full["mesh_size_factor"] == 0.5)]
    assert len(part) == len(on) == 972
    assert sorted(part["job_id"]) == sorted(on["job_id"])
    factors = [
        "wound_shape", "subcutis_thickness_factor", "patch_size_factor", "wound_width_factor",
        "wound_depth_factor", "wound_aspect_factor", "skin_type", "orientation_deg",
    ]  # fmt: skip
    assert not part[factors].astype(str).duplicated().any()
    assert len(full[factors].astype(str).drop_duplicates()) == 972


def test_between_sweeps_lie_between_the_paper_grid_values() -> None:
    """sweeps/paper-between-{calibration,test}.yaml: the paper's settings, every factor strictly
    inside the grid's range and on none of its values, the two sets on different values, and
    at least 100 jobs each (the surrogate's off-grid calibration and test)."""
    from woundsweep.config.manifest import expand

    paper = load_sweep(PAPER)
    sets = {
        k: load_sweep(PAPER.parent / f"paper-between-{k}.yaml") for k in ("calibration", "test")
    }
    factors = [
        "dermal_thickness_mm", "subcutis_thickness_factor", "patch_size_factor",
        "wound_width_factor", "orientation_deg",
    ]  # fmt: skip
    for sweep in sets.values():
        assert (sweep.materials, sweep.solver, sweep.stages) == (
            paper.materials,
            paper.solver,
            paper.stages,
        )
        assert sweep.exclude == paper.exclude
        assert len(expand(sweep)) >= 100
        for name in factors:
            grid = paper.grid[name]
            for v in sweep.grid[name]:
                assert min(grid) < v < max(grid) and v not in grid, (name, v)
        for shape, axes in sweep.shapes.items():
            for name, values in axes.items():
                grid = paper.shapes[shape][name]
                assert all(min(grid) < v < max(grid) and v not in grid for v in values)
        assert sweep.grid["mesh_size_factor"] == [max(paper.grid["mesh_size_factor"])]
    cal, test = sets["calibration"], sets["test"]
    for name in factors:
        assert not set(cal.grid[name]) & set(test.grid[name]), name

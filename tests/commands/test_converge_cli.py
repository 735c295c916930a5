"""`woundsweep converge` and the solve outputs of the zone issue on a tiny job (DOLFINx)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_run import generate_run

from woundsweep.studies.gci import fit_study, grid_study

SWEEP = {
    "name": "converge-test",
    "grid": {
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [1],
        "wound_width_factor": [0.5],
        "mesh_size_factor": [0.2],
        "skin_type": ["stiff"],
        "orientation_deg": [0],
    },
    "shapes": {"wedge": {"wound_depth_factor": [0.3]}},
    "solver": {"element_degree": 1},
}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate_run(SWEEP, tmp_path_factory.mktemp("converge"))


@pytest.mark.fem
def test_converge_writes_levels_orders_and_a_figure(run_dir: Path, capsys) -> None:
    from woundsweep.cli import main

    args = ["converge", str(run_dir), "--job", "0", "--levels", "3", "--ratio", "1.3"]
    assert main([*args, "--stages", "1-3"]) == 0
    out = capsys.readouterr().out
    assert "p99 vM kPa" in out and "closing kPa" in out and "GCI %" in out
    study = json.loads((run_dir / "convergence" / "job_0.json").read_text())
    levels = study["levels"]
    assert [lv["mesh_size_factor"] for lv in levels] == pytest.approx([0.2, 0.26, 0.338])
    cells = [lv["cells"] for lv in levels]
    assert cells[0] < cells[1] < cells[2]
    assert study["size_ratios"] == pytest.approx([1.3 ** (1 / 3)] * 2)
    assert sorted(study["studies"]) == ["1", "2", "3"]
    assert study["fits"] == {} and study["fit_deviations"] == {}  # three levels: no fit
    assert "closure_traction_kPa" in study["studies"]["3"]
    assert "contact_force_mN" not in study["studies"]["3"]  # no contact before stage 4
    # The stored study is the GCI of the stored values (f1 the finest level).
    for stage, per_q in study["studies"].items():
        for q, (s,) in per_q.items():
            f3, f2, f1 = (lv["stages"][stage][q] for lv in levels)
            ref = grid_study(f1, f2, f3, study["size_ratios"][0])
            assert s["kind"] == ref.kind
            for key in ("order", "extrapolated", "gci_fine"):
                want = getattr(ref, key)
                assert (s[key] is None and not math.isfinite(want)) or s[key] == pytest.approx(want)
    png = (run_dir / "convergence" / "job_0.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    # The level meshes are cached beside the study, not in the run's mesh cache.
    assert len(list((run_dir / "convergence" / "meshes").glob("*.npz"))) == 3


@pytest.mark.fem
def test_converge_on_listed_factors_uses_their_unequal_ratios(run_dir: Path, capsys) -> None:
    from woundsweep.cli import main

    factors = [0.2, 0.25, 0.3, 0.34]
    args = ["converge", str(run_dir), "--job", "0", "--factors", "0.2,0.25,0.3,0.34"]
    assert main([*args, "--stages", "1-1"]) == 0
    out = capsys.readouterr().out
    assert "dev %" in out and "least-squares fits over all levels" in out
    study = json.loads((run_dir / "convergence" / "job_0.json").read_text())
    levels = study["levels"]
    assert [lv["mesh_size_factor"] for lv in levels] == factors
    h = [(0.5 / m) ** (1 / 3) for m in factors]
    assert study["size_ratios"] == pytest.approx([a / b for a, b in zip(h, h[1:])])
    values = [lv["stages"]["1"]["p99_von_mises_kPa"] for lv in levels]
    f3, f2, f1 = values[-3:]
    ref = grid_study(f1, f2, f3, h[2] / h[3], h[1] / h[2])
    s = study["studies"]["1"]["p99_von_mises_kPa"][-1]  # the finest triple
    assert s["kind"] == ref.kind
    devs = study["deviations"]["1"]["p99_von_mises_kPa"]
    if ref.kind == "monotone":
        assert devs == pytest.approx([(f - ref.extrapolated) / ref.extrapolated for f in values])
    else:
        assert devs == [None] * 4
    # Four levels: the least-squares fit over all of them, as fit_study gives it.
    fit = study["fits"]["1"]["p99_von_mises_kPa"]
    want = fit_study(values, h)
    assert fit["kind"] == want.kind and fit["fit"] == want.fit
    for key in ("order", "extrapolated", "sigma"):
        w = getattr(want, key)
        assert (fit[key] is None and not math.isfinite(w)) or fit[key] == pytest.approx(w)
    fit_devs = study["fit_deviations"]["1"]["p99_von_mises_kPa"]
    if want.kind == "monotone":
        f0 = want.extrapolated
        assert fit_devs == pytest.approx([(f - f0) / f0 for f in values])
        assert fit["uncertainty"] == pytest.approx(list(want.uncertainty))


@pytest.mark.fem
def test_converge_on_uniform_refinements_is_nested(run_dir: Path, capsys) -> None:
    from woundsweep.cli import main

    args = ["converge", str(run_dir), "--job", "0", "--refine", "2", "--factors", "0.1"]
    assert main([*args, "--stages", "1-1"]) == 0
    assert "m=0.1/4" in capsys.readouterr().out
    study = json.loads((run_dir / "convergence" / "job_0_refined.json").read_text())
    levels = study["levels"]
    assert [lv["refinements"] for lv in levels] == [0, 1, 2]
    assert [lv["mesh_size_factor"] for lv in levels] == [0.1] * 3
    assert [lv["cells"] for lv in levels] == [levels[0]["cells"] * 8**k for k in range(3)]
    assert study["size_ratios"] == pytest.approx([2.0, 2.0])
    f3, f2, f1 = (lv["stages"]["1"]["p99_von_mises_kPa"] for lv in levels)
    ref = grid_study(f1, f2, f3, 2.0)
    (s,) = study["studies"]["1"]["p99_von_mises_kPa"]
    assert s["kind"] == ref.kind
    assert (run_dir / "convergence" / "job_0_refined.png").read_bytes()[:4] == b"\x89PNG"
    for bad in (["--refine", "1"], ["--refine", "2", "--factors", "0.1,0.2,0.3"]):
        assert main(["converge", str(run_dir), "--job", "0", *bad]) == 2


@pytest.mark.fem
def test_solve_flags_interpenetration_and_stores_profiles(run_dir: Path) -> None:
    import h5py

    from woundsweep.cli import main
    from woundsweep.physics.profiles import PROFILE_POINTS

    out = run_dir / "job0.h5"
    assert main(["solve", str(run_dir), "--job", "0", "--stages", "1-3", "--out", str(out)]) == 0
    with h5py.File(out, "r") as f:
        rows = json.loads(f.attrs["stage_results"])
        prof = {k: f[f"stage_{k}/profile_von_mises_kPa"][:] for k in (1, 2, 3)}
        pts = f["stage_1/profile_points_mm"][:]
        vm1 = f["stage_1/von_mises_kPa"][:]
    assert [r["closed"] for r in rows] == [None, 1, 1]  # stage 1 is open by design
    w = rows[0]["closure_gap_median_mm"] / rows[0]["closure_gap_median_per_w"]
    # Mirrored zone points overlapping, or the audit's flank nodes inside the other side.
    r3 = rows[2]
    overlap = r3["closure_overlap_mm"] > 0.01 * w or r3["audit_inside_nodes"] > 0
    assert r3["interpenetrating"] == int(overlap)
    assert pts.shape == (3, PROFILE_POINTS, 3) and prof[1].shape == (3, PROFILE_POINTS)
    # Sampled values are cell values, the maxima are those of the profiles.
    finite = prof[1][np.isfinite(prof[1])]
    assert np.isin(finite, vm1).all()
    for k, r in zip((1, 2, 3), rows):
        assert r["profile_along_wound_max_kPa"] == pytest.approx(np.nanmax(prof[k][0]), rel=1e-6)
        # The stored position is one where the (float32) profile reaches its maximum: values
        # equal to float32 precision can tie, so not necessarily numpy's first.
        i = int(np.argmin(np.abs(pts[0, :, 1] - r["profile_along_wound_max_at_mm"])))
        assert pts[0, i, 1] == pytest.approx(r["profile_along_wound_max_at_mm"], abs=1e-6)
        assert prof[k][0][i] == pytest.approx(np.nanmax(prof[k][0]), rel=1e-6)

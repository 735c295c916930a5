"""`woundsweep case` on a small wound: the report's files and numbers (fem, about a minute on
two busy cores: the case, the direction scan, the band's ends, the wound along the Langer line,
the mesh check and two finer meshes)."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest
from cli_run import ws

SMALL = [
    "--length-mm", "9", "--width-mm", "3", "--dermis-mm", "1.5", "--subcutis-mm", "1.5",
    "--depth-mm", "2.4", "--sutures", "3", "--angle-deg", "25", "--element", "1",
    "--mesh-factor", "0.12",
]  # fmt: skip


@pytest.mark.fem
@pytest.mark.slow
def test_case_writes_its_report(tmp_path: Path) -> None:
    out = tmp_path / "report"
    res = ws("case", "--out", str(out), *SMALL, "--converge", timeout=600)
    assert res.returncode == 0, res.stderr
    for name in ("report.md", "case.json", "forces.png", "wound.png", "view.png"):
        assert (out / name).stat().st_size > 0, name
    data = json.loads((out / "case.json").read_text())
    assert data["angle_to_langer_deg"] == 25.0 and data["width_mm"] == 3.0
    forces = data["suture_force_mN"]
    assert data["suture_y_mm"] == pytest.approx([-2.25, 0.0, 2.25])
    assert len(forces) == 3 and all(f > 0 for f in forces)
    # The load after closure, across the wound, in four steps, raises the suture forces.
    assert data["load"]["to_wound_deg"] == 90.0 and data["load"]["to_langer_deg"] == 65.0
    assert len(data["itch"]) == 4 and all(s is not None for s in data["itch"])
    assert all(a > b for a, b in zip(data["itch"][-1]["suture_force_mN"], forces))
    # One verdict: the report's bottom line and its load section say the same.
    verdict = {True: "HOLDS:", False: "DOES NOT HOLD:", None: "UNDECIDED:"}[data["holds"]]
    report = (out / "report.md").read_text()
    bottom, load = report.split("## Bottom line")[1], report.split("## Under the load")[1]
    assert verdict in bottom.split("##")[0] and verdict in load.split("##")[0]
    # The direction scan, the band's ends (soft and stiff around normal skin), the mesh check.
    assert [s["to_wound_deg"] for s in data["scan"]] == [0, 45, 90, 135]
    assert sorted(data["band"]) == ["soft", "stiff"] and data["skin_band"] == ["soft", "stiff"]
    soft, stiff = (data["band"][k]["suture_force_mN"] for k in ("soft", "stiff"))
    assert all(a < b < c for a, b, c in zip(soft, forces, stiff))
    check = data["mesh_check"]
    # At least 8 times the factor (the size law's halving), raised until the elements at the
    # wound are half as large as the case's.
    assert check["mesh_size_factor"] >= 8 * 0.12 and len(check["relative_change"]) == 3
    assert check["element_size_ratio_at_wound"] >= 2.0
    # The same wound along the Langer line.
    assert len(data["along_langer_force_mN"]) == 3
    for head in ("Bottom line", "Forces per suture", "Under the load after closure",
                 "Against the literature", "The same wound along the Langer line",
                 "Mesh uncertainty", "Limits of the model", "Model details"):  # fmt: skip
        assert f"## {head}" in report, head
    # Three meshes, each finer than the last.
    levels = data["mesh_levels"]
    assert [lv["mesh_size_factor"] for lv in levels] == pytest.approx([0.12, 0.27, 0.6075])
    assert levels[0]["dofs"] < levels[1]["dofs"] < levels[2]["dofs"]
    assert res.stdout.rstrip().endswith(f"wrote {out / 'report.md'}")


@pytest.mark.fem
@pytest.mark.slow
def test_case_without_the_optional_solves_says_so(tmp_path: Path) -> None:
    out = tmp_path / "report"
    skip = ["--no-even", "--no-compare", "--no-band", "--no-scan", "--no-mesh-check"]
    # --view needs plotly (the viewer's pages), which the DOLFINx 0.11 leg does not install.
    view_flag = ["--view"] if importlib.util.find_spec("plotly") is not None else []
    res = ws(
        "case", "--out", str(out), *SMALL, "--itch-angle-deg", "90", *skip, *view_flag,
        "--threads", timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    if view_flag:
        # --view: view.html, the sutured state, the load's end and (--threads) the wound
        # closed by threads, three threads each.
        page = (out / "view.html").read_text()
        view = json.loads(re.search(r'id="wsdata">(.*?)</script>', page, re.S).group(1))
        assert [s["label"] for s in view["stages"]] == [
            "sutured", "at the end of the load after closure", "closed by threads"
        ]  # fmt: skip
        for s in view["stages"]:
            assert sum(t["group"] == "threads (sutures)" for t in s["traces"]) == 3
            assert s["p99_von_mises_kPa"] > 0
        assert all(s["closure"] is not None for s in view["stages"][:2])
        knot = json.loads((out / "case.json").read_text())["threads"]["tension_mN"][0]
        names = [
            t["name"] for t in view["stages"][2]["traces"] if t["group"] == "threads (sutures)"
        ]
        assert all(f"({knot:.0f} mN)" in n for n in names)
        assert "[view.html](view.html)" in (out / "report.md").read_text()
    data = json.loads((out / "case.json").read_text())
    # The load's direction given against the Langer line: 90 to it is 65 to this wound.
    assert data["load"]["to_langer_deg"] == 90.0 and data["load"]["to_wound_deg"] == 65.0
    assert data["band"] == {} and len(data["scan"]) == 1 and "mesh_check" not in data
    report = (out / "report.md").read_text()
    assert "the mesh check was skipped (`--no-mesh-check`)" in report
    # --threads: every knot drawn with one tension until the walls meet, the tensions reported
    # beside the apposition forces, in the report, its literature table and case.json.
    th = data["threads"]
    assert th["status"] == "converged" and len(th["tension_mN"]) == 3
    assert max(th["closest_approach_mm"]) <= data["open_gap_mm"]  # the walls meet
    # The closest approach is over the bite depth, the surface included.
    assert np.all(np.array(th["closest_approach_mm"]) <= np.array(th["gap_at_suture_mm"]) + 0.02)
    assert all(t > 0 for t in th["tension_mN"]) and all(s >= 0 for s in th["knot_shortening_mm"])
    assert th["pull_mN"] == pytest.approx([2 * t for t in th["tension_mN"]], rel=0.05)
    assert th["tension_mN"] == pytest.approx([th["tension_mN"][0]] * 3, rel=1e-6)  # one pull
    assert "## Sutures as threads" in report and "threads drawn until the walls meet" in report
    # The bottom line draws on the threads: their tension under the load against the failure
    # ranges, the gap between the stitches and the pressure under the bites.
    bottom = report.split("## Bottom line")[1].split("\n## ")[0]
    assert "**Tied as threads** (4-0 nylon)" in bottom
    assert f"{max(th['bite_pressure_kPa']):.0f} kPa" in bottom
    assert f"{th['gap_between_max_mm']:.2f} mm" in bottom
    assert len(th["bite_pressure_kPa"]) == 3 and min(th["bite_pressure_kPa"]) > 0
    assert len(th["bite_pressure_under_load_kPa"]) == 3

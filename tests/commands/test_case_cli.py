"""`woundsweep case` on a small wound: the report's files and numbers (fem, about 30 s)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_run import ws

SMALL = [
    "--length-mm", "9", "--width-mm", "3", "--dermis-mm", "1.5", "--subcutis-mm", "1.5",
    "--depth-mm", "2.4", "--sutures", "3", "--angle-deg", "25", "--element", "1",
    "--mesh-factor", "0.18",
]  # fmt: skip


@pytest.mark.fem
def test_case_writes_its_report(tmp_path: Path) -> None:
    out = tmp_path / "report"
    res = ws("case", "--out", str(out), *SMALL, "--converge", timeout=300)
    assert res.returncode == 0, res.stderr
    for name in ("report.md", "case.json", "forces.png", "wound.png", "view.png"):
        assert (out / name).stat().st_size > 0, name
    data = json.loads((out / "case.json").read_text())
    assert data["angle_to_langer_deg"] == 25.0 and data["width_mm"] == 3.0
    forces = data["suture_force_mN"]
    assert data["suture_y_mm"] == pytest.approx([-2.25, 0.0, 2.25])
    assert len(forces) == 3 and all(f > 0 for f in forces)
    # The load after closure, in four steps, raises the suture forces.
    assert len(data["itch"]) == 4 and all(s is not None for s in data["itch"])
    assert all(a > b for a, b in zip(data["itch"][-1]["suture_force_mN"], forces))
    # The same wound along the Langer line.
    assert len(data["along_langer_force_mN"]) == 3
    report = (out / "report.md").read_text()
    assert "## Forces per suture" in report and "## When the patient moves" in report
    assert "## The same wound along the Langer line" in report
    # Three meshes, each finer than the last.
    levels = data["mesh_levels"]
    assert [lv["mesh_size_factor"] for lv in levels] == pytest.approx([0.18, 0.405, 0.91125])
    assert levels[0]["dofs"] < levels[1]["dofs"] < levels[2]["dofs"]
    assert "## Mesh convergence" in report
    assert res.stdout.rstrip().endswith(f"wrote {out / 'report.md'}")

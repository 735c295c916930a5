"""The clinical case's report on made-up solves (no finite elements, well under a second): one
verdict in every sentence, the "open" threshold in mm, the forces drawn where they belong, the
load's angle to the wound and to the Langer line, the literature's numbers from the forces."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from woundsweep.config.case import ClinicalCase, OPEN_GAP_mm, line_angle
from woundsweep.config.sutures import ItchLoad, SuturePlan
from woundsweep.physics.closure import ClosureMeasures
from woundsweep.physics.suture_measures import SutureState
from woundsweep.physics.sutures import SolveStep
from woundsweep.studies.case import BandEnd, CaseResult, LoadRun, MeshLevel
from woundsweep.studies.case_figures import force_series
from woundsweep.studies.case_literature import TEAR_THROUGH, literature_section, ours
from woundsweep.studies.case_report import _summary
from woundsweep.studies.case_text import render
from woundsweep.studies.case_verdict import open_stretches, verdict

YS = np.array([-3.0, 0.0, 3.0])
GAP_Y = np.linspace(-5.9, 5.9, 60)


def state(forces, gap=None, ys=YS, width=4.0) -> SutureState:  # noqa: ANN001
    """A sutured state: forces (mN) at ys, the surface gap (mm) at GAP_Y (default 0)."""
    g = np.zeros_like(GAP_Y) if gap is None else np.asarray(gap, float)
    z = np.zeros(1)
    cm = ClosureMeasures(float(g.min()), float(np.median(g)), float(g.max()), 0.0, width)
    return SutureState(
        np.asarray(ys, float), np.asarray(forces, float), cm, GAP_Y, g, z, z, z, z, (0.5, 0.5), 1.0
    )


def steps(*states: SutureState | None) -> list[SolveStep]:
    return [SolveStep("converged" if s else "diverged", 3, 1.0, s) for s in states]


def result(sutured, itch, *, case=None, evened=(), band=(), scan=(), check=None):  # noqa: ANN001
    case = case or ClinicalCase(length_mm=12.0, angle_deg=25.0, sutures=SuturePlan(count=3))
    return CaseResult(
        case, 1000, 300.0, sutured, sutured, itch, list(evened), None, None, 10.0, [], None,  # type: ignore[arg-type]
        list(band), list(scan), check, {},
    )  # fmt: skip


def gap_at(y0: float, y1: float, value: float) -> np.ndarray:
    return np.where((GAP_Y >= y0) & (GAP_Y <= y1), value, 0.0)


def sections(text: str) -> dict[str, str]:
    """report.md's sections by their heading."""
    out = {}
    for part in text.split("\n## ")[1:]:
        head, _, body = part.partition("\n")
        out[head] = body
    return out


# -- one verdict ----------------------------------------------------------------------------------


def test_a_load_that_opens_the_wound_is_said_so_everywhere() -> None:
    before = state([90, 110, 90])
    opened = state([140, 170, 140], gap_at(1.0, 2.0, 2 * OPEN_GAP_mm))
    r = result(before, steps(state([120, 140, 120]), opened, opened, opened))
    v = verdict(r)
    assert v.load.opens and v.sutures_hold and v.holds is False and v.load.first_step == 2
    assert v.load.opened[0].y0_mm == pytest.approx(GAP_Y[GAP_Y >= 1.0][0])
    text = render(r, "woundsweep case", [], v)
    s = sections(text)
    for part in (s["Bottom line"], s["Under the load after closure"]):
        assert (
            "the wound OPENS at y = +1.1 to +1.9 mm (gap up to 0.20 mm), from load step 2/4" in part
        )
        assert "; the sutures hold: the largest force, 0.17 N (170 mN), is 20 times below" in part
    assert "HOLDS" not in text and "nothing closed after suturing opens" not in text
    assert "beyond the end sutures" not in text  # +1.1 to +1.9 lies between two sutures
    assert json.loads(json.dumps(_summary(r, v)))["holds"] is False


def test_a_load_that_opens_nothing_is_said_so_everywhere() -> None:
    before = state([90, 110, 90], gap_at(5.0, 6.0, 0.5 * OPEN_GAP_mm))
    after = state([140, 170, 140], gap_at(5.0, 6.0, 0.9 * OPEN_GAP_mm))
    r = result(before, steps(after, after, after, after))
    v = verdict(r)
    assert not v.load.opens and v.holds is True and v.closed
    assert v.margin == pytest.approx(TEAR_THROUGH.low_N / 0.170)
    text = render(r, "woundsweep case", [], v)
    s = sections(text)
    for part in (s["Bottom line"], s["Under the load after closure"]):
        assert "the wound HOLDS: nothing closed after suturing opens (gap above 0.1 mm)" in part
        assert f"is {v.margin:.0f} times below" in part
    assert "OPEN" not in text and "TEAR THROUGH" not in text
    assert "At its end the edges meet everywhere." in s["Under the load after closure"]


def test_a_force_past_tear_through_is_said_so_everywhere() -> None:
    before = state([900, 2000, 900])
    after = state([1500, 3500, 1500])  # above the 3.44 N of the tear-through range
    r = result(before, steps(after, after))
    v = verdict(r)
    assert not v.load.opens and not v.sutures_hold and v.holds is False
    s = sections(render(r, "c", [], v))
    for part in (s["Bottom line"], s["Under the load after closure"]):
        assert "the sutures may TEAR THROUGH: the largest force, 3.5 N (3500 mN), reaches" in part
        assert "; nothing closed after suturing opens" in part


def test_one_suture_open_at_its_ends_is_one_story() -> None:
    # One suture: the ends of the wound stand open after suturing and open further under the
    # load; nothing between them opens. Every sentence says that, and only that.
    ys = np.array([0.0])
    before = state([200], 0.8 * np.abs(GAP_Y) / 5.9 * 3 * OPEN_GAP_mm, ys)
    after = state([260], before.gap_mm * 1.2, ys)
    r = result(before, steps(after, after, after, after))
    v = verdict(r)
    assert not v.closed and v.open_only_beyond_ends and v.load.opens
    text = render(r, "woundsweep case", [], v)
    s = sections(text)
    ends = "beyond the end sutures, toward the apices"
    for part in (s["Bottom line"], s["After closure"], s["Under the load after closure"]):
        assert ends in part
    assert (
        "the wound is OPEN at" in s["Bottom line"] and "the wound is OPEN at" in s["After closure"]
    )
    assert "the wound OPENS at" in s["Bottom line"]
    assert "the wound OPENS at" in s["Under the load after closure"]
    assert "HOLDS" not in text and "nothing closed after suturing opens" not in text
    assert "the edges meet everywhere" not in text


def test_an_unfinished_load_is_undecided() -> None:
    before = state([90, 110, 90])
    r = result(before, steps(state([120, 140, 120]), None))
    v = verdict(r)
    assert v.holds is None and v.load.steps_done == 1
    s = sections(render(r, "c", [], v))
    assert "UNDECIDED: the load was followed to step 1/2 only" in s["Bottom line"]
    assert "could not be followed past step 1/2" in s["Under the load after closure"]


def test_nothing_grows_is_said_not_printed_as_zeros() -> None:
    before = state([90, 110, 90])
    r = result(before, steps(before, before))
    text = render(r, "c", [], verdict(r))
    assert "No surface gap grows" in text and "0.000 -> 0.000" not in text


# -- the open threshold ---------------------------------------------------------------------------


@pytest.mark.parametrize("width", [1.0, 4.0, 20.0])
def test_open_is_a_gap_above_the_threshold_in_mm_whatever_the_width(width: float) -> None:
    below = state([1, 1, 1], np.full_like(GAP_Y, 0.99 * OPEN_GAP_mm), width=width)
    above = state([1, 1, 1], gap_at(-1.0, 1.0, 1.01 * OPEN_GAP_mm), width=width)
    assert OPEN_GAP_mm == 0.1
    assert verdict(result(below, steps(below))).closed
    v = verdict(result(above, steps(above)))
    assert not v.closed and not v.open_only_beyond_ends
    assert [(s.y0_mm, s.y1_mm) for s in v.after_closure] == [
        (pytest.approx(GAP_Y[GAP_Y >= -1][0]), pytest.approx(GAP_Y[GAP_Y <= 1][-1]))
    ]
    assert _summary(result(below, steps(below)), verdict(result(below, steps(below))))["closed"]
    assert open_stretches(GAP_Y, above.gap_mm, threshold=0.2) == []


# -- forces.png -----------------------------------------------------------------------------------


def test_forces_are_drawn_at_their_own_positions() -> None:
    before = state([90, 110, 90])
    evened = state([100, 101, 100], ys=np.array([-3.6, 0.0, 3.6]))
    soft = state([80, 95, 80])
    stiff = state([110, 130, 110])
    r = result(
        before, steps(state([120, 140, 120])), evened=[evened],
        band=[BandEnd("soft", soft, None), BandEnd("stiff", stiff, None)],
    )  # fmt: skip
    series = {s.label.split(" (")[0]: s for s in force_series(r)}
    assert series["evened placement"].y_mm.tolist() == [-3.6, 0.0, 3.6]
    assert series["evened placement"].force_mN.tolist() == [100, 101, 100]
    assert series["as placed"].y_mm.tolist() == YS.tolist()
    assert series["as placed"].low_mN.tolist() == [80, 95, 80]  # type: ignore[union-attr]
    assert series["as placed"].high_mN.tolist() == [110, 130, 110]  # type: ignore[union-attr]
    assert series["under the load"].force_mN.tolist() == [120, 140, 120]


# -- the load's direction -------------------------------------------------------------------------


def test_across_a_wound_at_25_degrees_is_65_degrees_to_the_langer_line() -> None:
    # The wound's long axis lies at +25 degrees to the Langer line; across it, at 25 + 90 =
    # 115 degrees, the line at -65: 65 degrees to the Langer line.
    c = ClinicalCase(length_mm=20.0, angle_deg=25.0)
    assert c.load.angle_to_langer_deg == pytest.approx(-65.0)
    assert c.to_wound_deg(c.load) == pytest.approx(90.0)
    # In the model the wound runs along y (orientation 65: the Langer line at 65 degrees to
    # x): across it is x, so the stretch is e x x^T.
    E = np.array(c.load.gradient(c.orientation_deg))
    assert E == pytest.approx(np.array([[0.1, 0.0], [0.0, 0.0]]), abs=1e-12)
    # The diagonals: 45 degrees to the wound is 70 to the line, 135 is 160, the line at 20.
    assert c.load_at(45.0).angle_to_langer_deg == pytest.approx(70.0)
    assert c.load_at(135.0).angle_to_langer_deg == pytest.approx(-20.0)
    assert c.to_wound_deg(c.load_at(135.0)) == pytest.approx(135.0)
    # Along the wound: 25 degrees to the line; the stretch along y.
    E0 = np.array(c.load_at(0.0).gradient(c.orientation_deg))
    assert E0 == pytest.approx(np.array([[0.0, 0.0], [0.0, 0.1]]), abs=1e-12)
    # An angle to the Langer line given instead is kept, and its angle to the wound follows.
    given = ClinicalCase(angle_deg=25.0, itch=ItchLoad(0.1, 90.0), itch_to_wound_deg=None)
    assert given.load.angle_to_langer_deg == 90.0
    assert given.to_wound_deg(given.load) == pytest.approx(65.0)
    assert abs(line_angle(-65.0)) == 65.0 and line_angle(180.0) == 0.0 and line_angle(-90) == 90


def test_the_report_states_the_load_against_the_wound_and_the_line() -> None:
    before = state([90, 110, 90])
    r = result(before, steps(state([120, 140, 120])))
    text = render(r, "c", [], verdict(r))
    assert (
        "90 degrees to the wound's long axis (across the wound), 65 degrees to the Langer line"
        in text
    )


def test_the_scan_names_the_worst_direction() -> None:
    before = state([90, 110, 90])
    c = ClinicalCase(length_mm=12.0, angle_deg=25.0, sutures=SuturePlan(count=3))
    runs = [
        LoadRun(c.load_at(d), d, steps(state([100, f, 100])))
        for d, f in ((0.0, 130.0), (45.0, 190.0), (135.0, 150.0))
    ]
    r = result(before, steps(state([120, 170, 120])), case=c, scan=runs)
    v = verdict(r)
    assert [s.to_wound_deg for s in v.scan] == [0, 45, 90, 135]
    assert v.worst.to_wound_deg == 45 and v.worst.to_langer_deg == 70
    s = sections(render(r, "c", [], v))
    assert (
        "**Worst direction** of those tried (0, 45, 90, 135 degrees to the wound): 45 degrees (70"
        in s["Bottom line"]
    )


# -- the literature and the mesh check ------------------------------------------------------------


def test_the_literature_section_reads_the_solved_forces() -> None:
    before = state([51.0, 107.0, 138.0])
    r = result(
        before, steps(before),
        band=[BandEnd("soft", state([45, 95, 115]), None), BandEnd("stiff", state([60, 130, 170]), None)],
    )  # fmt: skip
    o = ours(r)
    assert o.peak_N == pytest.approx(0.138) and o.smallest_N == pytest.approx(0.051)
    assert o.centre_to_end == pytest.approx(138.0 / np.mean([51.0, 138.0]))
    assert o.band_peak_N == pytest.approx((0.115, 0.170))
    text = "\n".join(literature_section(r))
    assert "| 0.051-0.138 (largest 0.115-0.17, soft to stiff skin) |" in text
    assert f"{o.centre_to_end:.1f} |" in text
    assert f"is {0.5 / 0.138:.1f} times below" in text
    # The model's side is computed: Table 2's pre-stress and stiffness.
    assert "1.9-5.6 kPa" in text and "of 18-83 kPa" in text


def test_the_mesh_line_gives_each_force_s_change() -> None:
    before = state([100.0, 200.0, 100.0])
    # 8 times the dofs of the case's 1,000: elements 2 times smaller, read from the meshes.
    check = MeshLevel(1.44, 8000, np.array([98.0, 202.0, 98.0]), 0.5, 0.12)
    r = result(before, steps(before), check=check)
    s = sections(render(r, "c", [], verdict(r)))
    assert "elements 2 times smaller the forces change by -2.0 to +1.0 %" in s["Bottom line"]
    assert "-2.0, +1.0, -2.0 %" in s["Mesh uncertainty"]
    coarse = MeshLevel(1.44, 3375, np.array([98.0, 202.0, 98.0]), 0.5, 0.12)
    r = result(before, steps(before), check=coarse)  # 3,375 dofs: 1.5 times smaller
    assert "elements 1.5 times smaller" in sections(render(r, "c", [], verdict(r)))["Bottom line"]
    # Where the check measured the element size at the wound, that ratio is the one stated.
    measured = MeshLevel(4.0, 8000, np.array([98.0, 202.0, 98.0]), 0.5, 0.12, 2.07)
    r2 = result(before, steps(before), check=measured)
    assert (
        "elements 2.1 times smaller at the wound the forces"
        in sections(render(r2, "c", [], verdict(r2)))["Bottom line"]
    )
    assert _summary(r2, verdict(r2))["mesh_check"]["element_size_ratio_at_wound"] == 2.07
    gap = "the largest surface gap after closure is 0.120 mm (here 0.000 mm; open above 0.1 mm)"
    assert gap in s["Mesh uncertainty"]
    skipped = sections(render(result(before, steps(before)), "c", []))
    assert "the mesh check was skipped (`--no-mesh-check`)" in skipped["Bottom line"]
    assert math.isclose(_summary(r, verdict(r))["mesh_check"]["relative_change"][1], 0.01)


def test_no_internal_words_or_outside_paths_before_the_model_details(tmp_path: Path) -> None:
    before = state([90, 110, 90])
    r = result(before, steps(state([120, 140, 120])))
    text = render(r, "c", [])
    main, _, details = text.partition("## Model details")
    for word in ("Dirichlet", "dofs", "degrees of freedom", "shared/", "notes/"):
        assert word not in main, word
    assert "degrees of freedom" in details

"""The case's 3D pictures on made-up fields (no finite elements, a few seconds): view.html of
`woundsweep case --view` is one self-contained page whose data round-trips (the surface's
displacement and stress, one thread per suture from bite to bite, the wound's rim, each state
labelled) and view.png is drawn with its rim and threads."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest
from case_view_data import FORCES, SUTURE_Y, displacement, made_up_view, write_page

from woundsweep.core.schema import PROFILE_LINES
from woundsweep.physics.suture_measures import SurfacePatch
from woundsweep.studies.case_view import THREAD_RISE, thread_arc, view_png
from woundsweep.viz.surface import surface_of
from woundsweep.viz.view import LineTrace, _trace

THREADS = "threads (sutures)"


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict]:
    path = write_page(tmp_path_factory.mktemp("caseview"))
    assert path.name == "view.html"
    text = path.read_text()
    m = re.search(r'<script type="application/json" id="wsdata">(.*?)</script>', text, re.S)
    assert m is not None
    return text, json.loads(m.group(1))


def _arr(b64: str, dtype: str) -> np.ndarray:
    return np.frombuffer(base64.b64decode(b64), dtype=dtype)


def _xyz(t: dict, scale: float = 1.0) -> np.ndarray:
    """A trace's points at deformation ``scale`` (NaN where a line breaks)."""
    f = lambda v: np.nan if v is None else v  # noqa: E731
    return np.array(
        [[f(t[c][i]) + scale * f(t["u" + c][i]) for c in "xyz"] for i in range(len(t["x"]))]
    )


def test_the_page_is_self_contained_and_parses(page) -> None:  # noqa: ANN001
    text, data = page
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert "<script src" not in text and "<link " not in text  # plotly.js and the viewer inline
    assert "Plotly" in text and "extraLines" in text
    assert "Case: 12 x 4 mm excision at 25 degrees to the Langer line, 3 sutures" in text
    assert [s["label"] for s in data["stages"]] == [
        "sutured", "at the end of the load after closure"
    ]  # fmt: skip
    assert data["initial"] == 1 and data["title"] == "" and data["camera"]["eye"]
    assert data["element"].startswith("P2")


def test_one_thread_per_suture_from_bite_to_bite(page) -> None:  # noqa: ANN001
    _, data = page
    view = made_up_view()
    p = view.points_mm
    for k, stage in enumerate(data["stages"], 1):
        u = displacement(p, k)
        threads = [t for t in stage["traces"] if t["group"] == THREADS]
        assert len(threads) == len(SUTURE_Y) == len(view.bites)
        for t, (a, b), y, f in zip(threads, view.bites, SUTURE_Y, FORCES * k):
            moved, ref = _xyz(t), _xyz(t, 0.0)
            np.testing.assert_allclose(moved[[0, -1]], (p + u)[[a, b]], atol=1e-4)
            np.testing.assert_allclose(ref[[0, -1]], p[[a, b]], atol=1e-4)
            # An arc above the chord, THREAD_RISE of its span at its middle.
            span = np.linalg.norm((p + u)[b] - (p + u)[a])
            chord_mid = 0.5 * ((p + u)[a] + (p + u)[b])
            np.testing.assert_allclose(moved[len(moved) // 2, 2] - chord_mid[2],
                                       THREAD_RISE * span, atol=1e-4)  # fmt: skip
            assert f"y = {y:+.1f} mm" in t["name"] and f"({f:.0f} mN)" in t["name"]
        rim = [t for t in stage["traces"] if t["group"] == "the wound's rim"]
        assert len(rim) == 1
        pts = _xyz(rim[0])
        assert len(pts) == 3 * len(view.rim) and np.isnan(pts[2::3]).all()
        np.testing.assert_allclose(pts[0::3], (p + u)[view.rim[:, 0]], atol=1e-4)


def test_the_surface_fields_round_trip(page) -> None:  # noqa: ANN001
    _, data = page
    view = made_up_view()
    s = surface_of(view.points_mm, view.cells, view.facets, np.zeros(len(view.facets), bool))
    assert data["n_triangles"] == len(s.triangles)
    np.testing.assert_allclose(_arr(data["x"], "<f4"), view.points_mm[s.nodes, 0], atol=1e-6)
    for stage, st in zip(data["stages"], view.states):
        u = _arr(stage["u"], "<f4").reshape(-1, 3)
        np.testing.assert_allclose(u, st.displacement_mm[s.nodes], atol=1e-6)
        vm = _arr(stage["vm"], "<f4")
        np.testing.assert_allclose(vm, st.von_mises_kPa[s.owner], rtol=1e-6)
        assert stage["p99_von_mises_kPa"] == st.p99_von_mises_kPa
        assert stage["max_von_mises_kPa"] == st.max_von_mises_kPa
        assert [ln["name"] for ln in stage["lines"]] == list(PROFILE_LINES)
        assert stage["closure"]["closing_force_per_length_mN_per_mm"] == pytest.approx(
            st.closing_mN_per_mm
        )
    assert data["outline"] == ""  # no closure zone drawn: the rim is the case's outline


def test_a_trace_breaks_where_its_points_are_nan() -> None:
    pts = np.array([[0, 0, 0], [1, 0, 0], [np.nan] * 3, [2, 0, 0]], float)
    t = _trace(LineTrace("a", pts, np.ones_like(pts), group="g"))
    assert t["x"] == [0.0, 1.0, None, 2.0] and t["ux"] == [1.0, 1.0, None, 1.0]
    assert t["group"] == "g" and t["color"] == "black"
    with pytest.raises(ValueError, match="displacement"):
        _trace(LineTrace("b", pts, np.ones((2, 3))))


def test_thread_arc_ends_at_the_bites() -> None:
    a, b = np.array([0.0, 0.0, 0.0]), np.array([4.0, 0.0, 1.0])
    arc = thread_arc(a, b, 0.5)
    np.testing.assert_allclose(arc[[0, -1]], [a, b])
    assert arc[len(arc) // 2, 2] == pytest.approx(0.5 + 0.5)  # the chord's middle is at 0.5


def test_view_png_is_drawn(tmp_path: Path) -> None:
    from PIL import Image

    view = made_up_view()
    p, u = view.points_mm, displacement(view.points_mm, 1)
    top = view.facets[view.facet_tags == 16]
    used, inv = np.unique(top, return_inverse=True)
    sp = SurfacePatch(
        (p + u)[used], inv.reshape(-1, 3), u[used, 2], (p + u)[view.bites],
        (p + u)[view.rim],
    )  # fmt: skip
    assert view_png(sp, tmp_path, "made up") == "view.png"
    img = np.asarray(Image.open(tmp_path / "view.png").convert("RGB"), dtype=int)
    assert img.shape[0] > 600 and img.shape[1] > 900
    red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
    assert red.sum() > 50  # the threads

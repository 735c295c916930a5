"""The report's section on the sutures as threads (`woundsweep case --threads`) and its
numbers in case.json: each thread's tension beside the apposition force it replaces, how far
its knot was drawn, the gaps under and between the stitches, the pressure between the
walls, and the tensions under the load after closure (docs/model.md, "Sutures as threads")."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..config.case import OPEN_GAP_mm
from ..physics.sutures import AIM, NOT_APPOSED
from ..physics.thread import NYLON_4_0, ANCHOR_RADIUS_mm
from .case import CaseResult, ThreadRun
from .case_format import newtons, where, y_mm
from .case_literature import REPORTED_RANGE_N, TEAR_THROUGH
from .case_verdict import load_verdict

__all__ = ["threads_bottom_line", "threads_section", "threads_summary"]


def _between(tr: ThreadRun) -> tuple[float, float]:
    """The widest surface gap between the stitches (mm) and its y."""
    st = tr.sutured
    ys = np.sort(st.suture_y_mm)
    inside = (
        (st.gap_y_mm > ys[0]) & (st.gap_y_mm < ys[-1])
        if len(ys) > 1
        else st.gap_y_mm == st.gap_y_mm
    )
    if not inside.any():
        return 0.0, float("nan")
    k = int(np.argmax(np.where(inside, st.gap_mm, -np.inf)))
    return float(st.gap_mm[k]), float(st.gap_y_mm[k])


def threads_bottom_line(result: CaseResult) -> list[str]:
    """The bottom line's bullet on the threads (empty without them): the knot tension, the
    thread that carries most under the load against the tear-through and breaking ranges, the
    gap between the stitches and the pressure under the bites."""
    tr = result.threads
    if tr is None:
        return []
    st, last = tr.sutured, tr.loaded.last
    T = st.suture_force_mN
    gap, gy = _between(tr)
    drawn = (
        f"every knot drawn to {newtons(T.max())} brings the walls together under every suture"
        if tr.status != NOT_APPOSED
        else f"no knot tension tried brought the walls together under every suture (the last, "
        f"{newtons(T.max())})"
    )
    out = [f"- **Tied as threads** ({NYLON_4_0.name}): {drawn}"]
    lv = load_verdict(st, tr.loaded)
    if lv.steps_done:
        opens = (
            f"it OPENS at {where(lv.opened)}"
            + (" beyond the end sutures" if lv.opened_only_beyond_ends else "")
            + f", from load step {lv.first_step}/{lv.steps}"
            if lv.opens
            else "nothing closed after tying opens"
        )
        reached = "" if lv.completed else f" (followed to step {lv.steps_done}/{lv.steps} only)"
        out.append(f"; under the load after closure{reached} {opens}")
    if last is not None:
        k = int(np.argmax(last.suture_force_mN))
        peak = float(last.suture_force_mN[k])
        out.append(
            f", and the thread at y = {y_mm(st.suture_y_mm[k])} mm carries most, "
            f"{newtons(peak)}, {TEAR_THROUGH.low_N * 1e3 / peak:.0f} times below "
            f"the {TEAR_THROUGH.low_N:.1f} N at which nylon tears through a skin model and "
            f"{NYLON_4_0.breaking_force_N[0] * 1e3 / peak:.0f} times below the "
            f"{NYLON_4_0.breaking_force_N[0]:g} N at which {NYLON_4_0.name} breaks"
        )
    opened = "OPEN" if gap > OPEN_GAP_mm else "closed"
    out.append(
        f"; between the stitches the edges part by up to {gap:.2f} mm (at y = {y_mm(gy)} mm: "
        f"{opened}, open being above {OPEN_GAP_mm:g} mm); the tissue under the bites carries "
        f"up to {tr.bite_pressure_kPa.max():.0f} kPa."
    )
    return ["".join(out)]


def threads_section(result: CaseResult) -> list[str]:
    """The section's lines (empty without `run_case(threads=True)`)."""
    tr = result.threads
    if tr is None:
        return []
    st = tr.sutured
    last = tr.loaded.last
    lines = [
        "## Sutures as threads",
        "",
        f"The same wound closed by {NYLON_4_0.name} threads: each suture a loop through the "
        f"tissue within {ANCHOR_RADIUS_mm:g} mm of the points where the thread turns (in each "
        f"flank its entry into the skin, {result.case.sutures.bite_width_mm:g} mm from the "
        "edge, and its exit from the wall at the bite depth), every knot drawn with one "
        "tension, the smallest under which the walls meet "
        "under every suture (their closest approach over the bite depth at most "
        f"{AIM * OPEN_GAP_mm:g} mm; open is above {OPEN_GAP_mm:g} mm), then tied. The "
        "table gives the surface gap left under each suture. The threads' tensions are equal by that rule until "
        "the load after closure; what differs between the sutures is the apposition force "
        "(what holds the edges together over each suture's stretch of wound when they are "
        "held shut, the forces above) and how far each knot had to be drawn.",
        "",
        "| suture | y (mm) | thread tension | pull on a flank (mN) | apposition force (mN) "
        "| knot drawn in by (mm) | surface gap under it (mm) | pressure under its bites (kPa) "
        "| tension under the load (mN) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for i, y in enumerate(st.suture_y_mm):
        under = f"{last.suture_force_mN[i]:.0f}" if last is not None else "-"
        lines.append(
            f"| {i + 1} | {y_mm(y)} | {newtons(st.suture_force_mN[i])} | {tr.pull_mN[i]:.0f} "
            f"| {tr.apposition_mN[i]:.0f} | {tr.shortening_mm[i]:.2f} "
            f"| {tr.gap_at_suture_mm[i]:.3f} | {tr.bite_pressure_kPa[i]:.1f} | {under} |"
        )
    gap, gy = _between(tr)
    T = st.suture_force_mN
    lo, hi = REPORTED_RANGE_N
    lines += [""]
    if tr.status == NOT_APPOSED:
        lines.append(
            "No knot tension within the trials allowed brought the walls together under every "
            "suture: the "
            "table gives the last state reached."
        )
    lines += [
        f"Between the stitches the edges part by up to {gap:.3f} mm (at y = {y_mm(gy)} mm); "
        f"the walls press on each other with up to {st.contact_pressure_kPa.max():.0f} kPa. "
        f"The threads pull {tr.pull_mN.sum():.0f} mN in all on a flank against the "
        f"{tr.apposition_mN.sum():.0f} mN the held-shut closure pulls: a thread pulls at its "
        "bite, a bite width from the edge, and is drawn until the edge between bite and wall, "
        "which springs back once released, meets the other side again.",
        "The pressure under the bites is the largest compressive stress in the tissue within "
        f"{ANCHOR_RADIUS_mm:g} mm of the thread's turns: the thread's pull spread as the model "
        "spreads it, not the bearing pressure under the thread itself, which is larger.",
        f"The tensions, {newtons(T.min())} to {newtons(T.max())}, sit "
        + (
            "within"
            if lo * 1e3 <= T.max() <= hi * 1e3
            else ("below" if T.max() < lo * 1e3 else "above")
        )
        + f" the {lo:g}-{hi:g} N reported for sutures (Against the literature).",
    ]
    if last is not None:
        k = int(np.argmax(last.suture_force_mN - T))
        lines.append(
            f"Under the load after closure the thread at y = {y_mm(st.suture_y_mm[k])} mm "
            f"rises most, {T[k]:.0f} -> {last.suture_force_mN[k]:.0f} mN; the widest surface "
            f"gap is then {last.gap_mm.max():.3f} mm"
            + (
                f" and the pressure under the bites up to {tr.loaded_bite_pressure_kPa.max():.1f} kPa."
                if tr.loaded_bite_pressure_kPa is not None
                else "."
            )
        )
        lv = load_verdict(st, tr.loaded)
        if lv.opens:
            lines.append(
                f"The flanks part first at {where(lv.opened)}, from load step "
                f"{lv.first_step}/{lv.steps}."
            )
        elif lv.grows is not None:
            gy_, before, after = lv.grows
            lines.append(
                f"Nothing closed after tying opens; the gap grows most at y = {y_mm(gy_)} mm, "
                f"{before:.3f} -> {after:.3f} mm."
            )
    return lines


def threads_summary(result: CaseResult) -> dict[str, Any]:
    """case.json's ``threads`` entry (empty without threads)."""
    tr = result.threads
    if tr is None:
        return {}
    last = tr.loaded.last
    return {
        "threads": {
            "status": tr.status,
            "material": NYLON_4_0.name,
            "anchor_radius_mm": ANCHOR_RADIUS_mm,
            "tension_mN": tr.sutured.suture_force_mN.tolist(),
            "pull_mN": tr.pull_mN.tolist(),
            "apposition_force_mN": tr.apposition_mN.tolist(),
            "knot_shortening_mm": tr.shortening_mm.tolist(),
            "gap_at_suture_mm": tr.gap_at_suture_mm.tolist(),
            "closest_approach_mm": tr.approach_mm.tolist(),
            "gap_between_max_mm": _between(tr)[0],
            "contact_pressure_max_kPa": float(tr.sutured.contact_pressure_kPa.max()),
            "bite_pressure_kPa": tr.bite_pressure_kPa.tolist(),
            "bite_pressure_under_load_kPa": (
                None
                if tr.loaded_bite_pressure_kPa is None
                else tr.loaded_bite_pressure_kPa.tolist()
            ),
            "tension_under_load_mN": None if last is None else last.suture_force_mN.tolist(),
        }
    }

"""The text of a case's report.md (`woundsweep case`), written for the surgeon: the bottom
line first, then the case, the forces per suture, where to place them, the wound after closure
and under the load after closure, the forces against the literature (`case_literature`), the
wound along the Langer line, the mesh check, the model's limits and, last, the model's
details. Every statement of whether the wound is open, opens or holds reads one
`case_verdict.Verdict`; forces are in N with mN in brackets.
"""

from __future__ import annotations

import numpy as np

from ..config.case import SITES
from .case import ITCH_STEPS, SCAN_STEPS, CaseResult, best_evened
from .case_details import along_section, details, limits, mesh_line, mesh_section
from .case_format import and_list, newtons, spread, where, y_mm, ys_mm
from .case_literature import (
    REPORTED_RANGE_N,
    SMALLEST_REPORTED_PEAK_N,
    TEAR_THROUGH,
    literature_section,
    ours,
)
from .case_threads import threads_bottom_line, threads_section
from .case_verdict import LoadVerdict, Verdict, carry_least, carry_most, verdict

__all__ = ["render"]


def _direction(lv: LoadVerdict) -> str:
    across = " (across the wound)" if abs(lv.to_wound_deg - 90) < 1e-6 else ""
    return (
        f"{lv.to_wound_deg:g} degrees to the wound's long axis{across}, "
        f"{lv.to_langer_deg:g} degrees to the Langer line"
    )


_TEAR = (
    f"{TEAR_THROUGH.low_N:.1f}-{TEAR_THROUGH.high_N:.1f} N at which nylon sutures (5-0 to 3-0) "
    "tear through a skin model"
)


def _ends(on: bool) -> str:
    return " beyond the end sutures, toward the apices" if on else ""


def _open_phrase(v: Verdict) -> str:
    """Where the wound is open after closure: the one phrase the bottom line and the closure's
    section share."""
    if v.closed:
        return "the edges meet everywhere"
    return (
        f"the wound is OPEN at {where(v.after_closure)}{_ends(v.open_only_beyond_ends)}; "
        "elsewhere the edges meet"
    )


def _load_phrase(v: Verdict) -> str:
    """Whether the wound holds under the case's load, and why: the one sentence the bottom
    line and the load's section share (`Verdict.holds`, `Verdict.sutures_hold`)."""
    lv = v.load
    force = f"the largest force, {newtons(lv.peak_force_mN)},"
    sutures = (
        f"the sutures hold: {force} is {v.margin:.0f} times below the {_TEAR}"
        if v.sutures_hold
        else f"the sutures may TEAR THROUGH: {force} reaches the {_TEAR}"
    )
    opened = (
        f"the wound OPENS at {where(lv.opened)}{_ends(lv.opened_only_beyond_ends)}, from load "
        f"step {lv.first_step}/{lv.steps}"
        if lv.opens
        else f"nothing closed after suturing opens (gap above {v.threshold_mm:g} mm)"
    )
    if v.holds is None:
        return (
            f"UNDECIDED: the load was followed to step {lv.steps_done}/{lv.steps} only; up to "
            f"there {opened}, and {sutures}"
        )
    if v.holds:
        return f"the wound HOLDS: {opened}, and {sutures}"
    return f"{opened}; {sutures}" if lv.opens else f"{sutures}; {opened}"


def _bottom_line(result: CaseResult, v: Verdict) -> list[str]:
    c, st = result.case, result.sutured
    f = st.suture_force_mN
    n = len(f)
    most = carry_most(st)
    who = (
        f"the suture at y = {y_mm(st.suture_y_mm[most[0]])} mm carries"
        if len(most) == 1
        else f"the sutures at y = {and_list(st.suture_y_mm[most])} mm carry"
    )
    each = "" if len(most) == 1 else " each"
    band = ""
    if result.band:
        peaks = [f.max()] + [b.sutured.suture_force_mN.max() for b in result.band]
        band = f" ({' to '.join(c.band)} skin: {min(peaks) / 1e3:.3g}-{max(peaks) / 1e3:.3g} N)"
    lines = [
        f"- **{n} simple interrupted suture{'s' if n > 1 else ''}**: {who} most, "
        f"{newtons(f.max())}{each}{band}"
        + (
            f"; the least, {newtons(f.min())}, at y = {and_list(st.suture_y_mm[carry_least(st)])} mm."
            if n > 1
            else "."
        ),
    ]
    best = best_evened(result)
    if best is not None:
        lines.append(
            f"- **Where to place them**: at y = {ys_mm(best.suture_y_mm)} mm the forces are "
            f"{best.suture_force_mN.min() / 1e3:.3g}-{best.suture_force_mN.max() / 1e3:.3g} N "
            f"(largest/smallest {spread(best.suture_force_mN):.2f}, as planned {spread(f):.2f})."
        )
    elif n > 1:
        lines.append(f"- **Where to place them**: {_no_better(result)}")
    lines.append(
        f"- **After closure** {_open_phrase(v)} (largest surface gap {st.gap_mm.max():.3f} mm; "
        f"open means a gap above {v.threshold_mm:g} mm)."
    )
    it = c.itch
    lines.append(
        f"- **Under the load after closure** (a {100 * it.strain:g} % {it.kind} at "
        f"{_direction(v.load)}), {_load_phrase(v)}."
    )
    if len(v.scan) > 1:
        w = v.worst
        opens = (
            f"opens at {where(w.opened)}{_ends(w.opened_only_beyond_ends)}"
            if w.opens
            else "opens nothing"
        )
        lines.append(
            f"- **Worst direction** of those tried ({', '.join(f'{s.to_wound_deg:g}' for s in v.scan)} "
            f"degrees to the wound): {w.to_wound_deg:g} degrees ({w.to_langer_deg:g} to the Langer "
            f"line), the largest suture force {newtons(w.peak_force_mN)}; it {opens}."
        )
    lines += threads_bottom_line(result)
    lines.append(f"- **Mesh**: {mesh_line(result)}")
    o = ours(result)
    size = (
        f"the largest force here is {o.below_reported:.1f} times below the smallest peak "
        f"force reported ({SMALLEST_REPORTED_PEAK_N:g} N)"
        if o.below_reported > 1
        else "the largest force here lies within the forces reported"
    )
    what = "The forces above hold the edges together at each suture"
    if result.threads is None:
        what += ", not a thread's tension"
    else:
        knot = float(result.threads.sutured.suture_force_mN.max())
        what += (
            f"; the threads' tension, {newtons(knot)}, is "
            f"{SMALLEST_REPORTED_PEAK_N * 1e3 / knot:.1f} times below the smallest peak reported"
        )
    lines.append(
        f"- **Against the literature** {size}; reported suture forces span about "
        f"{REPORTED_RANGE_N[0]:g}-{REPORTED_RANGE_N[1]:g} N. {what}, with Table 2's "
        "soft facial-skin parameters (below)."
    )
    return lines


def _band_place(skin: str, band: tuple[str, str]) -> str:
    return {band[0]: "the lower end", band[1]: "the upper end"}.get(skin, "the centre")


def _case_section(result: CaseResult, v: Verdict) -> list[str]:
    c = result.case
    site = SITES[c.site]
    given = c.dermal_thickness_mm is not None or c.subcutis_thickness_mm is not None
    return [
        f"- Excision: a {c.length_mm:g} x {c.width:.3g} mm ellipse, its long axis at "
        f"{c.angle_deg:g} degrees to the Langer line, {c.depth:.3g} mm deep.",
        f"- Site: {c.site}, dermis {c.dermis:g} mm, subcutis {c.subcutis:g} mm "
        f"({'thicknesses given' if given else site.thickness_source}).",
        f"- Skin: {c.skin_type} (Table 2), {_band_place(c.skin_type, c.band)} of the band "
        f"{' to '.join(c.band)}: {site.band_source}.",
        f"- Sutures: {len(result.sutured.suture_y_mm)} simple interrupted, bites "
        f"{c.sutures.bite_width_mm:g} mm from the edge and {c.sutures.depth(c.dermis):g} mm deep, "
        f"at y = {ys_mm(result.sutured.suture_y_mm)} mm.",
        f"- y is the position along the wound from its centre (mm); the apices are at y = "
        f"-{c.length_mm / 2:g} and +{c.length_mm / 2:g} mm.",
        f"- Open: a surface gap wider than {v.threshold_mm:g} mm, more than the epidermis is "
        "thick (0.08-0.1 mm on the trunk, Sandby-Moller et al., Acta Derm. Venereol. "
        "2003;83:410): the edges no longer meet there. This report uses no other measure.",
    ]


def _forces_section(result: CaseResult) -> list[str]:
    st = result.sutured
    last = result.loaded.last
    band = bool(result.band)
    head = "| suture | y (mm) | force |" + (
        f" {' to '.join(result.case.band)} skin (mN) |" if band else ""
    )
    head += " under the load (mN) | rise |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for i, (y, f) in enumerate(zip(st.suture_y_mm, st.suture_force_mN)):
        row = f"| {i + 1} | {y_mm(y)} | {newtons(f)} |"
        if band:
            fs = [f] + [b.sutured.suture_force_mN[i] for b in result.band]
            row += f" {min(fs):.0f}-{max(fs):.0f} |"
        if last is not None:
            g = last.suture_force_mN[i]
            row += f" {g:.0f} | {100 * (g / f - 1):+.0f} % |"
        else:
            row += " - | - |"
        lines.append(row)
    lines += [
        "",
        f"Total {newtons(st.suture_force_mN.sum())}. A suture's force is what holds the edges "
        "together over its footprint (a bite width along the wound), not its thread's tension "
        "(Limits of the model).",
    ]
    return lines


def _no_better(result: CaseResult) -> str:
    ratio = spread(result.sutured.suture_force_mN)
    if not result.evened:
        return f"as planned (largest/smallest {ratio:.2f}); not searched (`--no-even`)."
    return f"as planned; no placement tried evened the forces more (largest/smallest {ratio:.2f})."


def _placement_section(result: CaseResult) -> list[str]:
    st = result.sutured
    f = st.suture_force_mN
    best = best_evened(result)
    if best is None:
        if len(f) < 2:
            return ["One suture: nothing to even."]
        text = _no_better(result)
        return [text[0].upper() + text[1:]]
    dense = np.diff(best.suture_y_mm)
    mid = 0.5 * (best.suture_y_mm[1:] + best.suture_y_mm[:-1])
    i = int(np.argmin(dense))
    return [
        f"Placed at y = {ys_mm(best.suture_y_mm)} mm, the forces are "
        f"{', '.join(f'{x:.0f}' for x in best.suture_force_mN)} mN: largest/smallest "
        f"{spread(best.suture_force_mN):.2f} (as planned: {spread(f):.2f}). The stitches are "
        f"closest around y = {y_mm(mid[i])} mm ({dense[i]:.1f} mm apart there, {dense.max():.1f} mm "
        "at the widest).",
    ]


def _closure_section(result: CaseResult, v: Verdict) -> list[str]:
    st = result.sutured
    return [
        f"After closure {_open_phrase(v)}; the largest surface gap is {st.gap_mm.max():.3f} mm.",
        f"Dog-ears (the rise of the skin at the apices): {st.dog_ear_mm[0]:.2f} and "
        f"{st.dog_ear_mm[1]:.2f} mm.",
    ]


def _load_section(result: CaseResult, v: Verdict) -> list[str]:
    c, st, lv = result.case, result.sutured, v.load
    it = c.itch
    lines = [
        f"Load: a {100 * it.strain:g} % {it.kind} of the surrounding skin at {_direction(lv)}, "
        f"in {ITCH_STEPS} steps.",
        "",
    ]
    last = lv.last
    if not lv.completed:
        status = result.itch[lv.steps_done].status if lv.steps_done < len(result.itch) else ""
        lines.append(
            f"The load could not be followed past step {lv.steps_done}/{lv.steps} ({status})."
        )
    if last is not None:
        rise = last.suture_force_mN - st.suture_force_mN
        k = int(np.argmax(rise))
        lines.append(
            f"The suture at y = {y_mm(st.suture_y_mm[k])} mm gains most: "
            f"{newtons(st.suture_force_mN[k])} -> {newtons(last.suture_force_mN[k])}."
        )
    lines.append(f"Under this load {_load_phrase(v)}.")
    if last is not None:
        lines.append(
            f"At its end the wound is open at {where(lv.open_after)}."
            if lv.open_after
            else "At its end the edges meet everywhere."
        )
        lines.append(
            f"The gap grows most at y = {y_mm(lv.grows[0])} mm ({lv.grows[1]:.3f} -> "
            f"{lv.grows[2]:.3f} mm)."
            if lv.grows is not None
            else "No surface gap grows (by 0.001 mm or more)."
        )
        lines.append(f"Dog-ears under the load: {last.dog_ear_height_mm:.2f} mm.")
    ends = [b for b in result.band if b.loaded is not None and b.loaded.last is not None]
    if ends and last is not None:
        peaks = [last.suture_force_mN.max()] + [b.loaded.last.suture_force_mN.max() for b in ends]  # type: ignore[union-attr]
        lines.append(
            f"Largest force under the load, {' to '.join(c.band)} skin: "
            f"{min(peaks) / 1e3:.3g}-{max(peaks) / 1e3:.3g} N."
        )
    if len(v.scan) > 1:
        lines += [
            "",
            f"The same load along other directions ({SCAN_STEPS} steps each):",
            "",
            "| to the wound (deg) | to the Langer line (deg) | largest force | opens | largest gap (mm) |",
            "|---|---|---|---|---|",
        ]
        for s in v.scan:
            mark = " (this load)" if s is v.load else ""
            gap = s.last.gap_mm.max() if s.last is not None else float("nan")
            done = "" if s.completed else f" (to step {s.steps_done}/{s.steps})"
            opens = where(s.opened) if s.opens else "no"
            lines.append(
                f"| {s.to_wound_deg:g}{mark} | {s.to_langer_deg:g} | {newtons(s.peak_force_mN)}{done} "
                f"| {opens} | {gap:.3f} |"
            )
    return lines


def _page_link(name: str) -> str:
    """A page beside the figures (``view.html``, `woundsweep case --view`)."""
    return f"[{name}]({name}): the sutured wound in 3D, interactive (opens in a browser offline)"


def render(result: CaseResult, command: str, figures: list[str], v: Verdict | None = None) -> str:
    """report.md's text (module docstring)."""
    v = verdict(result) if v is None else v
    c = result.case
    lines = [
        f"# Case: {c.length_mm:g} x {c.width:.3g} mm ellipse on the {c.site}, at "
        f"{c.angle_deg:g} degrees to the Langer line",
        "",
        f"Command: `{command}`",
        "",
        "## Bottom line",
        "",
        *_bottom_line(result, v),
        "",
        "## The case",
        "",
        *_case_section(result, v),
        "",
        "## Forces per suture",
        "",
        *_forces_section(result),
        "",
        "## Where to place the sutures",
        "",
        *_placement_section(result),
        "",
        "## After closure",
        "",
        *_closure_section(result, v),
        "",
        "## Under the load after closure",
        "",
        *_load_section(result, v),
        "",
        *threads_section(result),
        *([""] if result.threads is not None else []),
        "## Against the literature",
        "",
        *literature_section(result),
        *along_section(result),
        *mesh_section(result),
        "",
        "## Limits of the model",
        "",
        *limits(result),
        "",
        "## Figures",
        "",
        *[f"![{f}]({f})" if f.endswith(".png") else _page_link(f) for f in figures],
        "",
        "## Model details",
        "",
        *details(result),
        "",
    ]
    return "\n".join(lines)

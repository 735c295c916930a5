"""The closing sections of a case's report (`woundsweep case`): the wound along the Langer
line, the mesh check, the model's limits and the model's details."""

from __future__ import annotations

import numpy as np

from ..config.case import OPEN_GAP_mm
from .case import ITCH_STEPS, SCAN_STEPS, CaseResult, MeshLevel
from .case_format import newtons
from .case_literature import BREAKING, TEAR_THROUGH

__all__ = ["along_section", "details", "limits", "mesh_change", "mesh_line", "mesh_section"]


def mesh_change(result: CaseResult) -> np.ndarray | None:
    """Each suture force's relative change from the case's mesh to the mesh check's."""
    fine = result.mesh_check
    if fine is None:
        return None
    return np.asarray(fine.suture_force_mN) / result.sutured.suture_force_mN - 1


def _h_ratio(result: CaseResult, fine: MeshLevel) -> float:
    """How many times smaller the check's elements are, from the meshes themselves: at the
    wound (`edge_length_near_mm`) where the check measured it, otherwise from the dofs, which
    grow as h^-3. (gmsh follows the size field loosely on coarse meshes, so the factor's
    nominal ratio overstates the refinement.)"""
    if np.isfinite(fine.h_ratio):
        return float(fine.h_ratio)
    return float((fine.dofs / result.dofs) ** (1 / 3))


def _smaller(result: CaseResult, fine: MeshLevel) -> str:
    where = " at the wound" if np.isfinite(fine.h_ratio) else ""
    return f"{_h_ratio(result, fine):.2g} times smaller{where}"


def mesh_line(result: CaseResult) -> str:
    d = mesh_change(result)
    if d is None or result.mesh_check is None:
        return (
            "the mesh check was skipped (`--no-mesh-check`): this report does not state how "
            "much the forces depend on the mesh."
        )
    return (
        f"with elements {_smaller(result, result.mesh_check)} the forces change by "
        f"{100 * d.min():+.1f} to {100 * d.max():+.1f} % (largest {100 * np.abs(d).max():.1f} %)."
    )


def along_section(result: CaseResult) -> list[str]:
    al, st = result.along, result.sutured
    if al is None:
        return []
    return [
        "",
        "## The same wound along the Langer line",
        "",
        f"Forces {', '.join(f'{x:.0f}' for x in al.suture_force_mN)} mN at the same positions, "
        f"total {newtons(al.suture_force_mN.sum())} (here {newtons(st.suture_force_mN.sum())}); "
        f"dog-ears {al.dog_ear_height_mm:.2f} mm (here {st.dog_ear_height_mm:.2f} mm).",
    ]


def mesh_section(result: CaseResult) -> list[str]:
    lines = ["", "## Mesh uncertainty", ""]
    d = mesh_change(result)
    fine = result.mesh_check
    if d is None or fine is None:
        lines.append(f"Skipped (`--no-mesh-check`): {mesh_line(result)}")
    else:
        m = result.case.mesh_size_factor
        lines.append(
            f"Solved again with elements {_smaller(result, fine)} (mesh size factor "
            f"{m:g} -> {fine.mesh_size_factor:.3g}): each suture's force changes by "
            f"{', '.join(f'{100 * x:+.1f}' for x in d)} %; the dog-ears by "
            f"{100 * (fine.dog_ear_height_mm / result.sutured.dog_ear_height_mm - 1):+.1f} %"
            + (
                f"; the largest surface gap after closure is {fine.gap_max_mm:.3f} mm (here "
                f"{result.sutured.gap_mm.max():.3f} mm; open above {OPEN_GAP_mm:g} mm)."
                if np.isfinite(fine.gap_max_mm)
                else "."
            )
        )
    if len(result.levels) > 1:
        lines += [
            "",
            "| mesh size factor | suture forces (mN) | dog-ear (mm) |",
            "|---|---|---|",
        ]
        for lv in result.levels:
            forces = ", ".join(f"{f:.1f}" for f in lv.suture_force_mN)
            lines.append(f"| {lv.mesh_size_factor:.4g} | {forces} | {lv.dog_ear_height_mm:.3f} |")
    return lines


_LIMITS = [
    "- **A suture is a held footprint.** The edges are tied together over a bite width along "
    "the wound, down to the bite depth; the thread, its knot, its path through the tissue and "
    "the eversion it causes are not modelled. The force is the apposition force over the "
    "footprint, not the thread's tension.",
    "- **Sutures never fail.** Nothing tears through or breaks in the model; the margin sets "
    f"the largest force beside the forces at which sutures fail: {TEAR_THROUGH.text}; "
    f"{BREAKING.text}.",
    "- **No friction.** The wound's walls slide freely where they touch outside the footprints.",
    "- **Facial-skin parameters.** Table 2's dermis (Flynn et al.'s facial skin) at every site; "
    "only the layer thicknesses are the site's. The band soft to stiff skin is Table 2's span, "
    "not a measured range of the site.",
    "- **Quasi-static and elastic.** No creep, relaxation or healing; the load after closure is "
    "applied slowly, once.",
    "- **No undermining, no deep sutures.** The edges are not freed from the subcutis, which "
    "lowers the closing force and the dog-ears in practice.",
]


def _resolution(result: CaseResult) -> str:
    """The spacing of the surface gap's samples along the wound (the mesh's surface pairs)."""
    dy = (
        float(np.median(np.diff(result.sutured.gap_y_mm)))
        if len(result.sutured.gap_y_mm) > 1
        else 0.0
    )
    return (
        f"- **Gap resolution.** The surface gap is known at points {dy:.1f} mm apart along the "
        "wound (the mesh's surface nodes); an opening at one point next to an apex is one "
        "sample."
    )


def details(result: CaseResult) -> list[str]:
    c, st = result.case, result.sutured
    lines = [
        f"- Finite elements: P{c.element_degree} tetrahedra, {result.dofs} degrees of freedom at "
        f"mesh size factor {c.mesh_size_factor:g}"
        + (f"; the mesh check's {result.mesh_check.dofs}." if result.mesh_check else "."),
        f"- Closing: stages 1-2 (pre-stretch, then the wound's walls closed by a prescribed "
        f"displacement, pulling {newtons(result.closing_force_mN)} on one flank), then each "
        f"footprint tied (penalty 1 GPa) and the rest released; the sutures then carry "
        f"{newtons(st.suture_force_mN.sum())} in all.",
        "- A suture's force: the tie's pull across the wound on one wall, each tied point "
        "counted for its nearest suture (blended over 0.5 mm halfway between two).",
        f"- The load after closure: the patch's side faces moved by the load's displacement "
        f"gradient in {ITCH_STEPS} steps (the scan's directions and the band's ends in {SCAN_STEPS}), contact on.",
    ]
    if result.along_closing_force_mN is not None:
        lines.append(
            f"- Along the Langer line the prescribed closure pulls "
            f"{newtons(result.along_closing_force_mN)} (here {newtons(result.closing_force_mN)})."
        )
    lines += [
        f"- Solved in {result.time_s:.0f} s:",
        "",
        "| part | solves | time (s) |",
        "|---|---|---|",
    ] + [f"| {k} | {v.solves} | {v.time_s:.0f} |" for k, v in result.costs.items()]
    return lines


def limits(result: CaseResult) -> list[str]:
    """The report's "Limits of the model" bullets."""
    threads = (
        ["- **Threads.** The threads (Sutures as threads) pull on the tissue around the points "
         "where they turn; the needle's hole, the knot's geometry and friction in the tracks and "
         "between the walls are not modelled; every knot is drawn with one tension, the "
         "smallest under which the walls meet under every suture, so the threads' "
         "tensions differ only under the load after closure."]
        if result.threads is not None
        else []
    )  # fmt: skip
    return [*_LIMITS, *threads, _resolution(result)]

"""``woundsweep case --out DIR [--length-mm L] [--width-mm W] [--angle-deg A] ...``: one clinical
case, a fusiform excision closed by simple interrupted sutures, from flags.

Solves the closure at the given angle to the Langer line, the load after closure ("when my
patient itches"; by default across the wound) and the same load along the scan's other
directions, a placement that evens the suture forces (by re-solving), the site's band of skin
types, the same wound along the Langer line and the sutures on a mesh with elements half the
size, and writes DIR/report.md, DIR/case.json and figures (`woundsweep.studies.case`,
`woundsweep.studies.case_report`); with --view also DIR/view.html, the sutured wound in 3D
(`woundsweep.viz.view.fields_page`, the viewer of `woundsweep view`). Exit status: 0 solved;
2 bad input (one line); 3 a solve did not converge; 4 the excision could not be meshed.
"""

from __future__ import annotations

import logging
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, cast

import click

from ..config.case import (
    DEPTH_INTO_SUBCUTIS,
    ELEMENT_DEGREE,
    MESH_CHECK_FACTOR,
    MESH_SIZE_FACTOR,
    SKIN_TYPES,
    ITCH_TO_WOUND_deg,
    SCAN_TO_WOUND_deg,
)
from ..config.sutures import BODY_SITES, ITCH_KINDS, BITE_WIDTH_mm, ItchLoad
from ..core.schema import PROFILE_LINES

if TYPE_CHECKING:
    from ..studies.case import CaseResult
    from ..studies.case_view import CaseView
    from ..viz.jobdata import JobFields

__all__ = ["VIEW_HTML", "cmd", "write_view"]

_ITCH = ItchLoad()


# What a case writes into --out (`studies.case_report`).
_REPORT_FILES = ("report.md", "case.json", "forces.png", "wound.png", "view.png", "view.html")
VIEW_HTML = "view.html"


def _set_aside_previous(out: Path, names: tuple[str, ...] = _REPORT_FILES) -> None:
    """Move an earlier case's report files (``names``) in ``out`` to ``out/previous/`` (kept,
    not taken for this case's), replacing what an earlier failure put there."""
    import os

    found = [out / n for n in names if (out / n).is_file() and not (out / n).is_symlink()]
    if not found:
        return
    dst = out / "previous"
    try:
        dst.mkdir(exist_ok=True)
        for p in found:
            os.replace(p, dst / p.name)
    except OSError:
        return  # the error being reported is the command's; the files stay where they were
    click.echo(f"the previous case's report in {out} moved to {dst}")


@click.command("case")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Report directory (created).",
)
@click.option(
    "--length-mm",
    type=float,
    default=20.0,
    show_default=True,
    help="Length of the elliptical excision.",
)
@click.option("--width-mm", type=float, default=None, help="Its width [a third of the length].")
@click.option(
    "--angle-deg",
    type=float,
    default=0.0,
    show_default=True,
    help="Angle of the long axis to the Langer line, 0-90.",
)
@click.option(
    "--site",
    type=click.Choice(list(BODY_SITES)),
    default="upper-back",
    show_default=True,
    help="Body-site preset of the layer thicknesses.",
)
@click.option("--dermis-mm", type=float, default=None, help="Dermal thickness [the site's].")
@click.option("--subcutis-mm", type=float, default=None, help="Subcutis thickness [the site's].")
@click.option(
    "--depth-mm",
    type=float,
    default=None,
    help=f"Excision depth [dermis + {DEPTH_INTO_SUBCUTIS:g} x subcutis].",
)
@click.option(
    "--skin",
    type=click.Choice(SKIN_TYPES),
    default="normal",
    show_default=True,
    help="Skin type (the paper's Table 2): the centre of the site's band.",
)
@click.option(
    "--sutures",
    "count",
    type=int,
    default=None,
    help="Number of sutures [spaced by the bite width].",
)
@click.option("--spacing-mm", type=float, default=None, help="Suture spacing instead of a count.")
@click.option(
    "--bite-width-mm",
    type=float,
    default=BITE_WIDTH_mm,
    show_default=True,
    help="Distance of each bite from the wound's edge.",
)
@click.option("--bite-depth-mm", type=float, default=None, help="Bite depth [the dermis].")
@click.option(
    "--itch-strain",
    type=float,
    default=_ITCH.strain,
    show_default=True,
    help="Load after closure: strain of the patch (0.1 = 10 %).",
)
@click.option(
    "--itch-to-wound-deg",
    type=float,
    default=ITCH_TO_WOUND_deg,
    show_default=True,
    help="Its direction: angle to the wound's long axis (90 = across the wound).",
)
@click.option(
    "--itch-angle-deg",
    type=float,
    default=None,
    help="Its direction as an angle to the Langer line instead (90 = across the line).",
)
@click.option(
    "--itch-kind",
    type=click.Choice(ITCH_KINDS),
    default=_ITCH.kind,
    show_default=True,
    help="Stretch along that direction, or shear.",
)
@click.option(
    "--element",
    type=click.IntRange(1, 2),
    default=ELEMENT_DEGREE,
    show_default=True,
    help="Element degree (1: P1, 2: P2).",
)
@click.option(
    "--mesh-factor",
    type=float,
    default=MESH_SIZE_FACTOR,
    show_default=True,
    help="Mesh size factor (larger is finer).",
)
@click.option("--no-even", is_flag=True, help="Skip the evened placement.")
@click.option("--no-compare", is_flag=True, help="Skip the same wound along the Langer line.")
@click.option("--no-band", is_flag=True, help="Skip the site's other skin types (2 solves).")
@click.option(
    "--no-scan",
    is_flag=True,
    help=f"Skip the load along {'/'.join(f'{d:g}' for d in SCAN_TO_WOUND_deg)} deg to the wound.",
)
@click.option(
    "--no-mesh-check",
    is_flag=True,
    help=f"Skip the sutures on a mesh of {MESH_CHECK_FACTOR:g} x the mesh factor (elements half "
    "the size).",
)
@click.option(
    "--converge",
    is_flag=True,
    help="Also solve the sutures on two finer meshes (mesh factor x2.25, x5.06).",
)
@click.option(
    "--view",
    is_flag=True,
    help="Also write DIR/view.html: the sutured wound in 3D, interactive (the viewer of "
    "`woundsweep view`: the deformed surface coloured by von Mises in kPa, the threads, the "
    "wound's rim; the state at the end of the load too, and with --threads the wound closed "
    "by threads), one self-contained file of about "
    "5 MB that opens offline.",
)
@click.option(
    "--threads",
    is_flag=True,
    help="Also close the wound by 4-0 nylon threads (every knot drawn with one tension, the "
    "smallest under which the walls meet under every suture) and report each thread's "
    "tension beside the apposition force, the gaps between the stitches and the tensions "
    "under the load (about six minutes more on the 2 cm case at P2).",
)
def cmd(out: Path, length_mm: float, width_mm: float | None, angle_deg: float, site: str,
        dermis_mm: float | None, subcutis_mm: float | None, depth_mm: float | None, skin: str,
        count: int | None, spacing_mm: float | None, bite_width_mm: float,
        bite_depth_mm: float | None, itch_strain: float, itch_to_wound_deg: float,
        itch_angle_deg: float | None, itch_kind: str, element: int, mesh_factor: float,
        no_even: bool, no_compare: bool, no_band: bool, no_scan: bool, no_mesh_check: bool,
        converge: bool, view: bool, threads: bool) -> None:  # fmt: skip
    """Solve one clinical case and write its report (the bottom line, forces per suture with
    the site's band, where to place them, what a load after closure does, the forces against
    the literature, the mesh check). With --view also view.html, the sutured wound in 3D:
    the deformed skin coloured by von Mises (kPa), each suture's thread drawn from bite to
    bite, the wound's rim outlined, a deformation scale and a cut at the wound's middle. With
    --threads also the sutures as threads: each thread's tension (N) and the gaps."""
    from ..config.case import ClinicalCase
    from ..config.sutures import CaseError, SuturePlan
    from ..core.fsutil import check_output_dir

    try:
        check_output_dir(out)
    except ValueError as err:
        raise CaseError(f"--out {err}") from None
    from click.core import ParameterSource

    ctx = click.get_current_context()
    to_wound: float | None = itch_to_wound_deg
    if itch_angle_deg is not None:
        if ctx.get_parameter_source("itch_to_wound_deg") == ParameterSource.COMMANDLINE:
            raise CaseError("give --itch-to-wound-deg or --itch-angle-deg, not both")
        to_wound = None
    plan = SuturePlan(count, spacing_mm, bite_width_mm, bite_depth_mm)
    load = ItchLoad(
        itch_strain,
        _ITCH.angle_to_langer_deg if itch_angle_deg is None else itch_angle_deg,
        itch_kind,
    )
    case = ClinicalCase(
        length_mm, width_mm, angle_deg, site, dermis_mm, subcutis_mm, depth_mm, skin, plan,
        load, mesh_factor, element, to_wound,
    )  # fmt: skip
    logging.getLogger().setLevel(logging.WARNING)
    from ..studies.case import run_case
    from ..studies.case_report import write_report

    try:
        result = run_case(
            case, echo=lambda s: click.echo(s), compare=not no_compare, even=not no_even,
            converge=converge, band=not no_band, scan=not no_scan, mesh_check=not no_mesh_check,
            view=view, threads=threads,
        )  # fmt: skip
        command = "woundsweep " + " ".join(shlex.quote(a) for a in sys.argv[1:])
        pages = (write_view(result, out),) if view else ()
        path = write_report(result, out, command, pages)
    except BaseException:
        _set_aside_previous(out)  # a failed case leaves no earlier case's report as its own
        raise
    if not view:
        _set_aside_previous(out, (VIEW_HTML,))  # an earlier case's view is not this one's
    click.echo(path.read_text())
    click.echo(f"wrote {path}")


def _fields(cv: CaseView) -> JobFields:
    """The case's states as the viewer's `JobFields`: one "stage" per state, no job."""
    import numpy as np

    from ..config.manifest import JobRow
    from ..core.schema import StageStatus
    from ..store.solverfile import CLOSURE_LINE_DATASETS
    from ..viz.jobdata import JobFields, StageNote

    rows, fields, profiles, lines = [], {}, {}, {}
    for k, st in enumerate(cv.states, 1):
        rows.append({"stage": k, "status": StageStatus.CONVERGED, "element_degree": cv.element_degree,
                     "p99_von_mises_kPa": st.p99_von_mises_kPa,
                     "max_von_mises_kPa": st.max_von_mises_kPa})  # fmt: skip
        fields[k] = (st.displacement_mm, st.von_mises_kPa)
        profiles[k] = {
            name: {"points_mm": st.profile_points_mm[i], "von_mises_kPa": st.profile_von_mises_kPa[i]}
            for i, name in enumerate(PROFILE_LINES[: len(st.profile_points_mm)])
        }  # fmt: skip
        loads = (st.line_y_mm, st.closing_mN_per_mm, st.contact_mN_per_mm)
        if all(a is not None for a in loads):
            lines[k] = dict(zip(CLOSURE_LINE_DATASETS, cast("tuple[np.ndarray, ...]", loads)))
    job = cast(JobRow, {"job_index": 0, "job_id": "case"})
    return JobFields(
        job, rows, cv.points_mm, cv.cells, cv.cell_tags, cv.facets, cv.facet_tags,
        np.zeros(len(cv.facets), bool), fields,
        [StageNote(k, StageStatus.CONVERGED, True, "") for k in fields],
        profiles=profiles, closure_lines=lines, source="woundsweep case",
    )  # fmt: skip


def write_view(result: CaseResult, out: Path) -> str:
    """DIR/view.html (`VIEW_HTML`): the case's states in the viewer of `woundsweep view`, the
    threads and the wound's rim as extra lines; its name."""
    from html import escape

    from ..core.fsutil import atomic_write
    from ..studies.case_view import view_lines
    from ..viz.view import LineTrace, fields_page

    cv = result.view
    assert cv is not None and cv.states, "run_case(view=True) captures the sutured state"
    c = result.case
    traces = {k: [LineTrace(*ln) for ln in view_lines(cv, st)] for k, st in enumerate(cv.states, 1)}
    forces = ", ".join(f"{f:.0f}" for f in cv.states[0].suture_force_mN)
    title = (
        f"Case: {c.length_mm:g} x {c.width:.3g} mm excision at {c.angle_deg:g} degrees to the "
        f"Langer line, {len(cv.bites)} sutures"
    )
    before = (
        f"<p>The sutured wound ({escape(c.skin_type)} skin, {escape(c.site)}); the sutures' "
        f"forces after closure: {escape(forces)} mN, from one end of the wound to the other. "
        'The report: <a href="report.md">report.md</a>.</p>\n'
    )
    page = fields_page(
        _fields(cv), title, traces=traces, legend=_LEGEND, before=before, initial=1,
        camera={"eye": {"x": 0.55, "y": -0.85, "z": 0.7}},  # the wound, the patch around it
        labels={k: st.label for k, st in enumerate(cv.states, 1)},
    )  # fmt: skip
    data = page.encode("utf-8")
    atomic_write(out / VIEW_HTML, lambda tmp: Path(tmp).write_bytes(data))
    return VIEW_HTML


_LEGEND = (
    "Left: the deformed skin (displacement times the deformation scale), each triangle "
    "coloured by the von Mises stress of the tetrahedron it bounds (its cell mean, kPa); the "
    "colour scale ends at the state's p99 of the volume, the cells above it shaded pale to "
    "deep magenta up to the largest; red: each suture's thread drawn from bite to bite as an "
    "arc above the skin (a drawing of where each suture holds, not the thread's path through "
    "the skin), its force on hover; black: the wound's rim at the skin surface; red "
    "diamond: the cell of the largest cell mean. The cut shows the half y &ge; the wound's "
    "middle. Right: von Mises along the profile lines (reference configuration); below it, "
    "along the wound, the sutures' pull per unit length (closing force) and the walls' "
    "contact force per unit length. Lengths in mm, stresses in kPa, line loads in mN/mm."
)

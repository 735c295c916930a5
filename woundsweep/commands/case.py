"""``woundsweep case --out DIR [--length-mm L] [--width-mm W] [--angle-deg A] ...``: one clinical
case, a fusiform excision closed by simple interrupted sutures, from flags.

Solves the closure at the given angle to the Langer line, the load after closure ("when my
patient itches"; by default across the wound) and the same load along the scan's other
directions, a placement that evens the suture forces (by re-solving), the site's band of skin
types, the same wound along the Langer line and the sutures on a mesh with elements half the
size, and writes DIR/report.md, DIR/case.json and figures (`woundsweep.studies.case`,
`woundsweep.studies.case_report`). Exit status: 0 solved; 2 bad input (one line); 3 a solve did
not converge; 4 the excision could not be meshed.
"""

from __future__ import annotations

import logging
import shlex
import sys
from pathlib import Path

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

__all__ = ["cmd"]

_ITCH = ItchLoad()


# What a case writes into --out (`studies.case_report`).
_REPORT_FILES = ("report.md", "case.json", "forces.png", "wound.png", "view.png")


def _set_aside_previous(out: Path) -> None:
    """Move an earlier case's report files in ``out`` to ``out/previous/`` (kept, not taken
    for this case's), replacing what an earlier failure put there."""
    import os

    found = [out / n for n in _REPORT_FILES if (out / n).is_file() and not (out / n).is_symlink()]
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
def cmd(out: Path, length_mm: float, width_mm: float | None, angle_deg: float, site: str,
        dermis_mm: float | None, subcutis_mm: float | None, depth_mm: float | None, skin: str,
        count: int | None, spacing_mm: float | None, bite_width_mm: float,
        bite_depth_mm: float | None, itch_strain: float, itch_to_wound_deg: float,
        itch_angle_deg: float | None, itch_kind: str, element: int, mesh_factor: float,
        no_even: bool, no_compare: bool, no_band: bool, no_scan: bool, no_mesh_check: bool,
        converge: bool) -> None:  # fmt: skip
    """Solve one clinical case and write its report (the bottom line, forces per suture with
    the site's band, where to place them, what a load after closure does, the forces against
    the literature, the mesh check)."""
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
        )  # fmt: skip
        command = "woundsweep " + " ".join(shlex.quote(a) for a in sys.argv[1:])
        path = write_report(result, out, command)
    except BaseException:
        _set_aside_previous(out)  # a failed case leaves no earlier case's report as its own
        raise
    click.echo(path.read_text())
    click.echo(f"wrote {path}")

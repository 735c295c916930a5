"""OCC model of the fusiform excision's quarter (x <= x_c, y >= 0) for `woundsweep.mesh.build`.

In the quarter the outline is one arc, of the circle centred at (x_c + c, 0) with radius R
(`woundsweep.config.fusiform`), so the cut is a vertical cylinder less the half-space below
the floor's plane z = -d + (x_c - x) tan(beta). The cylinder meets the quarter's mirror face
x = x_c at the apex, at half the apex angle, and the floor meets it on the long axis at z = -d:
both cross the face, so no tool face is coplanar with a box face. The closure zone's border is
imprinted on the wall: the arc z = z_min from y = 0 to y_max (or to the apex) and, when the
zone ends before the apex, the vertical line on the wall at y = y_max (split at the layer
interface).
"""

from __future__ import annotations

import math

import gmsh

from ..config.geometry import GeometrySpec
from ..core.errors import GeometryError

__all__ = ["fusiform_quarter"]


def _zone_border(spec: GeometrySpec) -> list[tuple[int, int]]:
    occ = gmsh.model.occ
    lens = spec.lens()
    R, c, a, x_c = lens.radius, lens.offset, lens.a, lens.x_c
    t_d, T = spec.dermal_thickness_mm, spec.total_thickness_mm
    y_max = spec.zone_y_fraction * spec.wound_half_length_mm
    z_min = -spec.zone_depth_fraction * spec.wound_depth_mm
    tol = 1e-9 * max(spec.patch_half_length_y_mm, T)
    at_apex = y_max >= a - tol
    y_end = a if at_apex else y_max

    def wall_x(y: float) -> float:
        return x_c + c - math.sqrt(R * R - y * y)

    curves = []
    if abs(z_min + t_d) > tol:  # else the layer interface already draws it
        centre = occ.addPoint(x_c + c, 0.0, z_min)
        start = occ.addPoint(x_c - lens.b, 0.0, z_min)
        end = occ.addPoint(x_c if at_apex else wall_x(y_end), y_end, z_min)
        curves.append(occ.addCircleArc(start, centre, end))
    if not at_apex:
        levels = [0.0] + ([-t_d] if z_min < -t_d - tol else []) + [z_min]
        x = wall_x(y_max)
        pts = [occ.addPoint(x, y_max, z) for z in levels]
        curves += [occ.addLine(p, q) for p, q in zip(pts, pts[1:])]
    return [(1, k) for k in curves]


def fusiform_quarter(spec: GeometrySpec) -> None:
    """Build and synchronise the quarter's two conforming layer volumes (GeometryError if the
    cut does not leave one volume per layer)."""
    occ = gmsh.model.occ
    t_d, T, L = spec.dermal_thickness_mm, spec.total_thickness_mm, spec.patch_half_length_mm
    lens = spec.lens()
    x_c, Ly = lens.x_c, spec.patch_half_length_y_mm
    dermis = occ.addBox(-L, 0.0, -t_d, L + x_c, Ly, t_d)
    subcutis = occ.addBox(-L, 0.0, -T, L + x_c, Ly, T - t_d)
    over = 0.25 * T
    R, c = lens.radius, lens.offset
    bottom = -T - over
    cylinder = occ.addCylinder(x_c + c, 0.0, bottom, 0.0, 0.0, T + 2 * over, R)
    # The half-space below the floor's plane, as a prism along y beyond the cylinder.
    span, slope, y0 = 2 * R + L, lens.floor_slope, -(R + over)
    low = min(-lens.d - span * slope, bottom) - over
    corners = [
        (x_c - span, -lens.d + span * slope),
        (x_c + span, -lens.d - span * slope),
        (x_c + span, low),
        (x_c - span, low),
    ]
    pts = [occ.addPoint(x, y0, z) for x, z in corners]
    lines = [occ.addLine(pts[i], pts[(i + 1) % 4]) for i in range(4)]
    section = occ.addPlaneSurface([occ.addCurveLoop(lines)])
    below = [dt for dt in occ.extrude([(2, section)], 0.0, 2 * (R + over), 0.0) if dt[0] == 3]
    tool, _ = occ.cut([(3, cylinder)], below)
    cut, _ = occ.cut([(3, dermis), (3, subcutis)], tool)
    if len(cut) != 2:
        raise GeometryError(f"the wound cut gave {len(cut)} volumes instead of 2")
    occ.fragment(cut[:1], cut[1:] + _zone_border(spec))
    occ.synchronize()

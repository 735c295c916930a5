"""The fusiform (elliptical) excision's geometry in closed form (pure Python).

The outline at the skin surface is a lens of two circular arcs meeting at the apices
(Moody, McCarthy and Sengelmann, Dermatol. Surg. 2001;27:61, "the apical angle"): length l
along y, width w across it, centred on (x_c, 0). With a = l / 2 and b = w / 2 each arc lies
on a circle of radius R = (a^2 + b^2) / (2 b) whose centre is c = (a^2 - b^2) / (2 b) beyond
the long axis, so the half-width at y is sqrt(R^2 - y^2) - c, and the apex angle is
4 arctan(w / l) (74 degrees at l = 3 w; the 30 degrees of the textbooks needs l of about
7.6 w with arcs).

The walls are vertical. The floor is a shallow V with its fold on the long axis at the depth
d and its two planes rising toward the walls by `FLOOR_RISE` d over the half-width b, so the
walls are at least (1 - FLOOR_RISE) d high (at mid-length) and d high at the apices. The fold
keeps the two halves of the floor facing each other as the wound closes (a flat floor would
put the two flanks' contact surfaces in one plane).
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["FLOOR_RISE", "Lens", "lens"]

# The floor rises from the depth d on the long axis by FLOOR_RISE * d at the walls' widest.
FLOOR_RISE = 0.25


class Lens(NamedTuple):
    """A fusiform excision of length ``2 a``, width ``2 b`` and depth ``d`` centred on x_c."""

    a: float  # half-length (mm)
    b: float  # half-width (mm)
    d: float  # depth on the long axis (mm)
    x_c: float  # the long axis' x (mm)

    @property
    def radius(self) -> float:
        """R, the arcs' radius (mm)."""
        return (self.a**2 + self.b**2) / (2 * self.b)

    @property
    def offset(self) -> float:
        """c, the distance (mm) from the long axis to the centre of the other side's arc."""
        return (self.a**2 - self.b**2) / (2 * self.b)

    @property
    def half_angle(self) -> float:
        """phi (rad): each arc subtends 2 phi at its centre (sin phi = a / R)."""
        return math.atan2(self.a, self.offset)

    @property
    def apex_angle_deg(self) -> float:
        """The angle between the two arcs at an apex: 4 arctan(w / l)."""
        return math.degrees(4 * math.atan(self.b / self.a))

    @property
    def floor_slope(self) -> float:
        """tan of the floor's inclination: FLOOR_RISE d over the half-width b."""
        return FLOOR_RISE * self.d / self.b

    def half_width(self, y: float) -> float:
        """The half-width (mm) of the outline at y (0 beyond the apices)."""
        if abs(y) >= self.a:
            return 0.0
        return math.sqrt(self.radius**2 - y * y) - self.offset

    def floor_z(self, x: float) -> float:
        """z of the floor below x."""
        return -self.d + abs(x - self.x_c) * self.floor_slope

    def area(self) -> float:
        """The outline's area (mm^2): two circular segments."""
        R, c, phi = self.radius, self.offset, self.half_angle
        return 2 * (R * R * phi - self.a * c)

    def rim_length(self) -> float:
        """The outline's length (mm): two arcs of angle 2 phi."""
        return 4 * self.radius * self.half_angle

    def volume(self) -> float:
        """The excised volume (mm^3): d A - tan(beta) * integral of b(y)^2 over y."""
        R, c, phi, a = self.radius, self.offset, self.half_angle, self.a
        b2 = 2 * a * (R * R + c * c) - 2 * a**3 / 3 - 2 * c * (a * c + R * R * phi)
        return self.d * self.area() - self.floor_slope * b2

    def distance(self, x: float, y: float, z: float) -> float:
        """Distance (mm) from a point of the patch to the excision: in plan to the outline,
        combined with the height below the floor at the nearest point of the outline."""
        R, c = self.radius, self.offset
        # Fold onto the left half (x <= x_c), y >= 0, where the outline is the arc of the
        # circle centred at (x_c + c, 0).
        px, py = self.x_c - abs(x - self.x_c), abs(y)
        dx, dy = px - (self.x_c + c), py
        r = math.hypot(dx, dy)
        if r <= R:
            plan, nx = 0.0, px
        else:
            nx = self.x_c + c + R * dx / r
            if nx <= self.x_c:
                plan = r - R
            else:  # nearest is the apex
                nx = self.x_c
                plan = math.hypot(px - self.x_c, py - self.a)
        below = max(0.0, self.floor_z(nx) - z)
        return math.hypot(plan, below)


def lens(length_mm: float, width_mm: float, depth_mm: float, x_c: float) -> Lens:
    """The `Lens` of an excision of the given length, width and depth centred on x_c."""
    return Lens(length_mm / 2, width_mm / 2, depth_mm, x_c)

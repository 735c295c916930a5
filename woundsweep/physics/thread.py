"""Sutures as threads on a wound mesh: the suture material, the needle tracks and the anchor
regions the threads pull on (docs/model.md, "Sutures as threads").

A simple interrupted suture enters the skin a bite width b from the wound's edge, runs
through the flank along the needle track to the wall at the bite depth, crosses the wound and
returns symmetrically through the other flank; its knot closes the loop above the skin. A
thread that slides in a straight track pulls on the tissue only where it turns: where it
enters the skin (the knot's strand lies on the skin, crossing the wound) and where it leaves
the wall (the buried strand crosses beneath). So a suture is a closed loop through four
anchors (`suture_loop`), the entry and the wall exit of each flank's needle track
(`needle_track`), each the tissue within a radius r of its point (`point_anchor`), coupled by
the weights

    w_k = int phi N_k dV / int phi dV,   phi = (1 - (rho / r)^2)^2 for rho < r,

rho the distance from the point, N_k the displacement's basis functions: the anchor point is
the phi-weighted mean of the deformed positions around it (a distributing coupling, as an
RBE3 element), so the pull spreads over the tissue the thread bears on, no node is held, and
the weights do not depend on the mesh beyond the integral's error (a grid of points
`GRID_PER_RADIUS` to a radius, so meshes coarser than r still see the region). The thread
slides freely, so the whole loop carries one tension T (`woundsweep.contact.cable`); its two
crossing strands pull each flank toward the other with 2 T, the knot's at the skin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..contact import Anchor
from .element import EDGES

if TYPE_CHECKING:
    from .domain import WoundDomain

__all__ = [
    "ANCHOR_RADIUS_mm",
    "needle_track",
    "point_anchor",
    "suture_loop",
    "GRID_PER_RADIUS",
    "NYLON_4_0",
    "SutureThread",
]

ANCHOR_RADIUS_mm = 1.0
GRID_PER_RADIUS = 5


@dataclass(frozen=True)
class SutureThread:
    """A suture material: ``diameter_mm`` and Young's modulus ``modulus_kPa``."""

    name: str
    diameter_mm: float
    modulus_kPa: float
    breaking_force_N: tuple[float, float]  # the range its straight pull breaks in

    @property
    def area_mm2(self) -> float:
        return math.pi * self.diameter_mm**2 / 4

    @property
    def EA_mN(self) -> float:
        """The thread's axial stiffness (mN)."""
        return self.modulus_kPa * self.area_mm2


# 4-0 monofilament nylon. Diameter: the United States Pharmacopeia's range for size 4-0
# synthetic sutures, 0.150-0.199 mm (USP <861>), its middle. Modulus: polyamide 6
# monofilament, 2 GPa nominal (Naleway et al., J. Biomed. Mater. Res. B 103:735, 2015,
# tensile-tested cutaneous sutures of size 3-0: nylon's initial modulus is of order GPa,
# three to four decades above the skin's); the tension does not depend on it
# (docs/validation.md, "Sutures as threads"). Breaking force: 3-0 nylon broke at 30.9 N
# unknotted in that study; 4-0 has about half the cross-section, so 10-15 N is taken.
NYLON_4_0 = SutureThread("4-0 nylon", 0.175, 2.0e6, (10.0, 15.0))


def _basis(lam: np.ndarray, degree: int) -> np.ndarray:
    """(p, 4 or 10) Lagrange basis at barycentric coordinates ``lam`` (p, 4), DOLFINx order."""
    if degree == 1:
        return lam
    out = np.empty((len(lam), 10))
    out[:, :4] = lam * (2.0 * lam - 1.0)
    for e, (i, j) in enumerate(EDGES):
        out[:, 4 + e] = 4.0 * lam[:, i] * lam[:, j]
    return out


def point_anchor(
    domain: WoundDomain, point: np.ndarray, side: int, radius_mm: float = ANCHOR_RADIUS_mm
) -> Anchor:
    """The anchor at ``point`` (reference coordinates, mm) in the flank on ``side`` of the
    wound (-1: x < x_c, +1: x > x_c): the nodes and weights of the module docstring.
    ValueError if no tissue lies within the radius."""
    a = np.asarray(point, dtype=float)
    h = radius_mm / GRID_PER_RADIUS
    lo, hi = a - radius_mm, a + radius_mm
    # The grid is centred on the point, so that mirror-image points get mirror-image grids
    # (and weights) and a symmetric placement keeps the problem symmetric.
    offsets = h * (np.arange(-(radius_mm // h) - 1, radius_mm // h + 1) + 0.5)
    axes = [a[k] + offsets for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    rho = np.linalg.norm(grid - a, axis=1)
    keep = (rho < radius_mm) & (side * (grid[:, 0] - domain.x_c) > 0)
    grid, rho = grid[keep], rho[keep]
    phi = (1.0 - (rho / radius_mm) ** 2) ** 2
    # Candidate cells: those whose vertices' box meets the region's.
    Xv = domain.X[domain.cell_vertices]
    near = np.all((Xv.max(axis=1) >= lo) & (Xv.min(axis=1) <= hi), axis=1)
    cand = np.flatnonzero(near)
    if len(cand) == 0 or len(grid) == 0:
        raise ValueError("no tissue within the anchor radius of the thread's turn")
    X0 = domain.X[domain.cell_vertices[cand, 0]]
    Dinv = domain.Dm_inv[cand]
    cell = np.full(len(grid), -1, dtype=np.int64)
    lam = np.zeros((len(grid), 4))
    best = np.full(len(grid), -np.inf)
    for start in range(0, len(grid), 256):
        g = grid[start : start + 256]
        l3 = np.einsum("mij,pmj->pmi", Dinv, g[:, None, :] - X0[None, :, :])
        low = np.minimum(l3.min(axis=2), 1.0 - l3.sum(axis=2))
        k = np.argmax(low, axis=1)
        rows = np.arange(len(g))
        sl = slice(start, start + len(g))
        best[sl] = low[rows, k]
        cell[sl] = k
        sel = l3[rows, k]
        lam[sl] = np.column_stack([1.0 - sel.sum(axis=1), sel])
    inside = best >= -1e-9
    if not inside.any():
        raise ValueError("no tissue within the anchor radius of the thread's turn")
    nodes_per_cell = domain.cell_nodes[cand[cell[inside]]]
    N = _basis(lam[inside], domain.degree) * phi[inside, None]
    nodes, inv = np.unique(nodes_per_cell.ravel(), return_inverse=True)
    w = np.bincount(inv, weights=N.ravel(), minlength=len(nodes))
    keep_w = np.abs(w) > 1e-14 * np.abs(w).max()
    nodes, w = nodes[keep_w], w[keep_w]
    return Anchor(nodes.astype(np.int64), w / w.sum())


def needle_track(
    domain: WoundDomain, half_width_mm: float, y_mm: float, bite_width_mm: float, depth_mm: float
) -> np.ndarray:
    """(2, 2, 3): per flank (left, right) the needle track's entry (on the surface,
    ``bite_width_mm`` from the edge) and exit (on the wall, ``depth_mm`` below the surface) at
    ``y_mm``, reference coordinates (mm); ``half_width_mm``: the wound's half-width there."""
    d = domain
    out = np.empty((2, 2, 3))
    for k, s in enumerate((-1.0, 1.0)):
        out[k, 0] = (d.x_c + s * (half_width_mm + bite_width_mm), y_mm, d.z_top)
        out[k, 1] = (d.x_c + s * half_width_mm, y_mm, d.z_top - depth_mm)
    return out


def suture_loop(
    domain: WoundDomain, track: np.ndarray, radius_mm: float = ANCHOR_RADIUS_mm
) -> list[Anchor]:
    """One suture's loop (module docstring) through the anchors of its turns, in the
    thread's order: the left entry, the left wall exit, the right wall exit, the right entry
    (``track`` from `needle_track`)."""
    return [
        point_anchor(domain, track[0, 0], -1, radius_mm),
        point_anchor(domain, track[0, 1], -1, radius_mm),
        point_anchor(domain, track[1, 1], 1, radius_mm),
        point_anchor(domain, track[1, 0], 1, radius_mm),
    ]

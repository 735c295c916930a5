"""The closure along the wound's line: how far the sutured zone stands open, and the closing
and contact forces per unit length along the wound (docs/model.md, "Closure measures").

Each zone node of the left flank is paired with its mirror image on the right flank (the mesh
is mirror-symmetric about x = x_c). A pair's gap is the x-distance (deformed) from the left
node to the right one: 0 where the flanks meet, positive where the wound stands open,
negative where the right node has passed the left one (overlap). The gap is measured at the
skin surface (the pairs at the top, z = z_top); the overlap over the whole zone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "CLOSED_MAX_PER_W",
    "CLOSED_MEDIAN_PER_W",
    "OVERLAP_PER_W",
    "ClosureLine",
    "ClosureMeasures",
    "LineLoads",
]

# A stage's sutured zone is closed when the surface gap is at most 1 % of the wound width at
# the median pair and 5 % at the widest; mirrored zone points overlap when the right one has
# passed the left one by more than 1 % of w (the contact's penetration is far below it).
CLOSED_MEDIAN_PER_W = 0.01
CLOSED_MAX_PER_W = 0.05
OVERLAP_PER_W = 0.01
# A line-load bin spans at least this many node spacings along the wound (two P2 elements),
# so the alternating vertex and edge-node shares of a consistent nodal load average out.
_BIN_SPACINGS = 4
_MAX_BINS = 60


class ClosureMeasures(NamedTuple):
    """The closure of one state (mm; ``*_per_w`` as fractions of the wound width)."""

    gap_min_mm: float
    gap_median_mm: float
    gap_max_mm: float
    overlap_mm: float
    width_mm: float

    @property
    def gap_median_per_w(self) -> float:
        return self.gap_median_mm / self.width_mm

    @property
    def gap_max_per_w(self) -> float:
        return self.gap_max_mm / self.width_mm

    @property
    def closed(self) -> bool:
        """The surface gap within the stated tolerances (module constants)."""
        return (
            self.gap_median_per_w <= CLOSED_MEDIAN_PER_W and self.gap_max_per_w <= CLOSED_MAX_PER_W
        )

    @property
    def interpenetrating(self) -> bool:
        """Mirrored zone points overlap by more than `OVERLAP_PER_W` of the width."""
        return self.overlap_mm > OVERLAP_PER_W * self.width_mm

    def columns(self) -> dict[str, float]:
        """The store's columns of these measures."""
        return {
            "closure_gap_min_mm": self.gap_min_mm,
            "closure_gap_median_mm": self.gap_median_mm,
            "closure_gap_max_mm": self.gap_max_mm,
            "closure_gap_median_per_w": self.gap_median_per_w,
            "closure_gap_max_per_w": self.gap_max_per_w,
            "closure_overlap_mm": self.overlap_mm,
        }


class LineLoads(NamedTuple):
    """Forces per unit length (mN/mm) along the wound, at bin centres ``y_mm``."""

    y_mm: np.ndarray
    closing_mN_per_mm: np.ndarray
    contact_mN_per_mm: np.ndarray


class ClosureLine:
    """The mirror pairs of a closure zone and the bins along the wound.

    ``X`` (n, 3) reference node coordinates, ``pairs`` (p, 2) left and right node of each
    mirror pair of the zone (`woundsweep.contact.ZoneTie.pairs`), ``left_wound_nodes`` every
    node of the left flank (for the contact's line load), ``z_top`` the skin surface.
    """

    def __init__(
        self, X: np.ndarray, pairs: np.ndarray, left_wound_nodes: np.ndarray, z_top: float
    ) -> None:
        self.pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if len(self.pairs) == 0:
            raise ValueError("the closure zone has no mirror pairs")
        tol = 1e-9 * float(np.ptp(X, axis=0).max())
        self.surface = self.pairs[np.abs(X[self.pairs[:, 0], 2] - z_top) <= tol]
        if len(self.surface) == 0:
            raise ValueError("the closure zone does not reach the skin surface")
        ref = X[self.surface[:, 1], 0] - X[self.surface[:, 0], 0]
        self.width_mm = float(ref.max())
        self.X = X
        self.left_wound_nodes = np.asarray(left_wound_nodes, dtype=np.int64)
        y = X[self.left_wound_nodes, 1]
        lo, hi = float(y.min()), float(y.max())
        spacing = np.diff(np.unique(np.round(X[self.surface[:, 0], 1], 9)))
        step = float(np.median(spacing)) if len(spacing) else hi - lo
        n = int(np.clip((hi - lo) / (_BIN_SPACINGS * max(step, 1e-12)), 1, _MAX_BINS))
        self.edges = np.linspace(lo, hi, n + 1)

    def measure(self, u: np.ndarray) -> ClosureMeasures:
        """The closure of the displacement ``u`` (flat dofs)."""
        x = self.X[:, 0] + u.reshape(-1, 3)[:, 0]
        gap_all = x[self.pairs[:, 1]] - x[self.pairs[:, 0]]
        gap = x[self.surface[:, 1]] - x[self.surface[:, 0]]
        return ClosureMeasures(
            float(gap.min()),
            float(np.median(gap)),
            float(gap.max()),
            float(max(0.0, -gap_all.min())),
            self.width_mm,
        )

    def _per_length(self, f: np.ndarray) -> np.ndarray:
        """Sum of the x-forces ``f`` (flat dofs) on the left flank's nodes per bin, per mm.

        A node on an inner bin edge (within a billionth of the wound's extent) gives half its
        force to each of the two bins, so mirror-image nodes about the wound's mid-line land
        in mirror-image bins and a symmetric wound has a symmetric profile: with a one-sided
        rule the zone's end nodes, which lie on edges, fall inward at one end and outward at
        the other.
        """
        nodes = self.left_wound_nodes
        fx = f.reshape(-1, 3)[nodes, 0]
        bins = len(self.edges) - 1
        y = self.X[nodes, 1]
        tol = 1e-9 * max(float(self.edges[-1] - self.edges[0]), 1e-12)
        above = np.clip(np.searchsorted(self.edges, y + tol, side="right") - 1, 0, bins - 1)
        below = np.clip(np.searchsorted(self.edges, y - tol, side="right") - 1, 0, bins - 1)
        total = np.bincount(above, weights=0.5 * fx, minlength=bins)
        total += np.bincount(below, weights=0.5 * fx, minlength=bins)
        return total / np.diff(self.edges)

    def line_loads(self, closing: np.ndarray | None, contact: np.ndarray | None) -> LineLoads:
        """Line loads on the left flank of the closing forces (``closing``: nodal forces, +x
        toward the mid-plane) and of the contact (``contact``: its residual term dPi_c/du,
        +x where the right flank pushes the left one away); flat dof vectors or None (0)."""
        n = len(self.edges) - 1
        zero = np.zeros(n)
        close = zero if closing is None else self._per_length(closing)
        touch = zero if contact is None else self._per_length(contact)
        centres = 0.5 * (self.edges[1:] + self.edges[:-1])
        return LineLoads(centres, close, touch)

"""The coupling pattern of the flank contact (`woundsweep.contact.smooth`): its planned pairs.

The tangent of an engaged point couples its node with the nodes of all its facets, so the
pattern is that clique per point over its planned facets. A plan at a state takes the points
that are engaged there or nearly so (g <= ``gap`` h, or a compressive multiplier), each with
the facets within (1 + ``margin``) kernel radii; most points of a flank never touch, and
leaving them out keeps the explicit zeros, and so the factorisation, small. A tangent with an
engaged pair outside the plan adds a plan at its state to the old one before it is returned
(`CouplingPlan.grow`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .surfaces import FlankPass, near_pairs

__all__ = ["PATTERN_GAP", "PATTERN_MARGIN", "CouplingPlan"]

# Margins of the plan (module docstring): the gap, in element sizes h, below which a point is
# planned, and the extra kernel radius of its facets. Wide enough that a contact stage rarely
# leaves the plan (each growth costs MUMPS a new analysis; paper job 7369 grows twice in
# stage 4's 35 steps), narrow enough that its explicit zeros add little to the factorisation
# (the plan at the start of stage 4 has 4-6 % more entries than the finite-element pattern
# with every tangent of stages 4-6, jobs 6367 and 7369).
PATTERN_GAP, PATTERN_MARGIN = 0.1, 0.1


class CouplingPlan:
    """The planned (point, facet) pairs of the ``passes`` and the pattern they allow.

    ``offsets`` are the passes' first points in the all-points numbering, ``n_nodes`` the
    node count. ``version`` changes whenever the pattern does (set, grown or cleared);
    ``growths`` counts the growths.
    """

    def __init__(
        self,
        passes: tuple[FlankPass, ...],
        offsets: tuple[int, ...],
        n_nodes: int,
        gap: float = PATTERN_GAP,
        margin: float = PATTERN_MARGIN,
    ) -> None:
        self.passes, self.offsets, self.n_nodes = passes, offsets, n_nodes
        self.n_points = sum(len(ps.nodes) for ps in passes)
        self.gap = float(gap)
        self.margin = float(margin)
        # Per pass the sorted keys q * n_facets + f of the planned pairs; None: no plan.
        self._keys: list[np.ndarray] | None = None
        self._structure: Any = None  # structure(), built on demand
        self.version = 0
        self.growths = 0

    def _plan(self, x: np.ndarray, gap: np.ndarray, mult: np.ndarray | None) -> list[np.ndarray]:
        """Planned pairs (keys) at positions ``x`` with gaps ``gap`` (module docstring)."""
        size = np.concatenate([ps.size_mm for ps in self.passes])
        near = gap <= self.gap * size
        if mult is not None:
            near |= mult < 0.0
        keys = []
        for ps, off in zip(self.passes, self.offsets):
            q, f = near_pairs(x, ps, 1.0 + self.margin)
            keep = near[off + q]
            keys.append(q[keep] * len(ps.facets) + f[keep])
        return keys

    def set(self, x: np.ndarray, gap: np.ndarray, mult: np.ndarray | None) -> None:
        """Plan at positions ``x`` with gaps ``gap`` and multipliers ``mult`` (or None)."""
        self._keys = self._plan(x, gap, mult)
        self._structure = None
        self.version += 1

    def grow(self, x: np.ndarray, gap: np.ndarray, mult: np.ndarray | None) -> None:
        """Add a plan at positions ``x`` (as `set`) to the planned pairs."""
        assert self._keys is not None
        new = self._plan(x, gap, mult)
        self._keys = [np.union1d(a, b) for a, b in zip(self._keys, new)]
        self._structure = None
        self.version += 1
        self.growths += 1

    def clear(self) -> None:
        """Drop the plan."""
        self._keys = None
        self._structure = None
        self.version += 1

    def covers(self, i: int, q: np.ndarray, f: np.ndarray) -> bool:
        """Whether every pair (``q``, ``f``) of pass ``i`` is planned (True without a plan)."""
        if self._keys is None:
            return True
        plan = self._keys[i]
        key = q * len(self.passes[i].facets) + f
        at = np.searchsorted(plan, key)
        inside = at < len(plan)
        inside[inside] = plan[at[inside]] == key[inside]
        return bool(inside.all())

    def structure(self) -> Any:
        """Structure (scipy CSR of ones, 3 n_nodes square) of every tangent entry the planned
        pairs allow: per point, its node and its planned facets' nodes coupled pairwise with
        all three components; None without a plan."""
        import scipy.sparse

        if self._keys is None:
            return None
        if self._structure is None:
            pts, nodes = [], []
            for ps, off, keys in zip(self.passes, self.offsets, self._keys):
                q, f = np.divmod(keys, max(len(ps.facets), 1))
                pts.append(np.repeat(off + q, 4))
                nodes.append(np.concatenate([ps.nodes[q][:, None], ps.facets[f]], axis=1).ravel())
            rows, cols = np.concatenate(pts), np.concatenate(nodes)
            shape = (self.n_points, self.n_nodes)
            B = scipy.sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=shape)
            B.data[:] = 1.0
            G = (B.T @ B).tocsr()  # nodes that share a point
            G.data[:] = 1.0
            P = scipy.sparse.kron(G, np.ones((3, 3)), format="csr")
            P.sort_indices()
            self._structure = P
        return self._structure

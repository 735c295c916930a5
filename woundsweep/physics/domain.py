"""The discretised wound patch: the DOLFINx mesh, its P1 or P2 space and the sets the stages
act on.

`WoundDomain` holds the node and facet sets of the boundary conditions (x and y faces, deep
face), the wound's mirror plane and depth, the closure zone on both flanks (the mesh's
WOUND_ZONE facets and their nodes), the two point constraints that remove rigid in-plane
motion, the facet tags of the solver's integrals, and the kinematics of the displacement
(`element`: gradient, det F). Node indices are DOLFINx dof-node indices (dof ``3 i + c`` is
component c of node i; P2 nodes include the edge midpoints); ``input_node`` maps input
points to their vertex nodes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.spatial

from ..config.paper import ClosureZone
from ..config.solver import DEGREES, SolverSettings
from ..contact.geometry import owning_cells
from ..contact.surfaces import triangle_areas
from ..core.schema import (
    BOTTOM,
    DERMIS,
    SUBCUTIS,
    WOUND_TAGS,
    WOUND_ZONE,
    X_MAX,
    X_MIN,
    Y_MAX,
    Y_MIN,
    MeshData,
)
from ..solver.symmetry import Isometry, SymmetryBasis, mirror_node_map, symmetry_basis
from . import compat
from .element import Element

__all__ = [
    "LATERAL_DERMIS",
    "LATERAL_SUBCUTIS",
    "WoundDomain",
    "dof_rows",
]

# Facet ids the solver derives for its integrals (not part of the mesh contract).
LATERAL_DERMIS, LATERAL_SUBCUTIS = 101, 102


def dof_rows(nodes: Any, comp: int) -> np.ndarray:
    """Flat dof indices of component ``comp`` of ``nodes``."""
    return (3 * np.asarray(nodes, dtype=np.int64) + comp).astype(np.int32)


class WoundDomain:
    """Mesh, space, index maps, boundary sets and closure zone of one wound patch.

    ``mesh_data`` is a `MeshData` (docs/design.md). The closure zone is the mesh's
    WOUND_ZONE facets; ``zone``, when given, must be the one the mesh was built with
    (``info["closure_zone"]``, if recorded). ``degree`` is the displacement element's (1 or
    2). Raises ValueError for a mesh that does not fit the contract (unused points, no deep
    face or x faces, another closure zone).
    """

    def __init__(
        self,
        mesh_data: MeshData,
        zone: ClosureZone | None = None,
        degree: int = SolverSettings.element_degree,
    ) -> None:
        if degree not in DEGREES:
            raise ValueError(f"element degree {degree!r}: expected one of {DEGREES}")
        built = (getattr(mesh_data, "info", None) or {}).get("closure_zone")
        # A zone whose depth scales with the wound width was resolved for this wound when
        # the mesh was built: only its y extent is compared.
        keys = ("y_fraction",) if zone is not None and zone.depth_per_w else built or ()
        if zone is not None and built is not None:
            if any(built[k] != getattr(zone, k) for k in keys):
                raise ValueError(f"the mesh's closure zone {built} is not the sweep's {zone}")
        self.zone_spec = zone or (ClosureZone(**built) if built else ClosureZone())
        pts = np.asarray(mesh_data.points, dtype=float)
        cells = np.asarray(mesh_data.cells, dtype=np.int64)
        ctags = np.asarray(mesh_data.cell_tags, dtype=np.int32)
        facets = np.asarray(mesh_data.facets, dtype=np.int64)
        ftags = np.asarray(mesh_data.facet_tags, dtype=np.int32)
        self.points, self.cells, self.cell_tags = pts, cells, ctags
        self.facets, self.facet_tags = facets, ftags
        self.mesh, self.cell_mt, self.facet_mt = compat.mesh_from_arrays(
            pts, cells, ctags, facets, ftags
        )
        self.degree = degree
        self.V = compat.vector_space(self.mesh, degree)
        self.node_input = compat.node_input_index(self.V)  # -1 for P2's edge nodes
        self.cell_input = compat.cell_input_index(self.mesh)
        vertex = np.flatnonzero(self.node_input >= 0)
        self.input_node = np.full(len(pts), -1, dtype=np.int64)
        self.input_node[self.node_input[vertex]] = vertex
        if np.any(self.input_node < 0):
            raise ValueError("the mesh has points that belong to no cell")
        # Reference coordinates of the nodes (the vertices' exactly the input points).
        self.X = compat.node_coordinates(self.V)
        self.X[vertex] = pts[self.node_input[vertex]]
        self.cell_nodes = compat.cell_dofs(self.V)  # (m, 4 or 10) node indices, cell order
        self.cell_vertices = self.cell_nodes[:, :4]
        self._prepare_kinematics()
        self._symmetry: dict[bool, SymmetryBasis | None] = {}
        self.element = Element(self.X, self.cell_nodes, self.Dm_inv)
        self._classify(facets, ftags)

    @property
    def n_dofs(self) -> int:
        return 3 * len(self.X)

    def wound_facets(self) -> np.ndarray:
        """The wound surface's facets (k, 3) in vertex node indices, the zone included (each
        is split into flat triangles through all its nodes by ``element.sub_triangles``)."""
        return self.input_node[self.facets[np.isin(self.facet_tags, WOUND_TAGS)]]

    # -- kinematics -------------------------------------------------------------------------

    def _prepare_kinematics(self) -> None:
        Xc = self.X[self.cell_vertices]  # (m, 4, 3)
        Dm = np.transpose(Xc[:, 1:, :] - Xc[:, :1, :], (0, 2, 1))  # columns = edges
        det = np.linalg.det(Dm)
        self.ref_det = det
        self.volumes = np.abs(det) / 6.0
        self.Dm_inv = np.linalg.inv(Dm)
        self.midpoints = Xc.mean(axis=1)
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        self.bbox = (lo, hi)
        self.ell = float(np.linalg.norm(hi - lo))

    def grad(self, w: np.ndarray) -> np.ndarray:
        """Gradients (p, 3, 3) of a vector field given as flat dofs (`Element.grad`)."""
        return self.element.grad(w)

    def min_det(self, u: np.ndarray) -> float:
        """Smallest det F at displacement ``u`` (per P1 cell, at P2 cells' quadrature points)."""
        G = self.grad(u)
        G[:, 0, 0] += 1.0
        G[:, 1, 1] += 1.0
        G[:, 2, 2] += 1.0
        return float(np.linalg.det(G).min())

    def max_strain(self, du: np.ndarray) -> float:
        """Largest Frobenius norm of grad(du) (per P1 cell, at P2 cells' quadrature points)."""
        return float(np.sqrt(np.max(np.sum(self.grad(du) ** 2, axis=(1, 2)), initial=0.0)))

    # -- boundary sets ----------------------------------------------------------------------

    def _nodes_of(self, mask: np.ndarray) -> np.ndarray:
        return self.element.triangle_nodes(self.input_node[self.facets[mask]])

    def _classify(self, facets: np.ndarray, ftags: np.ndarray) -> None:
        """Node sets for the boundary conditions and derived facet tags for the integrals."""
        self.x_face_nodes = self._nodes_of(np.isin(ftags, (X_MIN, X_MAX)))
        self.y_face_nodes = self._nodes_of(np.isin(ftags, (Y_MIN, Y_MAX)))
        self.bottom_nodes = self._nodes_of(ftags == BOTTOM)
        if len(self.bottom_nodes) == 0 or len(self.x_face_nodes) == 0:
            raise ValueError("the mesh has no tagged deep face or x faces")
        lo, hi = self.bbox
        self.x_c = 0.5 * (lo[0] + hi[0])
        self.y_c = 0.5 * (lo[1] + hi[1])
        self.half_length_y = 0.5 * (hi[1] - lo[1])
        self.z_top = float(hi[2])
        zone_left, zone_right = self._closure_zone(facets, ftags)
        # The zone's flat triangles in node indices, per flank.
        self.zone_left_facets = self.element.sub_triangles(self.input_node[facets[zone_left]])
        self.zone_right_facets = self.element.sub_triangles(self.input_node[facets[zone_right]])
        self.zone_left_nodes = self.zone_nodes[self.X[self.zone_nodes, 0] < self.x_c]
        self.zone_right_nodes = self.zone_nodes[self.X[self.zone_nodes, 0] >= self.x_c]
        lateral = np.flatnonzero(np.isin(ftags, (X_MIN, X_MAX, Y_MIN, Y_MAX)))
        owner = owning_cells(self.cells, facets[lateral], len(self.points))
        layer = np.where(self.cell_tags[owner] == DERMIS, LATERAL_DERMIS, LATERAL_SUBCUTIS)
        area = triangle_areas(self.points[facets[lateral]])
        on_xmax = ftags[lateral] == X_MAX
        self.x_max_area = {
            DERMIS: float(area[on_xmax & (layer == LATERAL_DERMIS)].sum()),
            SUBCUTIS: float(area[on_xmax & (layer == LATERAL_SUBCUTIS)].sum()),
        }
        self.solver_facet_mt = compat.facet_meshtags(self.mesh, facets[lateral], layer)
        self._point_constraints()

    def _closure_zone(self, facets: np.ndarray, ftags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Set the wound's mirror plane, depth and zone nodes; return the zone's facet indices
        (the WOUND_ZONE facets) on the left and right flank."""
        wound_mask = np.isin(ftags, WOUND_TAGS)
        self.has_wound = bool(wound_mask.any())
        empty = np.zeros(0, dtype=np.int64)
        self.zone_nodes = empty
        self.wound_depth = 0.0
        if not self.has_wound:
            return empty, empty
        p = self.points
        wound_pts = np.unique(facets[wound_mask])
        wx = p[wound_pts, 0]
        # The wound's mirror plane; the patch centre for the symmetric paper geometries.
        self.x_c = 0.5 * (wx.min() + wx.max())
        self.wound_depth = float(self.z_top - p[wound_pts, 2].min())
        zf = np.flatnonzero(ftags == WOUND_ZONE)
        self.zone_nodes = self.element.triangle_nodes(self.input_node[facets[zf]])
        left = p[facets[zf]].mean(axis=1)[:, 0] < self.x_c
        return zf[left], zf[~left]

    def _point_constraints(self) -> None:
        """In-plane gauge for stages 2+: nodes of the deep face near its centre line. The
        rotation is held at two nodes, mirror images about y = y_c, so the gauge shares the
        patch's mirror and half-turn symmetries (`symmetry`)."""
        zb = self.X[self.bottom_nodes]

        def nearest(target: tuple[float, float]) -> int:
            d = (zb[:, 0] - target[0]) ** 2 + (zb[:, 1] - target[1]) ** 2
            return int(self.bottom_nodes[np.argmin(d)])

        self.pin_a = nearest((self.x_c, self.y_c))
        self.pin_b = nearest((self.x_c, self.y_c + 0.5 * self.half_length_y))
        self.pin_c = nearest((self.x_c, self.y_c - 0.5 * self.half_length_y))

    def symmetry(self, mirrors: bool) -> SymmetryBasis | None:
        """The basis of the displacement fields symmetric under the patch's mirrors about
        x = x_c and y = y_c (``mirrors``), or under the half-turn about their common line;
        None when the mesh does not map onto itself."""
        if mirrors not in self._symmetry:
            c = np.array([2 * self.x_c, 2 * self.y_c, 0.0])
            flips = [np.array([-1.0, 1.0, 1.0]), np.array([1.0, -1.0, 1.0])]
            if not mirrors:
                flips = [flips[0] * flips[1]]
            gens: list[Isometry] = []
            for f in flips:
                image = np.where(f < 0, c - self.X, self.X)
                nodes = mirror_node_map(self.X, image, 1e-9 * self.ell)
                if nodes is None:
                    gens = []
                    break
                gens.append(Isometry(nodes, f))
            self._symmetry[mirrors] = symmetry_basis(gens) if gens else None
        return self._symmetry[mirrors]

    def pin_rows(self) -> np.ndarray:
        """Dofs of the point constraints: u_x, u_y at ``pin_a``, u_x at ``pin_b`` and
        ``pin_c``."""
        return np.concatenate(
            [
                dof_rows([self.pin_a], 0),
                dof_rows([self.pin_a], 1),
                dof_rows([self.pin_b, self.pin_c], 0),
            ]
        )

    def gauge_rows(self) -> np.ndarray:
        """Dofs held in stages 2-6: u_z of the deep face and the point constraints."""
        return np.concatenate([dof_rows(self.bottom_nodes, 2), self.pin_rows()])

    # -- measures of a state ----------------------------------------------------------------

    def near_wound_cells(self) -> np.ndarray | None:
        """Cells (bool, mesh order) whose midpoint lies within one total thickness of the
        wound's surface (reference configuration); None without a wound."""
        if not self.has_wound:
            return None
        if not hasattr(self, "_near_wound"):
            wound = np.unique(self.wound_facets())
            thickness = float(self.z_top - self.bbox[0][2])
            dist, _ = scipy.spatial.cKDTree(self.X[wound]).query(self.midpoints)
            self._near_wound = dist <= thickness
        return self._near_wound

    def deformed_zone_area(self, side: str, u: np.ndarray) -> float:
        """Deformed area (mm^2) of one flank's closure-zone triangles at the displacement
        dofs ``u`` (exact for P1; for P2 the area of the four flat triangles per facet)."""
        tri = self.zone_left_facets if side == "left" else self.zone_right_facets
        if len(tri) == 0:
            return 0.0
        return float(triangle_areas((self.X + u.reshape(-1, 3))[tri]).sum())

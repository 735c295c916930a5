"""Uniform refinement (`woundsweep.mesh.refine`): nested, volume- and area-preserving, tagged."""

from __future__ import annotations

import numpy as np
import pytest
from box_mesh import boundary_facets, box_tets

from woundsweep.config.geometry import GeometrySpec
from woundsweep.core.schema import WOUND_ZONE
from woundsweep.mesh.build import MeshData, build_mesh
from woundsweep.mesh.refine import refine_uniform


def volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    p = points[cells]
    return (
        np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6
    )


def normals(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p = points[tris]
    return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def box(n: int = 2) -> MeshData:
    points, cells = box_tets(n, (0.0, 0.0, 0.0), (1.0, 2.0, 0.5))
    cells = cells.astype(np.int64)
    neg = volumes(points, cells) < 0
    cells[neg] = cells[neg][:, [1, 0, 2, 3]]
    facets = boundary_facets(cells).astype(np.int64)
    tags = np.where(points[facets].mean(axis=1)[:, 2] > 0.49, 7, 3).astype(np.int32)
    cell_tags = np.where(points[cells].mean(axis=1)[:, 0] < 0.5, 1, 2).astype(np.int32)
    return MeshData(points, cells, cell_tags, facets, tags, {"cells": len(cells)})


def test_children_fill_their_parent_with_positive_volumes() -> None:
    coarse = box()
    fine = refine_uniform(coarse)
    assert fine.cells.shape == (8 * len(coarse.cells), 4)
    v = volumes(fine.points, fine.cells)
    assert (v > 0).all()
    np.testing.assert_allclose(v.reshape(-1, 8).sum(axis=1), volumes(coarse.points, coarse.cells))
    np.testing.assert_array_equal(fine.cell_tags, np.repeat(coarse.cell_tags, 8))
    assert fine.info["cells"] == len(fine.cells) and fine.info["refinements"] == 1


def test_nodes_are_the_vertices_then_the_edge_midpoints() -> None:
    coarse = box()
    fine = refine_uniform(coarse)
    edges = np.unique(
        np.sort(coarse.cells[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]], axis=2).reshape(
            -1, 2
        ),
        axis=0,
    )
    assert len(fine.points) == len(coarse.points) + len(edges)
    np.testing.assert_array_equal(fine.points[: len(coarse.points)], coarse.points)  # nested
    mids = 0.5 * (coarse.points[edges[:, 0]] + coarse.points[edges[:, 1]])
    assert np.isin(np.round(fine.points[len(coarse.points) :], 12).view("f8,f8,f8"),
                   np.round(mids, 12).view("f8,f8,f8")).all()  # fmt: skip
    # Every node is used, and the facets are exactly the refined mesh's boundary.
    assert np.unique(fine.cells).size == len(fine.points)
    got = np.sort(fine.facets, axis=1)
    want = boundary_facets(fine.cells)
    np.testing.assert_array_equal(got[np.lexsort(got.T[::-1])], want[np.lexsort(want.T[::-1])])


def test_facets_keep_area_orientation_and_tags() -> None:
    coarse = box()
    fine = refine_uniform(coarse)
    n0 = normals(coarse.points, coarse.facets)
    n1 = normals(fine.points, fine.facets).reshape(-1, 4, 3)
    np.testing.assert_allclose(n1.sum(axis=1), n0, atol=1e-14)  # same area and orientation
    assert (np.einsum("ikj,ij->ik", n1, n0) > 0).all()  # each child faces the parent's way
    np.testing.assert_array_equal(fine.facet_tags, np.repeat(coarse.facet_tags, 4))


def test_shapes_do_not_degrade_over_refinements() -> None:
    # The shortest-diagonal cut keeps the worst radius ratio from shrinking from level to level.
    def worst_quality(m: MeshData) -> float:
        p = m.points[m.cells]
        edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
        longest = np.max([np.linalg.norm(p[:, a] - p[:, b], axis=1) for a, b in edges], axis=0)
        return float((volumes(m.points, m.cells) / longest**3).min())

    meshes = [box(1)]
    for _ in range(3):
        meshes.append(refine_uniform(meshes[-1]))
    q = [worst_quality(m) for m in meshes]
    assert min(q[1:]) >= 0.5 * q[0]
    assert q[3] == pytest.approx(q[2], rel=1e-9)  # the worst shape repeats from then on


def test_refined_wound_mesh_keeps_its_zone() -> None:
    spec = GeometrySpec.wedge(1.0, 1.0, 4.0, 1.2, 0.6, 0.3)
    coarse = build_mesh(spec)
    fine = refine_uniform(coarse)
    zone0 = np.linalg.norm(
        normals(coarse.points, coarse.facets[coarse.facet_tags == WOUND_ZONE]), axis=1
    ).sum()
    zone1 = np.linalg.norm(
        normals(fine.points, fine.facets[fine.facet_tags == WOUND_ZONE]), axis=1
    ).sum()
    assert zone1 == pytest.approx(zone0, rel=1e-12)
    assert volumes(fine.points, fine.cells).sum() == pytest.approx(
        volumes(coarse.points, coarse.cells).sum(), rel=1e-12
    )


def test_the_element_size_at_the_wound_halves_under_refinement() -> None:
    from woundsweep.mesh.build import edge_length_near_mm

    spec = GeometrySpec.wedge(1.0, 1.0, 4.0, 1.2, 0.6, 0.3)
    coarse = build_mesh(spec)
    fine = refine_uniform(coarse)
    h0, h1 = edge_length_near_mm(coarse, spec), edge_length_near_mm(fine, spec)
    # Corner children halve their parents' edges (the octahedron's cut adds a diagonal a
    # little longer), and the cells within 1 mm of the wound are the finer ones there.
    assert 1.8 < h0 / h1 < 2.25
    # The cells near the wound are finer than the mesh's median (the size law grades away).
    X, c = coarse.points, coarse.cells[:, :4]
    every = np.median(np.linalg.norm(X[c[:, 0]] - X[c[:, 1]], axis=1))
    assert h0 < every

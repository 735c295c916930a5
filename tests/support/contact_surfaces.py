"""Triangulated test surfaces for the contact tests (numpy only): facing squares, half-cylinders,
a penalty contact between two surfaces and a penetrating displacement of one of them."""

from __future__ import annotations

import numpy as np

from woundsweep.contact import GPA_TO_KPA, FlankContact

__all__ = [
    "cylinder_surface", "make_contact", "normals", "penetrating_state", "square_grid",
    "two_squares",
]  # fmt: skip


def normals(X: np.ndarray, tri: np.ndarray) -> np.ndarray:
    p = X[tri]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def square_grid(n: int, x0: float, sign: float, first: int):
    """Triangulated unit square {x = x0} x [0, 1]^2 (2 n^2 equal right triangles) with nodes
    numbered from ``first`` and every facet normal pointing to ``sign`` * e_x."""
    s = np.linspace(0.0, 1.0, n + 1)
    Y, Z = np.meshgrid(s, s, indexing="ij")
    pts = np.c_[np.full(Y.size, x0), Y.ravel(), Z.ravel()]
    idx = lambda i, j: first + i * (n + 1) + j  # noqa: E731
    i, j = (a.ravel() for a in np.meshgrid(range(n), range(n), indexing="ij"))
    tri = np.concatenate([np.c_[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                          np.c_[idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]])  # fmt: skip
    local = np.vstack([np.zeros((first, 3)), pts])
    flip = normals(local, tri)[:, 0] * sign < 0
    tri[flip, 1], tri[flip, 2] = tri[flip, 2].copy(), tri[flip, 1].copy()
    return pts, tri


def two_squares(n_left: int, n_right: int):
    """Two facing unit squares on x = 0 with disjoint nodes: the left body's surface (normal
    +x, into the gap) and the right body's (normal -x). Returns (X, left, right, right_nodes)."""
    pl, tl = square_grid(n_left, 0.0, +1.0, 0)
    pr, tr = square_grid(n_right, 0.0, -1.0, len(pl))
    X = np.vstack([pl, pr])
    return X, tl, tr, np.arange(len(pl), len(X))


def cylinder_surface(n_theta: int, n_y: int, radius: float, outward: float, first: int = 0):
    """Triangulated half-cylinder x^2 + z^2 = radius^2, z <= 0, y in [0, 2]; facet normals
    point to ``outward`` times the radial direction. Returns (points, facets)."""
    th = np.linspace(np.pi, 2 * np.pi, n_theta + 1)
    ys = np.linspace(0.0, 2.0, n_y + 1)
    T, Y = np.meshgrid(th, ys, indexing="ij")
    pts = np.c_[radius * np.cos(T.ravel()), Y.ravel(), radius * np.sin(T.ravel())]
    idx = lambda i, j: first + i * (n_y + 1) + j  # noqa: E731
    i, j = (a.ravel() for a in np.meshgrid(range(n_theta), range(n_y), indexing="ij"))
    tri = np.concatenate([np.c_[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                          np.c_[idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]])  # fmt: skip
    local = np.vstack([np.zeros((first, 3)), pts])
    c = local[tri].mean(axis=1)
    radial = c * np.array([1.0, 0.0, 1.0])
    flip = np.einsum("ij,ij->i", normals(local, tri), radial) * outward < 0
    tri[flip, 1], tri[flip, 2] = tri[flip, 2].copy(), tri[flip, 1].copy()
    return pts, tri


def make_contact(X, left, right) -> FlankContact:
    c = FlankContact(X, left, right)
    c.k_V_kPa = 1.0 * GPA_TO_KPA
    return c


def penetrating_state(rng, X, right_nodes, depth: float, noise: float) -> np.ndarray:
    """The right surface pushed by ``depth`` into the left (-x), plus random noise."""
    U = noise * rng.standard_normal(X.shape)
    U[right_nodes, 0] -= depth
    return U.ravel()

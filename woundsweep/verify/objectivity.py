"""Objectivity of the assembled residual and of the solution under a rigid rotation.

- Residual: for any displacement u, the superposed rigid rotation x -> Q x of the deformed
  body (u* = Q (X + u) - X) must give the rotated nodal residual, R(u*) = Q R(u) node by
  node (W(Q F) = W(F) in the assembled forms, both layers, P2).
- Solution: the whole problem turned by a rotation Q about z (the mesh, the boundary values
  and the dermis's Langer line, orientation t -> t + beta; the Fung model's third axis is
  e_z, so turns about z are the ones it admits) must give the turned solution,
  u'(Q X) = Q u(X) at every node (a two-layer block, P2, u prescribed on its boundary).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..core.schema import DERMIS, SUBCUTIS, MeshData
from ..physics.materials import Fung, JobMaterials, MooneyRivlin
from .bvp import BoundaryValueProblem
from .meshes import slab

__all__ = ["residual_objectivity", "rotation", "solution_objectivity"]


def rotation(axis: Any, angle_deg: float) -> np.ndarray:
    """The rotation by ``angle_deg`` about ``axis`` (Rodrigues)."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    t = math.radians(angle_deg)
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def _block(n: int = 2) -> MeshData:
    """A two-layer block [0, 1] x [0, 1] x [-1, 0], dermis above z = -0.5."""
    s = np.linspace(0.0, 1.0, n + 1)
    z = np.linspace(-1.0, 0.0, 2 * n + 1)
    return slab(s, s, z, lambda mid: np.where(mid[:, 2] > -0.5, DERMIS, SUBCUTIS))


def _field(X: np.ndarray) -> np.ndarray:
    """A smooth nonlinear displacement (strains up to about 0.3)."""
    x, y, z = X.T
    return 0.1 * np.c_[np.sin(2 * x + y) + z * z, np.cos(x - z) * y, np.sin(x * y) + x]


def _materials(angle_deg: float) -> JobMaterials:
    return JobMaterials(Fung.normal(angle_deg), MooneyRivlin.subcutis(), 1.1)


def _match(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """For every point of B, the index of the coincident point of A."""
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(A).query(B)
    if dist.max() > 1e-9:
        raise ValueError("the rotated nodes do not coincide")
    return np.asarray(idx)


def residual_objectivity(degree: int = 2) -> float:
    """max |R(u*) - Q R(u)| / max |R(u)| for a rotation Q about an oblique axis."""
    prob = BoundaryValueProblem(_block(), degree, _materials(30.0))
    Q = rotation((1.0, 2.0, 3.0), 40.0)
    X = prob.X
    u = _field(X)
    prob.u[:] = u.ravel()
    R = prob.residual().reshape(-1, 3)
    prob.u[:] = ((X + u) @ Q.T - X).ravel()
    R_star = prob.residual().reshape(-1, 3)
    return float(np.abs(R_star - R @ Q.T).max() / np.abs(R).max())


def solution_objectivity(degree: int = 2, beta_deg: float = 25.0) -> float:
    """max |u'(Q X) - Q u(X)| / max |u| for the problem turned by ``beta_deg`` about z."""
    mesh = _block()
    Q = rotation((0.0, 0.0, 1.0), beta_deg)
    first = BoundaryValueProblem(mesh, degree, _materials(20.0))
    first.solve(_field(first.X), first_step=0.25)
    turned = mesh._replace(points=mesh.points @ Q.T)
    second = BoundaryValueProblem(turned, degree, _materials(20.0 + beta_deg))
    # u'(X') = Q u(Q^T X') on the boundary
    second.solve(_field(second.X @ Q) @ Q.T, first_step=0.25)
    u1 = first.u.reshape(-1, 3)
    u2 = second.u.reshape(-1, 3)
    idx = _match(first.X @ Q.T, second.X)
    return float(np.abs(u2 - u1[idx] @ Q.T).max() / np.abs(u1).max())

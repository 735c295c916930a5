"""Cellwise mechanics of a stored state, in numpy: the deformation gradient F = I + grad u of
the stored (vertex) displacement on each tetrahedron, det F, the Green-Lagrange strain, the
Cauchy stress of the job's materials and its von Mises and principal values.

The stresses are the derivative of the strain energy of `woundsweep.physics.materials` (the
same formulas, batched over cells; the complex-step derivative is exact to rounding). On a P1
run F is the solver's own, so the von Mises here equals the stored one; on a P2 run the
vertex displacement is the quadratic field's linear interpolant and these are its values.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..config.paper import FungParameters, Materials, MooneyRivlinParameters
from ..core.schema import DERMIS, SUBCUTIS

__all__ = ["CellMechanics", "cell_mechanics", "deformation_gradients", "first_piola"]

_H = 1e-30  # complex step


class CellMechanics(NamedTuple):
    """Per cell (m of them): tensors (m, 3, 3), scalars (m,); stresses in kPa."""

    F: np.ndarray
    det_F: np.ndarray
    green_lagrange: np.ndarray
    cauchy_kPa: np.ndarray
    von_mises_kPa: np.ndarray
    principal_kPa: np.ndarray  # (m, 3), largest first


def deformation_gradients(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> np.ndarray:
    """F = I + grad u per tetrahedron (u linear on the cell): Ds Dm^-1."""
    X = np.asarray(points, float)[cells]
    x = X + np.asarray(u, float)[cells]
    Dm = (X[:, 1:] - X[:, :1]).transpose(0, 2, 1)
    Ds = (x[:, 1:] - x[:, :1]).transpose(0, 2, 1)
    return Ds @ np.linalg.inv(Dm)


def _tr(A: np.ndarray) -> np.ndarray:
    return np.trace(A, axis1=-2, axis2=-1)


def _iso(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    J = np.linalg.det(F)
    return J, J[:, None, None] ** (-2.0 / 3.0) * (F.transpose(0, 2, 1) @ F)


def _mooney_rivlin(p: MooneyRivlinParameters, F: np.ndarray) -> np.ndarray:
    J, C = _iso(F)
    d = _tr(C) - 3.0
    return p.C10_kPa * d + p.C20_kPa * d * d + 0.5 * p.K_kPa * np.log(J) ** 2


def _fung(p: FungParameters, orientation_deg: float, F: np.ndarray) -> np.ndarray:
    J, C = _iso(F)
    E = 0.5 * (C - np.eye(3))
    E2 = E @ E
    t = math.radians(orientation_deg)
    a1, a3 = np.array([math.cos(t), math.sin(t), 0.0]), np.array([0.0, 0.0, 1.0])
    axes = (a1, np.cross(a1, a3), a3)
    e = [np.einsum("i,mij,j->m", a, E, a) for a in axes]
    e2 = [np.einsum("i,mij,j->m", a, E2, a) for a in axes]
    s = e[0] + e[1] + e[2]
    mu = p.mu_kPa
    Q = (
        2.0 * (mu[0] * e2[0] + mu[1] * e2[1] + mu[2] * e2[2])
        + p.lambda_other_kPa * s * s
        + (p.lambda11_kPa - p.lambda_other_kPa) * e[0] * e[0]
    ) / p.c_kPa
    return 0.5 * p.c_kPa * (np.exp(Q) - 1.0) + 0.5 * p.K_kPa * np.log(J) ** 2


def first_piola(energy: Callable[[np.ndarray], np.ndarray], F: np.ndarray) -> np.ndarray:
    """P = dW/dF (kPa) of a batched energy ``energy(F) -> (m,)`` by the complex step."""
    P = np.empty(F.shape)
    for i in range(3):
        for j in range(3):
            Fc = F.astype(complex)
            Fc[:, i, j] += 1j * _H
            P[:, i, j] = np.imag(energy(Fc)) / _H
    return P


def cell_mechanics(
    points: np.ndarray,
    cells: np.ndarray,
    cell_tags: np.ndarray,
    u: np.ndarray,
    materials: Materials,
    skin_type: str,
    orientation_deg: float,
) -> CellMechanics:
    """The cellwise mechanics of displacement ``u`` (mm) for one job's materials."""
    F = deformation_gradients(points, cells, u)
    J = np.linalg.det(F)
    P = np.zeros_like(F)
    dermis, sub = np.asarray(cell_tags) == DERMIS, np.asarray(cell_tags) == SUBCUTIS
    skin = materials.skin_types[skin_type]
    # A cell whose vertex interpolant of a P2 field is inverted or extreme has no stress (NaN):
    # the Fung exponential overflows there instead of raising.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        if dermis.any():
            P[dermis] = first_piola(lambda G: _fung(skin, orientation_deg, G), F[dermis])
        if sub.any():
            P[sub] = first_piola(lambda G: _mooney_rivlin(materials.subcutis, G), F[sub])
        sigma = P @ F.transpose(0, 2, 1) / J[:, None, None]
    sigma = 0.5 * (sigma + sigma.transpose(0, 2, 1))
    bad = ~np.isfinite(sigma).all(axis=(1, 2)) | (J <= 0)
    sigma[bad] = np.nan
    dev = sigma - _tr(sigma)[:, None, None] / 3.0 * np.eye(3)
    vm = np.sqrt(1.5 * np.einsum("mij,mij->m", dev, dev))
    principal = np.full((len(sigma), 3), np.nan)
    principal[~bad] = np.linalg.eigvalsh(sigma[~bad])[:, ::-1]
    E = 0.5 * (F.transpose(0, 2, 1) @ F - np.eye(3))
    return CellMechanics(F, J, E, sigma, vm, np.ascontiguousarray(principal))

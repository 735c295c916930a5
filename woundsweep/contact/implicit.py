"""A smooth implicit surface through a triangulated one, and its exact derivatives.

The gap of a point x to a master surface of facets f (deformed vertices x1, x2, x3) is

    phi(x) = N / D,   N = sum_f W(s_f) (x - c_f) . a_f,   D = sum_f W(s_f) |a_f|,

with c_f the centroid, a_f = (x2 - x1) x (x3 - x1) / 2 the area vector (outward), s_f =
|x - c_f|^2 / rho_f^2 and the kernel W(s) = (1 - s)^3 for s < 1 (0 beyond): an area-weighted
moving average of the signed distances to the facets' planes (implicit moving least squares).
W is C2 at s = 1, so phi is C2 in the point and in every vertex, across facet edges
included; it is exact on a plane (every facet gives the same distance) and within O(rho^2
kappa) of a surface of curvature kappa.

Derivatives are taken per (point, facet) pair in v = (r, e1, e2), r = x - c_f, e1 = x2 - x1,
e2 = x3 - x1, and mapped to q = (x, x1, x2, x3) by the constant ``V_TO_Q``. Vectorised over
pairs; `pair_terms` gives each pair's N, D and their first and second derivatives in q, which
`woundsweep.contact.smooth` sums per point.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "SUPPORT_T0",
    "SUPPORT_T1",
    "V_TO_Q",
    "PairTerms",
    "kernel",
    "pair_terms",
    "support_step",
]

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0

# v = V_TO_Q @ q with q = (x, x1, x2, x3): r = x - (x1 + x2 + x3) / 3, e1 = x2 - x1, e2 = x3 - x1.
_I = np.eye(3)
V_TO_Q = np.block(
    [
        [_I, -_I / 3, -_I / 3, -_I / 3],
        [0 * _I, -_I, _I, 0 * _I],
        [0 * _I, -_I, 0 * _I, _I],
    ]
)


def kernel(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W(s) = (1 - s)^3 on s < 1 and its first two derivatives (0 for s >= 1)."""
    t = np.clip(1.0 - s, 0.0, None)
    return t**3, -3.0 * t**2, 6.0 * t


class PairTerms(NamedTuple):
    """Per-pair numerator and denominator terms and their derivatives in q (12 coordinates)."""

    N: np.ndarray  # (P,)
    D: np.ndarray  # (P,)
    dN: np.ndarray  # (P, 12)
    dD: np.ndarray  # (P, 12)
    d2N: np.ndarray | None  # (P, 12, 12)
    d2D: np.ndarray | None  # (P, 12, 12)


def pair_terms(
    x: np.ndarray,
    x1: np.ndarray,
    x2: np.ndarray,
    x3: np.ndarray,
    rho: np.ndarray,
    hessian: bool = True,
) -> PairTerms:
    """N_f = W (r . a), D_f = W |a| of each pair and their derivatives in q = (x, x1, x2, x3).

    Inputs (P, 3) points and facet vertices, ``rho`` (P,) kernel radii.
    """
    r = x - (x1 + x2 + x3) / 3.0
    e1, e2 = x2 - x1, x3 - x1
    a = 0.5 * np.cross(e1, e2)
    m = np.linalg.norm(a, axis=1)
    n_hat = a / m[:, None]
    inv_r2 = 1.0 / rho**2
    s = np.einsum("pi,pi->p", r, r) * inv_r2
    W, W1, W2 = kernel(s)
    tri = np.einsum("pi,pi->p", r, a)  # (r . a)
    P = len(x)
    # First derivatives in v = (r, e1, e2).
    ds = np.zeros((P, 9))
    ds[:, 0:3] = 2.0 * r * inv_r2[:, None]
    dtri = np.concatenate([a, 0.5 * np.cross(e2, r), 0.5 * np.cross(r, e1)], axis=1)
    # a_i = 1/2 eps_ijk e1_j e2_k: Jacobians of a in e1 and e2.
    Ja1 = 0.5 * np.einsum("ijk,pk->pij", _EPS, e2)
    Ja2 = 0.5 * np.einsum("ijk,pj->pik", _EPS, e1)
    dm = np.zeros((P, 9))
    dm[:, 3:6] = np.einsum("pi,pij->pj", n_hat, Ja1)
    dm[:, 6:9] = np.einsum("pi,pik->pk", n_hat, Ja2)
    dN_v = W1[:, None] * ds * tri[:, None] + W[:, None] * dtri
    dD_v = W1[:, None] * ds * m[:, None] + W[:, None] * dm
    dN, dD = dN_v @ V_TO_Q, dD_v @ V_TO_Q
    if not hessian:
        return PairTerms(W * tri, W * m, dN, dD, None, None)
    # Second derivatives in v.
    d2s = np.zeros((P, 9, 9))
    d2s[:, 0:3, 0:3] = 2.0 * inv_r2[:, None, None] * _I
    d2tri = np.zeros((P, 9, 9))
    re1 = 0.5 * np.einsum("ijk,pk->pij", _EPS, e2)  # d2/dr_i de1_j
    re2 = 0.5 * np.einsum("ijk,pj->pik", _EPS, e1)  # d2/dr_i de2_k
    e12 = 0.5 * np.einsum("ijk,pi->pjk", _EPS, r)  # d2/de1_j de2_k
    d2tri[:, 0:3, 3:6], d2tri[:, 3:6, 0:3] = re1, np.transpose(re1, (0, 2, 1))
    d2tri[:, 0:3, 6:9], d2tri[:, 6:9, 0:3] = re2, np.transpose(re2, (0, 2, 1))
    d2tri[:, 3:6, 6:9], d2tri[:, 6:9, 3:6] = e12, np.transpose(e12, (0, 2, 1))
    Ja = np.concatenate([Ja1, Ja2], axis=2)  # (P, 3, 6)
    proj = (_I - n_hat[:, :, None] * n_hat[:, None, :]) / m[:, None, None]
    d2m = np.zeros((P, 9, 9))
    d2m[:, 3:9, 3:9] = np.einsum("pia,pij,pjb->pab", Ja, proj, Ja)
    cross = 0.5 * np.einsum("ijk,pi->pjk", _EPS, n_hat)  # sum_i n_i d2a_i/de1_j de2_k
    d2m[:, 3:6, 6:9] += cross
    d2m[:, 6:9, 3:6] += np.transpose(cross, (0, 2, 1))

    def second(f: np.ndarray, df: np.ndarray, d2f: np.ndarray) -> np.ndarray:
        sf = ds[:, :, None] * df[:, None, :]
        out = W2[:, None, None] * ds[:, :, None] * ds[:, None, :] * f[:, None, None]
        out += W1[:, None, None] * (d2s * f[:, None, None] + sf + np.transpose(sf, (0, 2, 1)))
        out += W[:, None, None] * d2f
        return V_TO_Q.T @ out @ V_TO_Q

    return PairTerms(W * tri, W * m, dN, dD, second(tri, dtri, d2tri), second(m, dm, d2m))


# The support step: s(t) = 0 for t <= T0, 1 for t >= T1, C2 (quintic smoothstep) between.
# t = D / D_full, D_full = pi rho^2 / 4 the kernel's integral over a plane: 1/4 at a corner
# of a flat surface, 1/2 on an edge, so only points past the master's boundary fade.
SUPPORT_T0, SUPPORT_T1 = 0.005, 0.05


def support_step(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s(t) and its first two derivatives (see ``SUPPORT_T0``, ``SUPPORT_T1``)."""
    w = SUPPORT_T1 - SUPPORT_T0
    x = np.clip((t - SUPPORT_T0) / w, 0.0, 1.0)
    s = x**3 * (10.0 - 15.0 * x + 6.0 * x**2)
    s1 = 30.0 * x**2 * (1.0 - x) ** 2 / w
    s2 = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / w**2
    return s, s1, s2

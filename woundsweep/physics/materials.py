"""Constitutive models of the two skin layers (paper eqs. 10-11; Table 2 from Flynn et al.).

Each material is a small frozen dataclass with a ``strain_energy(F)`` and, for UFL, the
``isochoric_stress`` of its energy in closed form. The same energy formula serves
two backends, chosen by the type of ``F``:

- a UFL expression: the energy used in the finite-element forms; the fields are then usually
  ``fem.Constant`` objects so that a compiled form serves every parameter set;
- a numpy array (real or complex): the energy of one homogeneous deformation, used to find the
  pre-stretched state of healthy skin (`homogeneous_state`) and for diagnostics.

The first Piola-Kirchhoff stress is the derivative of the energy: F S with S in closed form
for UFL (`second_piola`: a third of the generated kernel of differentiating W twice), the
complex-step derivative of W (exact to rounding) for numpy. Units: moduli in kPa, so energies
are in kPa (energy per unit reference volume) and stresses in kPa.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np
import ufl

from ..config.paper import FungParameters, Materials, MooneyRivlinParameters

__all__ = [
    "Fung",
    "HomogeneousState",
    "JobMaterials",
    "Material",
    "MooneyRivlin",
    "first_piola",
    "homogeneous_state",
    "langer_axis",
    "von_mises",
]

_COMPLEX_STEP = 1e-30


class _Ops(NamedTuple):
    det: Any
    tr: Any
    exp: Any
    ln: Any
    dot: Any
    cross: Any
    vector: Any
    identity: Any


_UFL = _Ops(ufl.det, ufl.tr, ufl.exp, ufl.ln, ufl.dot, ufl.cross, ufl.as_vector, ufl.Identity)
_NUMPY = _Ops(
    np.linalg.det, np.trace, np.exp, np.log, np.dot, np.cross, np.asarray, lambda n: np.eye(n)
)


def _ops(F: Any) -> _Ops:
    return _NUMPY if isinstance(F, np.ndarray) else _UFL


def langer_axis(orientation_deg: float) -> np.ndarray:
    """Unit in-plane vector a1 = (cos t, sin t, 0) of the stiff material axis (Langer line)."""
    t = math.radians(orientation_deg)
    return np.array([math.cos(t), math.sin(t), 0.0])


class Material(ABC):
    """A hyperelastic material: the stress is the derivative of `strain_energy`."""

    if TYPE_CHECKING:  # every material is a dataclass with a bulk modulus field K
        __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]
        K: Any

    @abstractmethod
    def strain_energy(self, F: Any) -> Any:
        """Strain energy per unit reference volume (kPa) at deformation gradient ``F``."""

    @abstractmethod
    def isochoric_stress(self, C_bar: Any) -> Any:
        """S~ = 2 dW_iso/dC~ (kPa, UFL) at the isochoric C~ = J^(-2/3) C, where
        ``strain_energy`` = W_iso(C~) + K/2 (ln J)^2."""


def second_piola(material: Any, F: Any) -> Any:
    """Second Piola-Kirchhoff stress S = 2 dW/dC (kPa, UFL) in closed form:
    S = J^(-2/3) (S~ - (S~ : C) C^-1 / 3) + K ln J C^-1 with S~ = ``isochoric_stress``.

    The same stress as differentiating ``strain_energy`` (to rounding), in a form whose
    generated tangent kernel is a third of the size and assembles 1.6-1.8 times faster
    (docs/model.md, "Materials")."""
    C = F.T * F
    J = ufl.det(F)
    C_inv = ufl.inv(C)
    S_bar = material.isochoric_stress(J ** (-2.0 / 3.0) * C)
    iso = J ** (-2.0 / 3.0) * (S_bar - ufl.inner(S_bar, C) / 3.0 * C_inv)
    return iso + material.K * ufl.ln(J) * C_inv


def first_piola(material: Material, F: Any) -> Any:
    """First Piola-Kirchhoff stress P = dW/dF (kPa): F S in closed form (`second_piola`) for
    UFL, the complex-step derivative of the energy for numpy."""
    if isinstance(F, np.ndarray):
        F = np.asarray(F, dtype=float)
        P = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                Fc = F.astype(complex)
                Fc[i, j] += 1j * _COMPLEX_STEP
                P[i, j] = np.imag(material.strain_energy(Fc)) / _COMPLEX_STEP
        return P
    return F * second_piola(material, F)


def von_mises(P: Any, F: Any) -> Any:
    """Von Mises stress of the Cauchy stress sigma = J^-1 P F^T (paper eq. 20), kPa."""
    o = _ops(F)
    sigma = o.dot(P, F.T) / o.det(F)
    s = sigma - o.tr(sigma) / 3.0 * o.identity(3)
    if o is _NUMPY:
        return float(np.sqrt(1.5 * np.sum(s * s)))
    return ufl.sqrt(1.5 * ufl.inner(s, s))


def _distortional_c(F: Any, o: _Ops) -> tuple[Any, Any]:
    """(J, C~ = J^(-2/3) F^T F): the isochoric right Cauchy-Green tensor."""
    J = o.det(F)
    return J, J ** (-2.0 / 3.0) * o.dot(F.T, F)


@dataclasses.dataclass(frozen=True)
class MooneyRivlin(Material):
    """Mooney-Rivlin subcutis, eq. 10: C10 (I1~ - 3) + C20 (I1~ - 3)^2 + K/2 (ln J)^2 (kPa)."""

    C10: Any
    C20: Any
    K: Any

    @classmethod
    def subcutis(cls) -> MooneyRivlin:
        """The paper's subcutis (Table 2, from Flynn et al.): C10 = 0.4, C20 = 1.4, K = 50 kPa."""
        return cls.from_parameters(MooneyRivlinParameters.table2())

    @classmethod
    def from_parameters(cls, p: MooneyRivlinParameters) -> MooneyRivlin:
        """From a sweep's ``materials.subcutis``."""
        return cls(float(p.C10_kPa), float(p.C20_kPa), float(p.K_kPa))

    def strain_energy(self, F: Any) -> Any:
        o = _ops(F)
        J, C = _distortional_c(F, o)
        d = o.tr(C) - 3.0
        return self.C10 * d + self.C20 * d * d + 0.5 * self.K * o.ln(J) ** 2

    def isochoric_stress(self, C_bar: Any) -> Any:
        """S~ = 2 (C10 + 2 C20 (I1~ - 3)) I."""
        d = ufl.tr(C_bar) - 3.0
        return 2.0 * (self.C10 + 2.0 * self.C20 * d) * ufl.Identity(3)


@dataclasses.dataclass(frozen=True)
class Fung(Material):
    """Orthotropic Fung dermis, eq. 11 (kPa).

    W = c/2 (exp(Q) - 1) + K/2 (ln J)^2 with
    Q = (1/c) sum_a [2 mu_a A_a : E~^2 + sum_b lambda_ab (A_a : E~)(A_b : E~)],
    E~ = (C~ - I)/2, A_a = a_a (x) a_a; a1 the Langer line, a3 = e_z, a2 = a1 x a3.
    ``lambda_ab`` is lambda11 for a = b = 1 and lambda_other for every other pair.
    ``mu`` and ``a1`` are length-3 sequences (or UFL vectors).
    """

    c: Any
    mu: Any
    lambda11: Any
    lambda_other: Any
    K: Any
    a1: Any

    @classmethod
    def table2(cls, skin_type: str, orientation_deg: float = 0.0) -> Fung:
        """Table 2 (Flynn et al.) dermis of skin type ``normal``, ``stiff`` or ``soft``."""
        return cls.from_parameters(Materials.table2().skin_types[skin_type], orientation_deg)

    @classmethod
    def normal(cls, orientation_deg: float = 0.0) -> Fung:
        """Normal skin (Table 2): c = 21.3, mu = (17.8, 5.9, 5.9), lambda = 1.0, K = 250 kPa."""
        return cls.table2("normal", orientation_deg)

    @classmethod
    def stiff(cls, orientation_deg: float = 0.0) -> Fung:
        """Stiff skin (Table 2): c = 42.6, mu = (35.6, 11.8, 11.8), lambda11 = 11.8, others 2.0."""
        return cls.table2("stiff", orientation_deg)

    @classmethod
    def soft(cls, orientation_deg: float = 0.0) -> Fung:
        """Soft skin (Table 2): c = 10.7, mu = (8.9, 3.0, 3.0), lambda = 0.5, K = 250 kPa."""
        return cls.table2("soft", orientation_deg)

    @classmethod
    def from_parameters(cls, p: FungParameters, orientation_deg: float) -> Fung:
        """From one ``materials.skin_types`` entry of a sweep, at an orientation."""
        return cls(
            float(p.c_kPa),
            tuple(float(m) for m in p.mu_kPa),
            float(p.lambda11_kPa),
            float(p.lambda_other_kPa),
            float(p.K_kPa),
            langer_axis(orientation_deg),
        )

    def strain_energy(self, F: Any) -> Any:
        o = _ops(F)
        J, C = _distortional_c(F, o)
        E = 0.5 * (C - o.identity(3))
        E2 = o.dot(E, E)
        a1 = self.a1 if o is _UFL else np.asarray(self.a1, dtype=float)
        a3 = o.vector((0.0, 0.0, 1.0))
        axes = (a1, o.cross(a1, a3), a3)
        e = [o.dot(a, o.dot(E, a)) for a in axes]  # A_a : E~
        e2 = [o.dot(a, o.dot(E2, a)) for a in axes]  # A_a : E~^2
        s = e[0] + e[1] + e[2]
        Q = (
            2.0 * (self.mu[0] * e2[0] + self.mu[1] * e2[1] + self.mu[2] * e2[2])
            + self.lambda_other * s * s
            + (self.lambda11 - self.lambda_other) * e[0] * e[0]
        ) / self.c
        return 0.5 * self.c * (o.exp(Q) - 1.0) + 0.5 * self.K * o.ln(J) ** 2

    def isochoric_stress(self, C_bar: Any) -> Any:
        """S~ = dW_iso/dE~ = exp(Q) (2 sum_a mu_a (A_a E~ + E~ A_a)
        + 2 sum_ab lambda_ab (A_b : E~) A_a) / 2, E~ = (C~ - I) / 2."""
        eye = ufl.Identity(3)
        E = 0.5 * (C_bar - eye)
        a1, a3 = self.a1, ufl.as_vector((0.0, 0.0, 1.0))
        A = [ufl.outer(a, a) for a in (a1, ufl.cross(a1, a3), a3)]
        e = [ufl.inner(Aa, E) for Aa in A]  # A_a : E~
        e2 = [ufl.inner(Aa, E * E) for Aa in A]  # A_a : E~^2
        s = e[0] + e[1] + e[2]
        lam_d = self.lambda11 - self.lambda_other
        Q = (
            2.0 * (self.mu[0] * e2[0] + self.mu[1] * e2[1] + self.mu[2] * e2[2])
            + self.lambda_other * s * s
            + lam_d * e[0] * e[0]
        ) / self.c
        dQ_c = (  # c dQ/dE~
            2.0 * (self.mu[0] * (A[0] * E + E * A[0]))
            + 2.0 * (self.mu[1] * (A[1] * E + E * A[1]))
            + 2.0 * (self.mu[2] * (A[2] * E + E * A[2]))
            + 2.0 * self.lambda_other * s * eye
            + 2.0 * lam_d * e[0] * A[0]
        )
        return 0.5 * ufl.exp(Q) * dQ_c


class HomogeneousState(NamedTuple):
    """Homogeneous in-plane stretch with a traction-free top: F = diag(s, s, lambda3)."""

    stretch: float
    lambda3: float
    F: np.ndarray
    P: np.ndarray  # first Piola-Kirchhoff stress, kPa


def homogeneous_state(material: Material, stretch: float, max_iter: int = 200) -> HomogeneousState:
    """Solve P_zz(diag(stretch, stretch, lambda3)) = 0 for lambda3 (Illinois regula falsi).

    With a1 and a2 in the plane and a3 = e_z, P_xz = P_yz = 0 for a diagonal F, so this state
    leaves a z-normal face traction-free; P_xy is non-zero when the Langer line is oblique.
    Converged when |P_zz| <= 1e-12 K or the bracket is below 1e-15.
    """

    def pzz(lam: float) -> float:
        return float(first_piola(material, np.diag([stretch, stretch, lam]))[2, 2])

    ftol = 1e-12 * float(material.K)
    lo, hi = 0.5, 1.0
    flo, fhi = pzz(lo), pzz(hi)
    while flo > 0 and lo > 1e-3:
        lo *= 0.5
        flo = pzz(lo)
    while fhi < 0 and hi < 1e3:
        hi *= 2.0
        fhi = pzz(hi)
    if not (math.isfinite(flo) and math.isfinite(fhi) and flo <= 0 <= fhi):
        raise ValueError(f"no through-thickness stretch balances P_zz at stretch {stretch}")
    lam, side = hi, 0
    for _ in range(max_iter):
        lam = (lo * fhi - hi * flo) / (fhi - flo)
        f = pzz(lam)
        if abs(f) <= ftol or hi - lo <= 1e-15:
            break
        if f < 0:  # Illinois: halve the stale end's value when the same side repeats
            lo, flo = lam, f
            fhi = fhi * 0.5 if side == -1 else fhi
            side = -1
        else:
            hi, fhi = lam, f
            flo = flo * 0.5 if side == 1 else flo
            side = 1
    F = np.diag([stretch, stretch, lam])
    return HomogeneousState(float(stretch), float(lam), F, first_piola(material, F))


@dataclasses.dataclass(frozen=True)
class JobMaterials:
    """The materials of one job: dermis (Fung at the job's orientation), subcutis, TSF."""

    dermis: Fung
    subcutis: MooneyRivlin
    tsf: float

    @classmethod
    def table2(cls, skin_type: str, orientation_deg: float) -> JobMaterials:
        """The paper's Table 2 values for ``skin_type`` (normal / stiff / soft)."""
        return cls.from_sweep(Materials.table2(), skin_type, orientation_deg)

    @classmethod
    def from_sweep(
        cls, materials: Materials, skin_type: str, orientation_deg: float
    ) -> JobMaterials:
        """From a sweep's ``materials`` section."""
        skin = materials.skin_types[skin_type]
        return cls(
            Fung.from_parameters(skin, orientation_deg),
            MooneyRivlin.from_parameters(materials.subcutis),
            float(skin.tsf),
        )

"""Materials: stresses against an independent numpy transcription of the paper's energies.

The reference energies below are written from eqs. 10-11 of the paper, not from
woundsweep.physics.materials, and differentiated by central finite differences.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from woundsweep.config.paper import FungParameters, Materials
from woundsweep.physics.materials import (
    Fung,
    MooneyRivlin,
    first_piola,
    homogeneous_state,
    von_mises,
)

# Table 2 entries in the short names of the reference energies below.
FLYNN_SKIN_TYPES = {
    name: {"c": e["c_kPa"], "mu": tuple(e["mu_kPa"]), "lambda11": e["lambda11_kPa"],
           "lambda_other": e["lambda_other_kPa"], "K": e["K_kPa"], "tsf": e["tsf"]}
    for name, e in Materials.table2().to_dict()["skin_types"].items()
}  # fmt: skip

SKIN_TYPES = ("normal", "stiff", "soft")
ANGLES = (0.0, 45.0, 90.0)


def ref_fung_energy(F: np.ndarray, p: dict, theta_deg: float) -> float:
    """Eq. 11 with the Table 2 parameters, written independently."""
    J = np.linalg.det(F)
    Fb = J ** (-1.0 / 3.0) * F
    E = 0.5 * (Fb.T @ Fb - np.eye(3))
    t = math.radians(theta_deg)
    a1 = np.array([math.cos(t), math.sin(t), 0.0])
    a3 = np.array([0.0, 0.0, 1.0])
    axes = [a1, np.cross(a1, a3), a3]
    A = [np.outer(a, a) for a in axes]
    lam = np.full((3, 3), p["lambda_other"])
    lam[0, 0] = p["lambda11"]
    Q = 0.0
    for a in range(3):
        Q += 2.0 * p["mu"][a] * np.sum(A[a] * (E @ E))
        for b in range(3):
            Q += lam[a, b] * np.sum(A[a] * E) * np.sum(A[b] * E)
    Q /= p["c"]
    return 0.5 * p["c"] * (math.exp(Q) - 1.0) + 0.5 * p["K"] * math.log(J) ** 2


def ref_mr_energy(F: np.ndarray, C10: float = 0.4, C20: float = 1.4, K: float = 50.0) -> float:
    """Eq. 10 with the Table 2 subcutis, written independently."""
    J = np.linalg.det(F)
    Fb = J ** (-1.0 / 3.0) * F
    I1 = np.trace(Fb @ Fb.T)
    return C10 * (I1 - 3) + C20 * (I1 - 3) ** 2 + 0.5 * K * math.log(J) ** 2


def fd_stress(energy, F: np.ndarray, h: float = 1e-6) -> np.ndarray:
    P = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            Fp, Fm = F.copy(), F.copy()
            Fp[i, j] += h
            Fm[i, j] -= h
            P[i, j] = (energy(Fp) - energy(Fm)) / (2 * h)
    return P


def deformations() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    Fs = [
        np.diag([1.10, 1.10, 0.83]),  # a pre-stretched state
        np.array([[1.05, 0.12, 0.0], [0.0, 0.97, 0.05], [0.02, 0.0, 1.01]]),  # with shear
    ]
    Fs += [np.eye(3) + 0.15 * rng.standard_normal((3, 3)) for _ in range(2)]
    return Fs


def test_table2_values() -> None:
    """The named constructors carry Table 2 (Flynn et al.) as printed in the paper."""
    assert Fung.normal().c == 21.3 and Fung.stiff().c == 42.6 and Fung.soft().c == 10.7
    assert Fung.stiff().mu == (35.6, 11.8, 11.8)
    assert (Fung.stiff().lambda11, Fung.stiff().lambda_other) == (11.8, 2.0)
    assert [FLYNN_SKIN_TYPES[s]["tsf"] for s in SKIN_TYPES] == [1.10, 1.05, 1.15]
    mr = MooneyRivlin.subcutis()
    assert (mr.C10, mr.C20, mr.K) == (0.4, 1.4, 50.0)


def test_from_parameters_matches_named_constructor() -> None:
    entry = FungParameters(42.6, (35.6, 11.8, 11.8), 11.8, 2.0, 250.0, 1.05)
    a, b = Fung.from_parameters(entry, 30.0), Fung.table2("stiff", 30.0)
    assert a.c == b.c and a.mu == b.mu and a.K == b.K
    np.testing.assert_allclose(a.a1, [math.cos(math.pi / 6), 0.5, 0.0])


@pytest.mark.parametrize("skin", SKIN_TYPES)
@pytest.mark.parametrize("angle", ANGLES)
def test_numpy_fung_stress_matches_reference(skin: str, angle: float) -> None:
    """The numpy backend (used for the lateral tractions) against the reference energy."""
    p = FLYNN_SKIN_TYPES[skin]
    mat = Fung.table2(skin, angle)
    for F in deformations():
        ref = fd_stress(lambda G: ref_fung_energy(G, p, angle), F)
        np.testing.assert_allclose(first_piola(mat, F), ref, rtol=1e-6, atol=1e-6)
        assert mat.strain_energy(F) == pytest.approx(ref_fung_energy(F, p, angle), rel=1e-12)


def test_numpy_mooney_rivlin_stress_matches_reference() -> None:
    mat = MooneyRivlin.subcutis()
    for F in deformations():
        ref = fd_stress(ref_mr_energy, F)
        np.testing.assert_allclose(first_piola(mat, F), ref, rtol=1e-6, atol=1e-7)


def test_stress_free_reference_state() -> None:
    for mat in (Fung.soft(45.0), MooneyRivlin.subcutis()):
        np.testing.assert_allclose(first_piola(mat, np.eye(3)), 0.0, atol=1e-12)


@pytest.mark.parametrize("skin", SKIN_TYPES)
def test_homogeneous_state_has_traction_free_top(skin: str) -> None:
    p = FLYNN_SKIN_TYPES[skin]
    for angle in ANGLES:
        st = homogeneous_state(Fung.table2(skin, angle), p["tsf"])
        ref = fd_stress(lambda G, a=angle: ref_fung_energy(G, p, a), st.F)
        assert abs(ref[2, 2]) < 1e-6 * p["K"]
        np.testing.assert_allclose(ref[:, 2], 0.0, atol=1e-6)
        # In-plane tension; shear only when the Langer line is oblique.
        assert st.P[0, 0] > 0 and st.P[1, 1] > 0
        assert (abs(st.P[0, 1]) > 0.1) == (angle == 45.0)
    mr = homogeneous_state(MooneyRivlin.subcutis(), 1.10)
    assert abs(fd_stress(ref_mr_energy, mr.F)[2, 2]) < 1e-6
    assert mr.P[0, 0] == pytest.approx(mr.P[1, 1])


def test_von_mises_of_uniaxial_and_hydrostatic_stress() -> None:
    F = np.eye(3)
    assert von_mises(np.diag([7.0, 0.0, 0.0]), F) == pytest.approx(7.0)
    assert von_mises(np.diag([3.0, 3.0, 3.0]), F) == pytest.approx(0.0, abs=1e-12)
    shear = np.array([[0.0, 2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert von_mises(shear, F) == pytest.approx(2.0 * math.sqrt(3.0))
    # Cauchy stress of a stretched state: sigma = P F^T / J.
    F2 = np.diag([2.0, 1.0, 0.5])
    P = np.diag([4.0, 0.0, 0.0])  # sigma = diag(8, 0, 0) / 1
    assert von_mises(P, F2) == pytest.approx(8.0)


# -- the UFL forms the solver compiles -------------------------------------------------------


def _ufl_stress(material_name: str, params: list[tuple[object, np.ndarray]]) -> list[np.ndarray]:
    """P from the UFL energy via DOLFINx: one tetrahedron, affine u = (F - I) X, DG0 test.

    Every parameter is a fem.Constant, so one compiled form serves all cases.
    """
    import dolfinx.fem
    import ufl

    from woundsweep.physics import compat

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    cells = np.array([[0, 1, 2, 3]])
    facets = np.array([[0, 1, 2]])
    mesh, _, _ = compat.mesh_from_arrays(pts, cells, np.array([1]), facets, np.array([16]))
    V = compat.vector_space(mesh, 1)
    u = dolfinx.fem.Function(V)
    q = ufl.TestFunction(compat.dg0_space(mesh))
    template = params[0][0]
    consts = {
        name: dolfinx.fem.Constant(mesh, np.asarray(getattr(template, name), dtype=float))
        for name in template.__dataclass_fields__
    }
    sym = type(template)(**consts)
    S = dolfinx.fem.Constant(mesh, np.zeros((3, 3)))
    Fv = ufl.variable(ufl.Identity(3) + ufl.grad(u))
    P = first_piola(sym, Fv)
    dx = ufl.dx(metadata={"quadrature_degree": 1})
    form = compat.compile_form(ufl.inner(P, S) * q * dx)
    X = V.tabulate_dof_coordinates()
    out = []
    for mat, F in params:
        for name, c in consts.items():
            c.value = np.asarray(getattr(mat, name), dtype=float)
        u.x.array[:] = (X @ (F - np.eye(3)).T).ravel()
        P_num = np.zeros((3, 3))
        for i in range(3):
            for j in range(3):
                sel = np.zeros((3, 3))
                sel[i, j] = 1.0
                S.value = sel
                b = compat.create_vector(form)
                compat.assemble_vector(b, form)
                P_num[i, j] = b.getArray()[0] * 6.0  # / cell volume 1/6
        out.append(P_num)
    return out


@pytest.mark.fem
def test_ufl_fung_stress_matches_reference_for_all_skin_types_and_orientations() -> None:
    cases, refs = [], []
    for skin in SKIN_TYPES:
        p = FLYNN_SKIN_TYPES[skin]
        for angle in ANGLES:
            for F in deformations()[:3]:
                cases.append((Fung.table2(skin, angle), F))
                refs.append(fd_stress(lambda G, p=p, a=angle: ref_fung_energy(G, p, a), F))
    for got, ref in zip(_ufl_stress("fung", cases), refs):
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-6)


@pytest.mark.fem
def test_ufl_mooney_rivlin_stress_matches_reference() -> None:
    cases = [(MooneyRivlin.subcutis(), F) for F in deformations()]
    for got, (_, F) in zip(_ufl_stress("mr", cases), cases):
        np.testing.assert_allclose(got, fd_stress(ref_mr_energy, F), rtol=1e-6, atol=1e-7)

"""The contact's coupling pattern and the preallocated tangent matrix of the wound problem.

Without DOLFINx: the vectorised neighbour search against brute force, the planned pattern
against the tangents of states near the plan, and its growth past the plan. With DOLFINx, on
a contact stage of a small real model (the demo's deep wedge at 45 degrees, tie active): every
entry of the contact and tie tangents lies in the preallocated pattern, the stage's Newton
steps cause no PETSc malloc and keep the matrix's nonzero state (so MUMPS keeps its
analysis), and the assembled Jacobian is the one of plain insertion into the form's matrix.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np
import pytest
import scipy.sparse
from contact_surfaces import penetrating_state, two_squares

from woundsweep.contact import GPA_TO_KPA, FlankContact
from woundsweep.physics.assembly import structure


def _contains(P: Any, K: Any) -> bool:
    """Whether the structure ``P`` holds every entry of ``K``."""
    return structure(P, K).nnz == structure(P).nnz


def _squares_contact(**kw: float) -> tuple[FlankContact, np.ndarray]:
    X, left, right, right_nodes = two_squares(3, 4)
    c = FlankContact(X, left, right, **kw)
    c.k_V_kPa = 1.0 * GPA_TO_KPA
    return c, right_nodes


# -- without DOLFINx ---------------------------------------------------------------------------


def test_neighbour_search_finds_the_brute_force_pairs_in_point_facet_order() -> None:
    c, right_nodes = _squares_contact()
    rng = np.random.default_rng(1)
    for noise in (0.0, 0.02, 0.1):
        x = c.positions(penetrating_state(rng, c.X, right_nodes, 0.01, noise))
        for ps in c.passes:
            q, f = c._pairs(x, ps)
            cen = x[ps.facets].mean(axis=1)
            d2 = np.sum((x[ps.nodes][:, None, :] - cen[None, :, :]) ** 2, axis=2)
            q_ref, f_ref = np.nonzero(d2 < ps.rho_mm[None, :] ** 2)  # row-major: q, then f
            assert len(q) > 0
            np.testing.assert_array_equal(q, q_ref)
            np.testing.assert_array_equal(f, f_ref)


def test_the_planned_pattern_holds_the_tangents_of_nearby_states() -> None:
    c, right_nodes = _squares_contact()
    rng = np.random.default_rng(2)
    u0 = penetrating_state(rng, c.X, right_nodes, 0.01, 0.002)
    c.plan_pattern(u0)
    P, version = c.coupling_pattern(), c.pattern_version
    for _ in range(5):
        u = u0 + 0.002 * rng.standard_normal(len(u0))  # a tenth of the kernel margin
        K = c.tangent_csr(u)
        assert K.nnz > 0 and _contains(P, K)
    assert c.pattern_version == version and c.pattern_growths == 0
    # The plan leaves out the points that are far from touching.
    c.clear_pattern()
    assert c.coupling_pattern() is None
    c.plan_pattern(penetrating_state(rng, c.X, right_nodes, -0.5, 0.0))  # pulled apart
    assert c.coupling_pattern().nnz == 0


def test_a_tangent_past_the_plan_grows_the_pattern_without_dropping_it() -> None:
    c, right_nodes = _squares_contact(pattern_gap=0.0, pattern_margin=0.0)
    rng = np.random.default_rng(3)
    u0 = penetrating_state(rng, c.X, right_nodes, 0.01, 0.0)
    c.plan_pattern(u0)
    P0, v0 = c.coupling_pattern(), c.pattern_version
    u1 = u0.copy()
    u1.reshape(-1, 3)[right_nodes, 1] += 0.3  # the right square slides along y
    K = c.tangent_csr(u1)
    assert not _contains(P0, K)  # the slide reaches past the plan ...
    assert c.pattern_growths == 1 and c.pattern_version != v0
    P1 = c.coupling_pattern()
    assert _contains(P1, K) and _contains(P1, P0)  # ... which grows and keeps P0's pairs
    c.tangent_csr(u1)  # the same state again: no growth
    assert c.pattern_growths == 1


# -- on a real model -----------------------------------------------------------------------------


def _nonzero_state(A: Any) -> int:
    """PETSc's nonzero state of ``A`` (MUMPS redoes its analysis when it changes)."""
    from petsc4py import PETSc

    try:
        get = ctypes.CDLL(PETSc.__file__).MatGetNonzeroState
    except (OSError, AttributeError):
        pytest.skip("MatGetNonzeroState is not reachable through ctypes")
    out = ctypes.c_int64()
    assert get(ctypes.c_void_p(A.handle), ctypes.byref(out)) == 0
    return out.value


def _csr(A: Any) -> Any:
    indptr, indices, data = A.getValuesCSR()
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=A.getSize())


class _Step:
    """One recorded Jacobian: mallocs, nonzero state and the pattern version after it, and
    whether the contact and tie tangents lay in the matrix's pattern."""

    def __init__(self, A: Any, m: Any, mallocs: float) -> None:
        c, tie = m.contact, m.tie
        self.mallocs = mallocs
        self.state = _nonzero_state(A)
        self.version = c.pattern_version
        S = _csr(A)
        Ks = [c.tangent_csr(m.u)] + ([tie.tangent_csr(c.k_V_kPa)] if tie.active else [])
        self.inside = all(_contains(S, K) for K in Ks)
        self.contact_nnz = Ks[0].nnz


@pytest.fixture(scope="module")
def stage4(deep_wedge_mesh) -> dict[str, Any]:
    """Stages 1-4 of the demo's deep wedge at 45 degrees, every stage-4 Jacobian recorded."""
    from woundsweep.config.solver import SolverSettings
    from woundsweep.physics.materials import JobMaterials
    from woundsweep.physics.model import WoundModel
    from woundsweep.physics.stages import run_stage

    m = WoundModel(deep_wedge_mesh, SolverSettings(element_degree=1))  # the P1 mesh
    m.set_materials(JobMaterials.table2("stiff", 45.0))
    for k in (1, 2, 3):
        run_stage(m, k)
    A, jacobian, steps = m.problem.A, m.problem.jacobian, []

    def recorded(A_: Any) -> None:
        before = A_.getInfo()["mallocs"]
        jacobian(A_)
        steps.append(_Step(A_, m, A_.getInfo()["mallocs"] - before))

    m.problem.jacobian = recorded
    out = run_stage(m, 4)
    del m.problem.jacobian
    return {"model": m, "out": out, "steps": steps, "A": A}


@pytest.mark.fem
def test_a_contact_stage_stays_in_its_preallocated_pattern(stage4) -> None:
    m, steps = stage4["model"], stage4["steps"]
    assert stage4["out"].solve.status == "converged"
    assert m.tie.active and len(steps) > 5 and all(s.contact_nnz > 0 for s in steps)
    assert all(s.inside for s in steps)
    assert sum(s.mallocs for s in steps) == 0
    # The nonzero state changes only where the contact's pattern grew.
    for a, b in zip(steps, steps[1:]):
        assert (a.state == b.state) == (a.version == b.version)
    assert m.contact.pattern_growths <= 1


@pytest.mark.fem
def test_the_preallocated_jacobian_is_that_of_plain_insertion(stage4) -> None:
    from woundsweep.physics import compat

    m = stage4["model"]
    m.problem.jacobian(m.problem.A)
    B = compat.create_matrix(m.forms.a_form)  # not the problem's: contact terms inserted
    m.problem.jacobian(B)
    J, J_ref = _csr(m.problem.A), _csr(B)
    scale = abs(J_ref).max()
    assert abs(J - J_ref).max() <= 1e-12 * scale


@pytest.mark.fem
def test_the_pattern_grows_when_a_state_leaves_it(stage4) -> None:
    from woundsweep.physics import compat

    m = stage4["model"]
    c, A = m.contact, m.problem.A
    u2, u4 = m.displacements[2].copy(), m.u.copy()
    saved = c.pattern_gap, c.pattern_margin
    c.pattern_gap = c.pattern_margin = 0.0  # no margin: any slide leaves the plan
    try:
        m.set_materials(m.materials)  # a new job: stage 1 assembles the form alone
        m.problem.jacobian(A)
        assert c.coupling_pattern() is None
        m.tie.set_reference(u2)
        m.u[:] = u4
        c.k_V_kPa = 1.0 * GPA_TO_KPA
        m.problem.jacobian(A)  # plans at u4
        growths, version = c.pattern_growths, c.pattern_version
        m.u.reshape(-1, 3)[c.surfaces[0].nodes, 1] += 0.5 * float(np.min(c.passes[0].size_mm))
        before = A.getInfo()["mallocs"]
        m.problem.jacobian(A)
        assert c.pattern_growths == growths + 1 and c.pattern_version != version
        assert A.getInfo()["mallocs"] == before
        B = compat.create_matrix(m.forms.a_form)
        m.problem.jacobian(B)
        J, J_ref = _csr(A), _csr(B)
        assert abs(J - J_ref).max() <= 1e-12 * abs(J_ref).max()
    finally:
        c.pattern_gap, c.pattern_margin = saved


@pytest.mark.fem
def test_an_entry_outside_the_pattern_still_reaches_the_factorised_matrix(stage4) -> None:
    """A tangent entry the preallocation did not foresee is inserted, never dropped: through
    the block matrix too, whose grown structure the factorised matrix then takes."""
    from woundsweep.physics import compat

    m = stage4["model"]
    c, A = m.contact, m.problem.A
    n = A.getSize()[0]
    i, j = 0, n - 1  # two dofs far apart: no form, contact or tie term couples them
    assert _csr(A)[i, j] == 0.0
    K = c.tangent_csr(m.u) + scipy.sparse.csr_matrix(([7.0, 7.0], ([i, j], [j, i])), shape=(n, n))
    m.problem._assemble(A, c, K)
    assert A.getInfo()["mallocs"] == 0  # A took the grown structure at once
    B = compat.create_matrix(m.forms.a_form)
    compat.assemble_matrix(B, m.forms.a_form, finalize=False)
    from woundsweep.physics.assembly import add_csr

    add_csr(B, K, finalize=False)
    if m.tie.active:
        add_csr(B, m.tie.tangent_csr(c.k_V_kPa), finalize=False)
    B.assemble()
    J, J_ref = _csr(A), _csr(B)
    assert J[i, j] == 7.0 and J[j, i] == 7.0
    assert abs(J - J_ref).max() <= 1e-12 * abs(J_ref).max()
    m.problem.jacobian(A)  # the next step: the stray entry is gone again (zeroed)
    assert _csr(A)[i, j] == 0.0

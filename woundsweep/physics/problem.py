"""The nonlinear problem Newton solves: the wound model's residual, tangent and potential.

`WoundProblem` joins the compiled forms (`WoundForms`), the closure load of stages 3-6 (a
nodal force vector, ``closure_load``), the flank contact (a `woundsweep.contact.ContactModel`,
or None for an unwounded patch) and the closure zone's tangential tie
(`woundsweep.contact.ZoneTie`) into the `woundsweep.solver.NonlinearProblem` protocol. The
contact and tie terms are added while the penalty is on (``contact.k_V_kPa > 0``; the tie only
once set); the sutures' threads (``cables``, `woundsweep.contact.Cables`, None without) once
tied, whatever the penalty: their tangent's sparse part into ``A``, the rest a low-rank term
Newton takes apart (`low_rank`); ``multipliers`` are the contact multipliers Newton carries
there. The potential is
not used by Newton: that it exists (every load is dead) makes the tangent symmetric, and
`tests/physics/test_stages_contact.py` checks R = dPi/du.

Sparsity of the tangent matrix ``A``: while the contact is off, that of the form; while it is
on, the form's plus the contact's coupling pattern (planned at the first tangent of a contact
episode, grown by the contact when a tangent reaches past it) plus the tie's fixed pairs,
preallocated at once; the threads' fixed pattern is added to either once they are attached. Between the growths the Newton steps add no nonzeros, so PETSc does not
reallocate and MUMPS keeps its symbolic analysis.

Where DOLFINx makes one, the tangent is assembled into a block matrix (BAIJ, 3x3 node blocks:
DOLFINx then inserts a cell's values with one search per node pair instead of one per entry)
with the same pattern closed to whole blocks, and copied into ``A``, the scalar AIJ matrix
that MUMPS's LDL^T factorises.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import scipy.sparse
from petsc4py import PETSc

from ..contact import Cables, ContactModel, ContactMultipliers, ZoneTie
from . import compat
from .assembly import add_csr, add_vector, structure
from .domain import WoundDomain
from .forms import WoundForms

__all__ = ["WoundProblem"]


def _blocks(P: Any, bs: int) -> Any:
    """The block structure (CSR of ones, sorted) of the blocks of size ``bs`` that hold an
    entry of the structure ``P``."""
    coo = P.tocoo()
    n = P.shape[0] // bs
    ones = np.ones(len(coo.row), dtype=np.int32)
    Pb = scipy.sparse.csr_matrix((ones, (coo.row // bs, coo.col // bs)), shape=(n, n))
    Pb.sum_duplicates()
    Pb.sort_indices()
    Pb.data[:] = 1
    return Pb


class WoundProblem:
    """Residual R(u), tangent dR/du and potential of the wound model at the state ``forms.u``."""

    def __init__(
        self,
        domain: WoundDomain,
        forms: WoundForms,
        contact: ContactModel | None,
        tie: ZoneTie | None = None,
    ) -> None:
        self.domain, self.forms, self.contact, self.tie = domain, forms, contact, tie
        # Dead nodal forces (mN, flat dofs) of the closure of stages 3-6; None: no such load.
        self.closure_load: np.ndarray | None = None
        # The sutures as threads (`woundsweep.contact.cable`); in A's pattern once preallocated.
        self.cables: Cables | None = None
        self._cables_in_pattern = False
        self.A = compat.create_matrix(forms.a_form)
        self._B = compat.create_block_matrix(forms.a_form)  # None: assemble into A itself
        self._B_nnz: float | None = None  # B's entries when A last took its structure
        # A's sparsity (module docstring): the form's structure once seen, and the contact's
        # pattern_version A is preallocated for (None: the form's alone).
        self._form_structure: Any = None
        self._pattern_version: int | None = None
        # Carried by Newton in the contact stages (woundsweep.contact.multipliers).
        self.multipliers = (
            ContactMultipliers(contact, self.solution) if contact is not None else None
        )

    def _contact_on(self) -> ContactModel | None:
        c = self.contact
        return c if c is not None and c.k_V_kPa > 0.0 else None

    # -- NonlinearProblem -------------------------------------------------------------------

    def solution(self) -> np.ndarray:
        return self.forms.u.x.array

    def residual(self, b: PETSc.Vec) -> None:
        compat.assemble_vector(b, self.forms.R_form)
        if self.closure_load is not None:
            add_vector(b, -self.closure_load)
        c = self._contact_on()
        if c is not None:
            u = self.solution()
            add_vector(b, c.force_vector(u))
            if self.tie is not None and self.tie.active:
                add_vector(b, self.tie.force_vector(u, c.k_V_kPa))
        if self.cables is not None and self.cables.active:
            add_vector(b, self.cables.force_vector(self.solution()))

    def jacobian(self, A: PETSc.Mat) -> None:
        c = self._contact_on()
        if A is not self.A:  # not the problem's matrix: its pattern grows by insertion
            threads = self.cables is not None and self.cables.active
            compat.assemble_matrix(A, self.forms.a_form, finalize=c is None and not threads)
            if c is not None:
                self._add_contact(A, c, c.tangent_csr(self.solution()))
            if threads:
                self._add_cables(A)
            if c is not None or threads:
                A.assemble()
            return
        if c is None:
            missing = self.cables is not None and not self._cables_in_pattern
            if self._pattern_version is not None or missing:  # a contact episode ended
                self._preallocate(A, None)
            self._assemble(A)
            if self._form_structure is None:
                self._form_structure = self._structure_of(A)
            return
        u = self.solution()
        if c.coupling_pattern() is None:
            c.plan_pattern(u)
        K = c.tangent_csr(u)  # grows the coupling pattern if it reaches past it
        if self._pattern_version != c.pattern_version or (
            self.cables is not None and not self._cables_in_pattern
        ):
            self._preallocate(A, c)
        self._assemble(A, c, K)

    def _assemble(self, A: PETSc.Mat, c: ContactModel | None = None, K: Any = None) -> None:
        """Assemble the form, and with ``c`` the contact tangent ``K`` and the tie's, into A
        (through the block matrix where there is one): one finalisation per step."""
        M = self._B if self._B is not None else A
        compat.assemble_matrix(M, self.forms.a_form, finalize=False)
        if c is not None:
            self._add_contact(M, c, K)
        self._add_cables(M)
        M.assemble()
        if M is A:
            return
        nnz = M.getInfo()["nz_used"]
        if nnz != self._B_nnz:  # M newly preallocated, or an entry went in outside its pattern
            indptr, indices, _ = M.getValuesCSR()
            A.setPreallocationCSR((indptr, indices))
            A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
            self._B_nnz = nnz
        # The copy keeps A's structure (the same as M's), so MUMPS keeps its analysis.
        M.convert(A.getType(), out=A)

    def _add_contact(self, M: PETSc.Mat, c: ContactModel, K: Any) -> None:
        """Add the contact tangent ``K`` and the tie's to ``M``, unfinalised (entries outside
        its pattern are inserted)."""
        t0 = time.perf_counter()
        if K is not None and K.nnz:
            add_csr(M, K, finalize=False)
        c.assembly_time_s += time.perf_counter() - t0
        if self.tie is not None and self.tie.active:
            add_csr(M, self.tie.tangent_csr(c.k_V_kPa), finalize=False)

    def set_cables(self, cables: Cables | None) -> None:
        """Add the threads ``cables`` to the problem (None: none); A's pattern takes theirs at
        the next tangent."""
        self.cables = cables
        self._cables_in_pattern = False

    def _add_cables(self, M: PETSc.Mat) -> None:
        """Add the threads' tangent's sparse part to ``M``, unfinalised (nothing while they
        are untied)."""
        if self.cables is not None and self.cables.active:
            add_csr(M, self.cables.sparse_tangent_csr(self.solution()), finalize=False)

    def low_rank(self) -> tuple[Any, np.ndarray] | None:
        """The tangent's part not in ``A``: (U, c) with J = A + U diag(c) U^T (the threads',
        `Cables.low_rank`), or None."""
        if self.cables is None or not self.cables.active:
            return None
        U, c = self.cables.low_rank(self.solution())
        return (U, c) if len(c) else None

    @staticmethod
    def _structure_of(A: PETSc.Mat) -> Any:
        """The nonzero structure of the assembled matrix ``A`` (scipy CSR of ones)."""
        indptr, indices, _ = A.getValuesCSR()
        return scipy.sparse.csr_matrix(
            (np.ones(len(indices), dtype=np.int32), indices, indptr), shape=A.getSize()
        )

    def _preallocate(self, A: PETSc.Mat, c: ContactModel | None) -> None:
        """Give ``A`` the form's structure plus, with ``c``, the contact's coupling pattern and
        the tie's pairs (no values are kept); without ``c`` the contact's pattern is dropped."""
        if self._form_structure is None:  # A holds no more than the form's structure yet
            self._assemble(A)
            self._form_structure = self._structure_of(A)
        parts = [self._form_structure]
        if c is not None:
            parts.append(c.coupling_pattern())
            if self.tie is not None and len(self.tie):
                parts.append(self.tie.coupling_pattern())
        elif self.contact is not None:
            self.contact.clear_pattern()
        if self.cables is not None:
            parts.append(self.cables.coupling_pattern())
        self._cables_in_pattern = self.cables is not None
        P = structure(*parts)
        # The block matrix holds whole 3x3 blocks; A takes its entries at the next assembly.
        M = self._B if self._B is not None else A
        if M is self._B:
            assert M is not None  # it is self._B, which is not None here
            P = _blocks(P, M.getBlockSize())
            self._B_nnz = None
        M.setPreallocationCSR((P.indptr.astype(PETSc.IntType), P.indices.astype(PETSc.IntType)))
        # Preallocation forbids new entries; one outside the pattern must still go in.
        M.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self._pattern_version = None if c is None else c.pattern_version

    def energy(self) -> float | None:
        """Total potential (mN mm) at the current state: every load is dead."""
        e = compat.assemble_scalar(self.forms.Pi_form)
        if self.closure_load is not None:
            e -= float(self.closure_load @ self.solution())
        c = self._contact_on()
        if c is not None:
            e += c.energy(self.solution())
            if self.tie is not None:
                e += self.tie.energy(self.solution(), c.k_V_kPa)
        if self.cables is not None:
            e += self.cables.energy(self.solution())
        return e

    def min_det(self, u: np.ndarray) -> float:
        return self.domain.min_det(u)

    def max_strain(self, du: np.ndarray) -> float:
        return self.domain.max_strain(du)

    def length_scale(self) -> float:
        return self.domain.ell

    # -- helpers of the stages --------------------------------------------------------------

    def residual_array(self) -> np.ndarray:
        """R(u) at the current state as a flat array (reactions included)."""
        b = self.forms.u_vec.duplicate()
        self.residual(b)
        return b.getArray(readonly=True).copy()

    def internal_force(self) -> np.ndarray:
        """Nodal internal forces at the current state (external loads and contact off)."""
        saved, closure = self.forms.loads(), self.closure_load
        c = self.contact
        k_V = c.k_V_kPa if c is not None else 0.0
        self.forms.set_loads(0.0, 0.0)
        self.closure_load = None
        if c is not None:
            c.k_V_kPa = 0.0
        r = self.residual_array()
        self.forms.set_loads(*saved)
        self.closure_load = closure
        if c is not None:
            c.k_V_kPa = k_V
        return r

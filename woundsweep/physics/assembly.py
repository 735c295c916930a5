"""PETSc glue for the terms assembled outside the forms (contact and tie): adding flat force
vectors to an assembled residual, scipy CSR tangents to an assembled matrix, and the union
of sparsity structures that preallocates it."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["add_csr", "add_vector", "structure"]


def add_vector(b: Any, f: np.ndarray) -> None:
    """Add the flat dof vector ``f`` to the assembled PETSc vector ``b`` (serial)."""
    arr = b.getArray()
    arr += f[: len(arr)]


def add_csr(A: Any, K: Any, *, finalize: bool = True) -> None:
    """Add the scipy CSR matrix ``K`` to the PETSc matrix ``A``; re-finalise it unless
    ``finalize`` is False.

    An entry outside the preallocated pattern is inserted (a malloc and a new nonzero state,
    so MUMPS redoes its analysis), never refused: the contact terms couple nodes across the
    wound that the finite-element pattern does not."""
    from petsc4py import PETSc

    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    A.setValuesCSR(
        K.indptr.astype(PETSc.IntType),
        K.indices.astype(PETSc.IntType),
        K.data.astype(PETSc.ScalarType),
        addv=PETSc.InsertMode.ADD_VALUES,
    )
    if finalize:
        A.assemble()


def structure(*mats: Any) -> Any:
    """The union of the sparsity structures of scipy sparse matrices of one shape: a CSR
    matrix of ones with sorted indices (explicit zeros count as entries)."""
    import scipy.sparse

    parts = []
    for M in mats:
        S = scipy.sparse.csr_matrix(M, copy=True)
        S.data = np.ones(len(S.data), dtype=np.int32)  # positive: a sum cannot cancel an entry
        parts.append(S)
    out = parts[0]
    for S in parts[1:]:
        out = out + S
    out = scipy.sparse.csr_matrix(out)
    out.sum_duplicates()
    out.data[:] = 1
    return out

"""One sparse Cholesky factor, factored once and solved many times (CHOLMOD through cholespy).

The package's sparse symmetric positive definite systems (the reconstruction's normal matrix,
:mod:`.poisson`; the contact QP's ADMM system, :mod:`facebasis.contact.qp`) all go through
:class:`SparseCholesky`: cholespy (a small, maintained binding of CHOLMOD's supernodal
factorisation with multi-column solves) is used instead of ``scipy.sparse.linalg.splu`` / ``spsolve``,
which factor an SPD matrix as a general one (LU, no symmetry: about twice the fill and flops).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class SparseCholesky:
    """Sparse Cholesky factor of a symmetric positive definite matrix ``M`` (n, n), factored once.

    Raises what cholespy raises (``RuntimeError`` / ``ValueError``) when ``M`` is not positive
    definite; callers turn it into their own error (e.g. a mesh part without anchor)."""

    def __init__(self, M: sp.spmatrix):
        from cholespy import CholeskySolverD, MatrixType

        coo = sp.coo_matrix(M)
        self.n = coo.shape[0]
        self._s = CholeskySolverD(self.n, coo.row.astype(np.int32), coo.col.astype(np.int32),
                                  coo.data.astype(np.float64), MatrixType.COO)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``M^-1 rhs`` for rhs (n,) or (n, c) (all columns in one pass), float64."""
        b = np.ascontiguousarray(rhs, np.float64)
        x = np.zeros_like(b)
        self._s.solve(b, x)
        return x


__all__ = ["SparseCholesky"]

"""Harmonic initialisation of the mesh displacements (Wu & Ju 2016, eq. 6-9).

The stretching energy of the displacement field ``d`` (eq. 6) is minimised by ``Laplace d = 0``
(eq. 7) with the cotangent Laplace-Beltrami operator (eq. 8)::

    (Laplace d)_i = 1 / (2 A_i) * sum_j (cot alpha_ij + cot beta_ij) (d_j - d_i)

(:func:`facebasis.geometry.laplacian.cotangent_laplacian`) and the landmark displacements as
Dirichlet conditions (eq. 9). The factor ``1 / (2 A_i)`` scales
row ``i`` only, so it does not change the solution and is dropped. Eliminating the landmark unknowns
from eq. 9 leaves ``L_ff d_f = -L_fc h`` for the free vertices ``f``, a sparse system factored once
on the first frame (SciPy SuperLU); each frame only changes the right-hand side ``h``.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.linalg import splu

from facebasis.errors import SolverError
from facebasis.geometry.laplacian import cotangent_laplacian


class HarmonicDeformer:
    """Harmonic displacement field with Dirichlet values at the control vertices (eq. 7-9).

    Parameters
    ----------
    V : ndarray, shape (N, 2)
        Rest positions (first frame).
    F : ndarray, shape (M, 3)
    controls : ndarray, shape (H,)
        Indices of the control vertices (the landmarks).

    Notes
    -----
    The factorisation of ``L_ff`` is computed once here; :meth:`solve` is a pair of triangular
    solves per call.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, controls: np.ndarray):
        n = len(V)
        self.n = n
        self.controls = np.asarray(controls, int)
        mask = np.ones(n, bool)
        mask[self.controls] = False
        self.free = np.flatnonzero(mask)
        K = cotangent_laplacian(V, F).tocsc()
        self._K_fc = K[self.free][:, self.controls].tocsr()
        if len(self.free):
            try:
                self._lu = splu(K[self.free][:, self.free].tocsc())  # eq. 9, left side: factored once
            except RuntimeError as exc:
                raise SolverError(f"harmonic initialisation: the Laplacian is singular ({exc})", "singular") from None

    def solve(self, h: np.ndarray) -> np.ndarray:
        """Displacements of all vertices for control displacements ``h``.

        Parameters
        ----------
        h : ndarray, shape (H, 2)
            Displacements of the control vertices (eq. 9 right-hand side ``h_b``).

        Returns
        -------
        ndarray, shape (N, 2)
        """
        d = np.zeros((self.n, 2))
        d[self.controls] = h
        if len(self.free):
            d[self.free] = self._lu.solve(-(self._K_fc @ h))  # eq. 9: L_ff p = -L_fc h
        return d

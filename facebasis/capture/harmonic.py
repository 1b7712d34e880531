"""Harmonic initialisation of the mesh displacements (Wu & Ju 2016, eq. 6-9).

The stretching energy of the displacement field ``d`` (eq. 6) is minimised by ``Laplace d = 0``
(eq. 7) with the cotangent Laplace-Beltrami operator (eq. 8)::

    (Laplace d)_i = 1 / (2 A_i) * sum_j (cot alpha_ij + cot beta_ij) (d_j - d_i)

and the landmark displacements as Dirichlet conditions (eq. 9). The factor ``1 / (2 A_i)`` scales
row ``i`` only, so it does not change the solution and is dropped. Eliminating the landmark unknowns
from eq. 9 leaves ``L_ff d_f = -L_fc h`` for the free vertices ``f``, a sparse system factored once
on the first frame (SciPy SuperLU); each frame only changes the right-hand side ``h``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from facebasis.errors import SolverError


def cotangent_weights(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cotangent edge weights of a 2D triangle mesh (eq. 8).

    Parameters
    ----------
    V : ndarray, shape (N, 2)
    F : ndarray, shape (M, 3)

    Returns
    -------
    I, W : ndarrays, shape (3M, 2) and (3M,)
        Half-edge vertex pairs ``(i, j)`` and ``0.5 * cot`` of the angle opposite to edge ``ij`` in
        that triangle; summing over both triangles of an edge gives
        ``0.5 * (cot alpha_ij + cot beta_ij)``.
    """
    out_i, out_w = [], []
    for k in range(3):  # the three corners of every triangle, vectorised over triangles
        o, i, j = F[:, k], F[:, (k + 1) % 3], F[:, (k + 2) % 3]
        u, v = V[i] - V[o], V[j] - V[o]
        cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        cot = (u * v).sum(1) / np.maximum(cross, 1e-12)
        out_i.append(np.stack([i, j], 1))
        out_w.append(0.5 * cot)
    return np.concatenate(out_i), np.concatenate(out_w)


def cotangent_laplacian(V: np.ndarray, F: np.ndarray, clip_negative: bool = False) -> sp.csr_matrix:
    """Symmetric positive semi-definite cotangent Laplacian ``K`` (eq. 8 without the area factor).

    ``d^T K d = sum_edges w_ij |d_i - d_j|^2`` is the Dirichlet (stretching) energy of eq. 6.

    Parameters
    ----------
    V : ndarray, shape (N, 2)
    F : ndarray, shape (M, 3)
    clip_negative : bool
        Replace negative edge weights (edges opposite obtuse angles on the boundary) by zero.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (N, N)
    """
    n = len(V)
    I, W = cotangent_weights(V, F)
    W_edge = sp.coo_matrix((W, (I[:, 0], I[:, 1])), shape=(n, n)).tocsr()
    W_edge = W_edge + W_edge.T
    if clip_negative:
        W_edge.data = np.maximum(W_edge.data, 0.0)
    deg = np.asarray(W_edge.sum(1)).ravel()
    return (sp.diags(deg) - W_edge).tocsr()


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

"""The cotangent Laplace-Beltrami operator of a triangle mesh in the plane or in space.

For a mesh with vertices ``V`` (n, 2) or (n, 3) and triangles ``F`` (m, 3), the symmetric positive
semi-definite matrix

    K = sum_edges w_ij (e_i - e_j)(e_i - e_j)^T,   w_ij = (cot alpha_ij + cot beta_ij) / 2

so that ``d^T K d = sum_ij w_ij |d_i - d_j|^2`` is the Dirichlet energy of a per-vertex field ``d``
(Pinkall & Polthier 1993; Meyer et al. 2003). ``-K`` is libigl's ``cotmatrix``. The lumped mass
gives each vertex a third of the area of its triangles. Used by the capture's harmonic
initialisation (Wu & Ju 2016, eq. 8) and by the reproduction's smooth mesh driving.

References
----------
- Pinkall U., Polthier K. Computing discrete minimal surfaces and their conjugates. Experimental
    Mathematics 2(1), 1993.
- Meyer M., Desbrun M., Schroeder P., Barr A. H. Discrete differential-geometry operators for
    triangulated 2-manifolds. Visualization and Mathematics III, 2003.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def _corner_cotangents(V: np.ndarray, F: np.ndarray):
    """Per corner k of every triangle: the opposite edge (i, j) and ``cot`` of the angle at k, and
    twice the triangle areas (m,). Degenerate triangles (area below 1e-12 of the mesh's squared
    size) get cotangent 0."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    P = V[F]                                                   # (m, 3, d)
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    if V.shape[1] == 2:
        area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    else:
        area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    ok = area2 > 1e-12 * max(1.0, float(np.abs(V).max())) ** 2
    I, J, C = [], [], []
    for k in range(3):  # the three corners, each vectorised over all triangles
        a, b, c = P[:, k], P[:, (k + 1) % 3], P[:, (k + 2) % 3]
        cot = np.einsum("ij,ij->i", b - a, c - a) / np.where(ok, area2, 1.0)
        I.append(F[:, (k + 1) % 3])
        J.append(F[:, (k + 2) % 3])
        C.append(np.where(ok, cot, 0.0))
    return np.concatenate(I), np.concatenate(J), np.concatenate(C), np.where(ok, area2, 0.0)


def cotangent_laplacian(V: np.ndarray, F: np.ndarray, clip_negative: bool = False) -> sp.csr_matrix:
    """The cotangent Laplacian ``K`` (n, n), positive semi-definite (see the module docstring).

    Parameters
    ----------
    V : (n, 2) or (n, 3) vertex positions
    F : (m, 3) triangles
    clip_negative : replace negative edge weights (edges opposite obtuse angles) by zero, which
        keeps ``K`` an M-matrix (a maximum principle) at the price of consistency

    Returns
    -------
    K : scipy.sparse.csr_matrix (n, n)
    """
    n = len(V)
    I, J, cot, _ = _corner_cotangents(V, F)
    W = sp.coo_matrix((0.5 * cot, (I, J)), shape=(n, n)).tocsr()
    W = W + W.T
    if clip_negative:
        W.data = np.maximum(W.data, 0.0)
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()


def lumped_mass(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """A third of the area of the triangles around each vertex, (n,)."""
    _, _, _, area2 = _corner_cotangents(V, F)
    mass = np.zeros(len(V))
    np.add.at(mass, np.asarray(F, np.int64).ravel(), np.repeat(area2 / 6.0, 3))
    return mass


__all__ = ["cotangent_laplacian", "lumped_mass"]

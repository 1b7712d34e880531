"""The separation QP of exact contact: its energy, its rows and its solver (ADMM).

The energy of a correction ``x`` (n, 3) of a transferred shape is ``x^T L x`` with ``L = E^T E (+ w X^T X)``
the normal matrix the deformation transfer factors (Sumner and Popovic 2004; plus the virtual-edge
rows, if any), optionally ``+ beta I`` (``stiffness``: the smallest displacement, for generated shapes).
Every constrained triangle pair (T_i, T_j) with separating unit normal ``n`` and gap ``delta`` gives
nine rows ``n . (X_a - X_b) >= delta`` over the corners a of T_i and b of T_j.

References
----------
- Sumner R. W., Popovic J. Deformation transfer for triangle meshes. SIGGRAPH 2004.
- Stellato B., Banjac G., Goulart P., Bemporad A., Boyd S. OSQP: an operator splitting solver for
    quadratic programs. Mathematical Programming Computation 12, 2020 (the ADMM splitting).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..geometry.cholesky import SparseCholesky
from ..geometry.gradients import edge_operator


def normal_matrix(dt, stiffness: float = 0.0) -> sp.csr_matrix:
    """``L = E^T E (+ w X^T X) (+ stiffness I)``, (n, n): the normal matrix the transfer ``dt`` factors
    (before removing anchors), with an optional position term."""
    F, n = dt.template.faces, dt.template.n_vertices
    E = edge_operator(F, n)
    L = E.T @ E
    if dt.poisson.extra_rows is not None:
        X = dt.poisson.extra_rows
        L = L + dt.poisson.extra_weight * (X.T @ X)
    if stiffness:
        L = L + float(stiffness) * sp.eye(n, format="csr")
    return sp.csr_matrix(L)


def separation_rows(F, pairs, normals, delta, active, P, cols):
    """The rows ``active`` (ids ``p * 9 + 3 ka + kb``: pair p, corner ka of its first triangle, kb of its
    second) as ``A x >= g`` over the corrections of the vertices ``cols`` (sorted), x at ``P + x``.

    Returns
    -------
    A : list of three (c, len(cols)) sparse matrices, one per coordinate
    g : (c,) ``delta - n . (P_a - P_b)``
    """
    p, ka, kb = active // 9, (active % 9) // 3, active % 3
    va, vb = F[pairs[p, 0], ka], F[pairs[p, 1], kb]
    nr = normals[p]
    g = delta[p] - (nr * (P[va] - P[vb])).sum(1)
    ca, cb = np.searchsorted(cols, va), np.searchsorted(cols, vb)
    ok_a = (ca < len(cols)) & (cols[np.minimum(ca, len(cols) - 1)] == va)
    ok_b = (cb < len(cols)) & (cols[np.minimum(cb, len(cols) - 1)] == vb)
    c = len(active)
    rows = np.arange(c)
    A = [sp.csr_matrix((np.concatenate([nr[ok_a, k], -nr[ok_b, k]]),
                        (np.concatenate([rows[ok_a], rows[ok_b]]), np.concatenate([ca[ok_a], cb[ok_b]]))),
                       shape=(c, len(cols))) for k in range(3)]
    return A, g


def admm(L: sp.spmatrix, A: sp.csr_matrix, g: np.ndarray, delta: np.ndarray, x: np.ndarray, y: np.ndarray,
         max_iterations: int = 2000, rho_scale: float = 0.5, alpha: float = 1.6):
    """``min 1/2 x^T (I_3 (x) L) x  s.t.  A x >= g`` by ADMM with OSQP's splitting (Stellato et al. 2020):
    stops once every row is met to half its margin ``delta`` and the iterates settle.

    Parameters
    ----------
    L : (r, r) energy; A : (c, 3 r) rows, columns (coordinate, vertex); g, delta : (c,)
    x : (3 r,) start; y : (c,) start multipliers

    Returns
    -------
    x (3 r,), the row multipliers (c,), the iterations.
    """
    n3 = A.shape[1]
    Lb = sp.block_diag([L, L, L], format="csr")
    rho = rho_scale * float(L.diagonal().mean())
    sigma = 1e-6 * rho
    chol = SparseCholesky((Lb + sigma * sp.eye(n3) + rho * (A.T @ A)).tocsr())
    At = A.T.tocsr()
    z = np.maximum(g, A @ x)
    k = 0
    for k in range(1, max_iterations + 1):
        x_new = chol.solve((sigma * x + At @ (rho * z - y))[:, None])[:, 0]
        Ax = A @ x_new
        Ax_r = alpha * Ax + (1.0 - alpha) * z  # over-relaxation
        z = np.maximum(g, Ax_r + y / rho)
        y = y + rho * (Ax_r - z)
        step = float(np.abs(x_new - x).max())
        x = x_new
        if np.all(Ax >= g - 0.5 * delta) and step <= 1e-3 * float(delta.max()):
            break
    return x, y, k


__all__ = ["normal_matrix", "separation_rows", "admm"]

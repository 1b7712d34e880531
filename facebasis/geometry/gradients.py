"""Per-triangle frames, deformation gradients and the vertex-to-edge operator.

All functions are vectorised over triangles and over any leading batch axes (many shapes at once).

References
----------
Sumner, R. W. and Popovic, J. (2004). Deformation transfer for triangle meshes. SIGGRAPH.
   Eq. 1-4: the frame ``V = [v2 - v1, v3 - v1, v4 - v1]`` with
   ``v4 - v1 = (v2 - v1) x (v3 - v1) / sqrt(|(v2 - v1) x (v3 - v1)|)``, and the deformation
   gradient ``Q = V~ V^-1``.
Seed 000 (example-based blendshape generation), section 2.2 and eq. 2-4: blendshapes are
   represented by the edge columns of these frames ("gradient space").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: Triangle edges as (tail corner, head corner): e0 = v2 - v1, e1 = v3 - v2, e2 = v1 - v3.
#: Using all three edges makes the reconstruction symmetric in the triangle's corners.
EDGE_CORNERS = np.array([[0, 1], [1, 2], [2, 0]])

#: Map from the two frame edge columns (v2 - v1, v3 - v1) to the three triangle edges above:
#: ``edges = FRAME_TO_EDGES @ [a, b]`` with a = v2 - v1, b = v3 - v1.
FRAME_TO_EDGES = np.array([[1.0, 0.0], [-1.0, 1.0], [0.0, -1.0]])


def frames_cm(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Sumner-Popovic frames in component-major layout (the fast path used by the solvers).

    Parameters
    ----------
    V : (..., n, 3) vertex positions
    F : (m, 3) triangles

    Returns
    -------
    A : (..., 3, 3, m): ``A[..., x, c, t]`` is coordinate x of column c of triangle t's frame,
        columns ``[v2 - v1, v3 - v1, n / sqrt(|n|)]``, ``n = (v2 - v1) x (v3 - v1)``
        (Sumner & Popovic 2004, eq. 1 and 3).
    """
    # gather from a contiguous (..., 3, n) copy: three times faster than indexing the strided view
    P = np.ascontiguousarray(np.moveaxis(np.asarray(V, dtype=np.float64), -1, -2))  # (..., 3, n)
    v1 = np.take(P, F[:, 0], axis=-1)
    out = np.empty(P.shape[:-2] + (3, 3, len(F)))
    a = out[..., :, 0, :]
    b = out[..., :, 1, :]
    np.subtract(np.take(P, F[:, 1], axis=-1), v1, out=a)
    np.subtract(np.take(P, F[:, 2], axis=-1), v1, out=b)
    nrm = out[..., :, 2, :]
    nrm[..., 0, :] = a[..., 1, :] * b[..., 2, :] - a[..., 2, :] * b[..., 1, :]
    nrm[..., 1, :] = a[..., 2, :] * b[..., 0, :] - a[..., 0, :] * b[..., 2, :]
    nrm[..., 2, :] = a[..., 0, :] * b[..., 1, :] - a[..., 1, :] * b[..., 0, :]
    length = np.sqrt(np.sqrt((nrm ** 2).sum(-2, keepdims=True)))
    np.divide(nrm, length, out=nrm, where=length > 0)
    return out


def triangle_frames(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Sumner-Popovic frames of every triangle (Sumner & Popovic 2004, eq. 1 and 3).

    Parameters
    ----------
    V : (..., n, 3) float array, vertex positions (leading axes are batches of meshes)
    F : (m, 3) int array

    Returns
    -------
    A : (..., m, 3, 3) float array, columns ``[v2 - v1, v3 - v1, n / sqrt(|n|)]`` with
        ``n = (v2 - v1) x (v3 - v1)``. The scaled normal makes the frame's third column scale
        like an edge, so a uniform scaling of the mesh scales the whole frame.
    """
    return np.moveaxis(frames_cm(V, F), -1, -3)


def edge_columns_to_rows(Y: np.ndarray) -> np.ndarray:
    """Frame edge columns (k, 3, 2, m) -> triangle-edge targets (k*3, 3m) for ``EdgePoisson``.

    Row ``3 i + x`` holds coordinate x of shape i; column ``3 t + e`` is edge e of triangle t in
    the order of :data:`EDGE_CORNERS` (:data:`FRAME_TO_EDGES`: ``a``, ``b - a``, ``-b`` for
    columns ``a = v2 - v1``, ``b = v3 - v1``).
    """
    k, _, _, m = Y.shape
    return np.asarray(Y.reshape(k * 3, 2 * m) @ frame_edge_operator(m).T)


def frame_edge_operator(m: int) -> sp.csr_matrix:
    """Sparse (3m, 2m) form of :data:`FRAME_TO_EDGES` for m triangles: maps the frame columns
    ``[a_1..a_m, b_1..b_m]`` to the edges ``3 t + e`` of :data:`EDGE_CORNERS`."""
    t = np.arange(m)
    e, c = np.nonzero(FRAME_TO_EDGES)
    rows = (3 * t[None, :] + e[:, None]).ravel()
    cols = (c[:, None] * m + t[None, :]).ravel()
    vals = np.repeat(FRAME_TO_EDGES[e, c], m)
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * m, 2 * m))


def deformation_gradients(V_rest: np.ndarray, V_def: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Deformation gradients ``Q = A_def A_rest^-1`` of every triangle (Sumner & Popovic eq. 4).

    Parameters
    ----------
    V_rest : (n, 3) rest positions
    V_def : (..., n, 3) deformed positions (batch axes allowed)
    F : (m, 3) triangles

    Returns
    -------
    Q : (..., m, 3, 3). A rigid motion gives rotations, an affine map ``x -> M x + t`` gives ``M``
        for every triangle.
    """
    A_rest_inv = np.linalg.inv(triangle_frames(V_rest, F))
    return triangle_frames(V_def, F) @ A_rest_inv


def triangle_edges(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The three edge vectors of every triangle, (..., m, 3 edges, 3 coords), see ``EDGE_CORNERS``."""
    V = np.asarray(V, dtype=np.float64)
    return V[..., F[:, EDGE_CORNERS[:, 1]], :] - V[..., F[:, EDGE_CORNERS[:, 0]], :]


def frame_edges_to_triangle_edges(A: np.ndarray) -> np.ndarray:
    """Triangle edges (..., m, 3, 3) from frames' first two columns (..., m, 3, >=2)."""
    # edges[e] = sum_c FRAME_TO_EDGES[e, c] * A[:, c]
    return np.einsum("ec,...mxc->...mex", FRAME_TO_EDGES, A[..., :2])


def edge_operator(F: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """Sparse operator ``E`` (3m, n) with ``(E @ V)[3 t + e] = V[head] - V[tail]`` of edge e of t.

    ``E.T @ E`` is the uniform graph Laplacian of the mesh (interior edges counted twice); its
    null space holds one constant per connected component, the translation freedom that
    :class:`facebasis.geometry.poisson.EdgePoisson` removes with anchors.
    """
    m = len(F)
    rows = np.arange(3 * m)
    heads = F[:, EDGE_CORNERS[:, 1]].ravel()
    tails = F[:, EDGE_CORNERS[:, 0]].ravel()
    data = np.concatenate([np.ones(3 * m), -np.ones(3 * m)])
    return sp.csr_matrix(
        (data, (np.concatenate([rows, rows]), np.concatenate([heads, tails]))), shape=(3 * m, n_vertices)
    )

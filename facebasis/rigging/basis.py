"""The basis step of example-based generation (Gao, Tan, Guo, Fan 2015, eq. 2-4), vectorised over triangles.

With the weights X (k, m) fixed, every triangle t solves for the target blendshapes' frame edge
columns Y (k, 6) (the six numbers of the 3 x 2 edge columns of each shape)::

    (X X^T + alpha W_t) Y_t = X R_t + alpha W_t A~_t                      (eq. 2-4, normal equations)

with R_t (m, 6) the training frames minus the target neutral's, A~_t (k, 6) the deformation
transfer prior (eq. 3) and W_t = diag(w_it) its per-shape weights. With m well below k the system
is solved through the m x m Woodbury form, otherwise by a k x k Cholesky per triangle
(:func:`use_direct`); blocks of triangles run on worker threads.

Array layouts (the four a newcomer meets here)::

    frames_cm          (q, 3, 3, t)   shape, coordinate x, frame column c, triangle (geometry)
    edge columns       (q, 3, 2, t)   its first two columns (v2 - v1, v3 - v1), as (q, 6, t)
    triangle-first     (t, 6, q)      triangle, row 2x + c, shape: :func:`to_triangle_major`,
                                      :func:`training_rows`; the inputs RT, AT of :func:`basis_rows`
                                      (a block of triangles is one contiguous (6c, q) matrix)
    reconstruction     (2, t, 3, k)   column c, triangle, coordinate x, shape: the output of
                                      :func:`basis_rows`, reshaped (2t, 3k) it is the right-hand side
                                      of ``EdgePoisson.solve_frame_rows`` (no transpose of the whole
                                      array)

References
----------
- Gao Yali, Tan Guanghua, Guo Songrui, Fan Xiaowei. Example-based facial blendshape generation
    (基于样例的面部表情基生成). Computer Engineering 41(3): 258-261, 2015. Equation numbers
    "eq. N" in this module are this paper's unless another paper is named.
"""

from __future__ import annotations


import numpy as np


from ..errors import InputError, SolverError
from .spdsolve import posv_rows



# ----------------------------------------------------------------------------------------------
# pure functions of the method

def regularisation_weights(template_frame_deltas, template_frames, mu=0.1, sigma=2.0, measure="relative"):
    """Per-triangle regulariser weights of eq. 3, (m_tri, k).

    ``w = ((1 + s) / (mu + s))^sigma`` with ``s = ||A_i^S||`` (``measure="absolute"``, the paper)
    or ``s = ||A_i^S|| / ||A_0^S||`` (``"relative"``, scale-free), norms over the two edge columns.

    Parameters
    ----------
    template_frame_deltas : (k, 3, 2, m_tri) edge columns of ``S_i``'s frames minus ``S_0``'s
    template_frames : (3, 3, m_tri) frames of ``S_0``
    """
    s = np.sqrt((template_frame_deltas ** 2).sum(axis=(1, 2)))  # (k, m_tri)
    if measure == "relative":
        s = s / np.sqrt((template_frames[:, :2] ** 2).sum(axis=(0, 1)))

    return (((1.0 + s) / (mu + s)) ** sigma).T


#: triangles per block of the basis step (blocks stay in cache and run on the worker threads)
BASIS_BLOCK = 512

#: the basis step uses the m x m Woodbury form while ``m < WOODBURY_RATIO * k``, else the direct
#: k x k Cholesky per triangle. Measured on ICT (k = 53, 28,068 triangles, one thread, CPU seconds
#: per step): direct 0.48-0.55 vs Woodbury 0.30 at m = 20, 0.48-0.55 vs 0.45-0.50 at m = 30,
#: 0.46 vs 0.64-0.73 at m = 40 (forming the m x m systems costs 2 k m^2 per triangle against
#: k^3 / 3 for the Cholesky factor).
WOODBURY_RATIO = 0.6


def use_direct(k: int, m: int) -> bool:
    """Whether the basis step solves the k x k systems directly (else the m x m Woodbury form)."""
    return m >= WOODBURY_RATIO * k


#: triangles whose k x k systems are formed at a time inside a block of the direct path (one
#: cache-resident buffer of SUB_BLOCK k^2 doubles, reused, instead of a block-sized array)
SUB_BLOCK = 32

#: below this fraction of ``||R||^2`` the block's E_fit is recomputed from the residual itself
#: (the short form of :func:`_block_energies` subtracts numbers of the size of ``||R||^2``)
FIT_CANCELLATION = 1e-6


def _block_energies(X, Rs, XR, Y, As, wt, alpha):
    """(E_fit, E_reg) of eq. 2 and 3 on a block, from the solved system instead of the residual.

    With ``(X X^T + D) Y = X R + D A~`` (``D = alpha diag(w)``, per triangle), ``Y X X^T Y`` equals
    ``Y (XR + D A~ - D Y)``, so ``E_fit = ||R||^2 - 2 Y.XR + Y.X X^T Y = ||R||^2 - Y.XR + Y.D(A~ - Y)``:
    inner products of (c, 6, k) arrays, no (6c, m) product with X. Where that difference is small
    against ``||R||^2`` (below :data:`FIT_CANCELLATION`) it is recomputed as ``||Y X - R||^2``.

    Rs (6c, m), XR = Rs X^T and Y, As (c, 6, k), wt (c, k).
    """
    diff = As - Y
    wd = diff * wt[:, None, :]
    e_reg = float(np.vdot(wd, diff))
    r2 = float(np.vdot(Rs, Rs))
    e_fit = r2 - float(np.vdot(Y, XR)) + alpha * float(np.vdot(Y, wd))
    if e_fit < FIT_CANCELLATION * r2:
        fit = Y.reshape(len(Rs), -1) @ X
        fit -= Rs
        e_fit = float(np.vdot(fit, fit))
    return e_fit, e_reg


def _basis_block(X, XX, RT, AT, w, alpha, out, s):
    """Eq. 4 on the triangles of slice ``s``; writes ``out[:, s]`` and returns (E_fit, E_reg) there.

    Triangle-first layout: ``RT`` (m_tri, 6, m) and ``AT`` (m_tri, 6, k) hold ``R_j`` and ``A~_i``
    with the 6 edge-column entries (coordinate d, column e) after the triangle, so a block's rows
    are one contiguous (6c, m) matrix, its right-hand sides ``X R + D A~`` come out of one product
    as (c, 6, k), which is per triangle the Fortran-ordered (k, 6) LAPACK solves in place;
    ``out`` is (2, m_tri, 3, k) = [column e, triangle, coordinate d, shape i]. ``XX`` is ``X X^T``
    (k, k) when :func:`use_direct` (k x k Cholesky solves, one LAPACK ``posv`` per triangle without
    the GIL (:func:`~facebasis.rigging.spdsolve.posv_rows`), the matrices formed :data:`SUB_BLOCK`
    at a time in one reused buffer), else the (k, m*m) table of
    ``x_i x_i^T`` for the Woodbury form.
    """
    k, m = X.shape
    wt = w[s]                                            # (c, k)
    c = wt.shape[0]
    Rs = RT[s].reshape(6 * c, m)                         # contiguous view
    As = AT[s]                                           # (c, 6, k)
    XR = (Rs @ X.T).reshape(c, 6, k)                     # sum_j x_ij R_j
    if use_direct(k, m):  # (X X^T + D) Y = X R + D A~ directly, per triangle (Cholesky: D > 0)
        D = alpha * wt
        Y = D[:, None, :] * As
        Y += XR                                          # right-hand sides, solved in place: (c, 6, k)
        buf = np.empty((min(SUB_BLOCK, c), k, k))
        for j0 in range(0, c, SUB_BLOCK):
            n = min(SUB_BLOCK, c - j0)
            A = buf[:n]
            A[...] = XX
            A.reshape(n, -1)[:, :: k + 1] += D[j0:j0 + n]
            try:  # one LAPACK Cholesky solve per triangle, in place, without the GIL (spdsolve)
                posv_rows(A, Y[j0:j0 + n])
            except SolverError as err:  # pragma: no cover - X X^T + D is positive definite for alpha, w > 0
                raise SolverError(f"basis step: {err}", err.status) from None
    else:
        dinv = 1.0 / (alpha * wt)                        # D^-1, (c, k)
        Gm = XR * dinv[:, None, :]
        Gm += As                                         # D^-1 (X R + D A~)
        XtG = (Gm.reshape(6 * c, k) @ X).reshape(c, 6, m)
        # K_t = I + X^T D_t^-1 X for every triangle of the block: one (c, k) x (k, m*m) product
        K = (dinv @ XX).reshape(c, m, m)
        K.reshape(c, -1)[:, :: m + 1] += 1.0
        Z = np.linalg.solve(K, XtG.transpose(0, 2, 1))   # (c, m, 6)
        XZ = (np.ascontiguousarray(Z.transpose(0, 2, 1)).reshape(6 * c, m) @ X.T).reshape(c, 6, k)
        XZ *= dinv[:, None, :]
        Y = np.subtract(Gm, XZ, out=Gm)                  # (c, 6, k)
    out[:, s] = Y.reshape(c, 3, 2, k).transpose(2, 0, 1, 3)
    return _block_energies(X, Rs, XR, Y, As, wt, alpha)


def basis_rows(X, RT, AT, w, alpha, *, executor=None, block: int = BASIS_BLOCK, out=None):
    """Eq. 4 for every triangle in the triangle-first layout of :func:`_basis_block`.

    Parameters
    ----------
    X : (k, m) weights
    RT : (m_tri, 6, m) training rows (:func:`training_rows`), C-contiguous
    AT : (m_tri, 6, k) prior rows (:func:`to_triangle_major`)
    w : (m_tri, k) regulariser weights; alpha : > 0
    out : optional (2, m_tri, 3, k) float64 C-contiguous array to write into (a caller repeating
        the step reuses one buffer: a fresh 70 MB array per step on ICT at k = 53 costs its page
        faults every time)

    Returns (out (2, m_tri, 3, k), E_fit, E_reg); ``out.reshape(2 m_tri, 3k)`` is what
    :meth:`facebasis.geometry.poisson.EdgePoisson.solve_frame_rows` takes.
    """
    k, m = X.shape
    m_tri = RT.shape[0]
    X = np.ascontiguousarray(X, dtype=np.float64)
    RT = np.ascontiguousarray(RT, dtype=np.float64)
    AT = np.ascontiguousarray(AT, dtype=np.float64)
    XX = X @ X.T if use_direct(k, m) else (X[:, :, None] * X[:, None, :]).reshape(k, m * m)
    if out is None:
        out = np.empty((2, m_tri, 3, k))
    elif out.shape != (2, m_tri, 3, k) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise InputError(f"basis_rows: out: expected a C-contiguous float64 array of shape {(2, m_tri, 3, k)}, found "
                         f"{out.dtype} {out.shape}")
    blocks = [slice(i, min(i + block, m_tri)) for i in range(0, m_tri, block)]
    if executor is None:
        parts = [_basis_block(X, XX, RT, AT, w, alpha, out, s) for s in blocks]
    else:
        parts = list(executor.map(lambda s: _basis_block(X, XX, RT, AT, w, alpha, out, s), blocks))
    return out, float(sum(p[0] for p in parts)), float(sum(p[1] for p in parts))


def _deletion_block(X, XX, RT, AT, w, alpha, labels, outs, resid, s):
    """:func:`fold_deletion_rows` on the triangles of slice ``s`` (Woodbury form, every fold at once)."""
    k, m = X.shape
    wt = w[s]
    c = wt.shape[0]
    Rs = RT[s].reshape(6 * c, m)
    As = AT[s]
    dinv = 1.0 / (alpha * wt)                                    # D^-1, (c, k)
    Gm = (Rs @ X.T).reshape(c, 6, k) * dinv[:, None, :]
    Gm += As                                                     # D^-1 (X R + D A~)
    K = (dinv @ XX).reshape(c, m, m)
    K.reshape(c, -1)[:, :: m + 1] += 1.0                         # K = I + X^T D^-1 X
    P = np.linalg.inv(K)                                         # K^-1 = I - H (hat matrix H = X^T M^-1 X)
    XtG = (Gm.reshape(6 * c, k) @ X).reshape(c, 6, m)
    Y = Gm - ((XtG @ P.transpose(0, 2, 1)).reshape(6 * c, m) @ X.T).reshape(c, 6, k) * dinv[:, None, :]
    E = Rs.reshape(c, 6, m) - (Y.reshape(6 * c, k) @ X).reshape(c, 6, m)   # residuals e = R - X^T Y, (c, 6, m)
    for f, (out, res) in enumerate(zip(outs, resid)):
        idx = np.flatnonzero(labels == f)
        # (I - H_ff)^-1 e_f = (K^-1)_ff^-1 e_f: the fold's residuals under the fit without it
        ef = np.linalg.solve(P[:, idx[:, None], idx], E[:, :, idx].transpose(0, 2, 1))   # (c, |f|, 6)
        if res is not None:
            res[s] = ef.transpose(0, 2, 1)
        if out is not None:  # Y_-f = Y - M^-1 X_f (I - H_ff)^-1 e_f, M^-1 X = D^-1 X K^-1
            Q = P[:, :, idx] @ ef                                # (c, m, 6)
            corr = (np.ascontiguousarray(Q.transpose(0, 2, 1)).reshape(6 * c, m) @ X.T).reshape(c, 6, k)
            corr *= dinv[:, None, :]
            out[:, s] = (Y - corr).reshape(c, 3, 2, k).transpose(2, 0, 1, 3)


def fold_deletion_rows(X, RT, AT, w, alpha, labels, *, rows: bool = True, residuals: bool = False,
                       executor=None, block: int = BASIS_BLOCK):
    """Eq. 4 refitted without each fold of training expressions, in closed form from the full fit.

    Per triangle, with ``M = X X^T + D`` the matrix of eq. 4, ``Y`` its solution on all m
    expressions, ``e = R - X^T Y`` the residuals (m, 6) and ``H = X^T M^-1 X`` the hat matrix, the
    solution without fold f (the columns ``X_f`` and rows ``R_f`` deleted) is the fold-deletion
    (Sherman-Morrison-Woodbury) formula ::

        Y_-f = Y - M^-1 X_f (I - H_ff)^-1 e_f,       R_f - X_f^T Y_-f = (I - H_ff)^-1 e_f

    In the Woodbury form ``K = I + X^T D^-1 X`` gives ``I - H = K^-1`` and ``M^-1 X = D^-1 X K^-1``,
    so one m x m inverse per triangle serves every fold (against one eq. 4 solve per fold).

    Parameters
    ----------
    X : (k, m) weights; RT (m_tri, 6, m), AT (m_tri, 6, k), w (m_tri, k), alpha: as :func:`basis_rows`
    labels : (m,) fold of every training expression (0 .. folds - 1)
    rows : return every fold's solution in the layout of :func:`basis_rows`
    residuals : return every fold's held-out residuals ``R_f - X_f^T Y_-f`` as (m_tri, 6, |f|)

    Returns
    -------
    list over folds of (2, m_tri, 3, k) arrays (``rows``) and/or a list of (m_tri, 6, |f|) arrays
    (``residuals``), as a tuple (rows, residuals) with None for what was not asked.
    """
    k, m = X.shape
    labels = np.asarray(labels)
    if labels.shape != (m,) or labels.min() < 0:
        raise InputError(f"fold_deletion_rows: labels: expected ({m},) folds >= 0, found {labels.shape}")
    folds = int(labels.max()) + 1
    m_tri = RT.shape[0]
    X = np.ascontiguousarray(X, dtype=np.float64)
    RT = np.ascontiguousarray(RT, dtype=np.float64)
    AT = np.ascontiguousarray(AT, dtype=np.float64)
    XX = (X[:, :, None] * X[:, None, :]).reshape(k, m * m)
    outs = [np.empty((2, m_tri, 3, k)) if rows else None for _ in range(folds)]
    resid = [np.empty((m_tri, 6, int((labels == f).sum()))) if residuals else None for f in range(folds)]
    blocks = [slice(i, min(i + block, m_tri)) for i in range(0, m_tri, block)]
    run = lambda s: _deletion_block(X, XX, RT, AT, w, alpha, labels, outs, resid, s)  # noqa: E731
    if executor is None:
        for s in blocks:
            run(s)
    else:
        list(executor.map(run, blocks))
    return (outs if rows else None), (resid if residuals else None)


def training_rows(E, F) -> np.ndarray:
    """Edge columns of the frames of deltas ``E`` (m, n, 3) in the triangle-first layout
    (m_tri, 6, m) of :func:`basis_rows`: row ``2 d + e`` is coordinate d of column e
    (e = 0: v2 - v1, e = 1: v3 - v1), as ``frames_cm(T)[:, :, :2] - frames_cm(B_0)[:, :2]``."""
    Et = np.ascontiguousarray(np.asarray(E, dtype=np.float64).transpose(1, 2, 0))  # (n, 3, m)
    v1 = Et[F[:, 0]]                                                                 # (m_tri, 3, m)
    out = np.empty((len(F), 3, 2, Et.shape[2]))
    np.subtract(Et[F[:, 1]], v1, out=out[:, :, 0])
    np.subtract(Et[F[:, 2]], v1, out=out[:, :, 1])
    return out.reshape(len(F), 6, -1)


def to_triangle_major(A) -> np.ndarray:
    """(q, 6, m_tri) -> (m_tri, 6, q), the layout of :func:`basis_rows`."""
    return np.ascontiguousarray(np.asarray(A, dtype=np.float64).transpose(2, 1, 0))


def basis_step(X, R, A_tilde, w, alpha, *, executor=None, block: int = BASIS_BLOCK, energies: bool = False):
    """Solve eq. 4 for every triangle at once.

    Parameters
    ----------
    X : (k, m) weights, column j = x_j
    R : (m, 6, m_tri) training frame deltas ``A_j^T - A_0^B`` (edge columns, flattened 3 x 2)
    A_tilde : (k, 6, m_tri) deformation-transfer prior ``A~_i``
    w : (m_tri, k) regulariser weights
    alpha : regularisation weight (> 0)
    executor : optional ``concurrent.futures`` executor; blocks of triangles run on it
    block : triangles per block
    energies : also return ``(E_fit, E_reg)`` of eq. 2 and 3 at the solution

    Returns
    -------
    Y : (k, 6, m_tri) blendshape frame deltas ``A_i^B`` minimising ``E_fit + alpha E_reg``
    (and ``E_fit, E_reg`` if ``energies``).

    Notes
    -----
    Per triangle ``(X X^T + D) Y = X R + D A~`` with ``D = alpha diag(w_t)``. With m small against k
    (:func:`use_direct`) the Woodbury identity
    ``(D + X X^T)^-1 = D^-1 - D^-1 X (I + X^T D^-1 X)^-1 X^T D^-1`` reduces each triangle to an
    m x m solve (one BLAS product per contraction over a block); otherwise the k x k system is
    solved directly, one in-place LAPACK Cholesky solve (``posv``) per triangle. Triangles are
    processed in cache-sized blocks; blocks are independent and run in parallel on ``executor``. This wrapper converts
    layouts; the generator calls :func:`basis_rows` on data kept in its layout.
    """
    k = X.shape[0]
    m_tri = R.shape[-1]
    out, e_fit, e_reg = basis_rows(X, to_triangle_major(R), to_triangle_major(A_tilde), w, alpha,
                                   executor=executor, block=block)
    Y = np.ascontiguousarray(out.transpose(3, 2, 0, 1)).reshape(k, 6, m_tri)  # [i, (d, e), t]
    return (Y, e_fit, e_reg) if energies else Y


def basis_energies(X, R, A_tilde, w, Y):
    """``E_fit`` (eq. 2) and ``E_reg`` (eq. 3) at blendshape frames Y, over edge columns."""
    k, m = X.shape
    fit = (X.T @ Y.reshape(k, -1)).reshape(R.shape)
    fit -= R
    e_fit = float(np.einsum("i,i->", fit.ravel(), fit.ravel()))
    diff = A_tilde - Y
    diff *= diff
    e_reg = float(np.einsum("kt,kct->", w.T, diff))
    return e_fit, e_reg
